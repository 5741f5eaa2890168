//! Whether two recordings share their samples: a validation file that is a fit file in another
//! form (reprinted, with other line ends, its time axis shifted, a slice of it) scores the fit's
//! own data, though its bytes differ. Compared by the drive and the displacement, sample by
//! sample, within what a reprint changes and far below any sensor's noise.

use crate::recording::Recording;

/// Samples compared to find a shared stretch (or the shorter recording's, down to
/// [`MIN_WINDOW`]: a slice shorter than that is not looked for).
const WINDOW: usize = 256;

/// See [`WINDOW`].
const MIN_WINDOW: usize = 64;

/// Two samples are the same within this share of the channel's span, plus [`SAME_OF_VALUE`] of
/// its largest magnitude: six significant digits reprint a value within 5e-7 of it, while a
/// sensor's noise is 1e-4 of the span and more.
const SAME_OF_SPAN: f64 = 1e-5;

/// See [`SAME_OF_SPAN`].
const SAME_OF_VALUE: f64 = 2e-6;

/// A stretch of samples two recordings share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shared {
    /// Its first sample in the first recording.
    pub first_at: usize,
    /// Its first sample in the second.
    pub second_at: usize,
    /// How many samples.
    pub samples: usize,
}

/// The channels compared: the drive both give (the current, else the command) and the
/// displacement; `None` when they share none of them.
fn channels<'a>(a: &'a Recording, b: &'a Recording) -> Option<[(&'a [f64], &'a [f64]); 2]> {
    let drive = match (&a.current_a, &b.current_a, &a.command_v, &b.command_v) {
        (Some(x), Some(y), _, _) | (_, _, Some(x), Some(y)) => (x.as_slice(), y.as_slice()),
        _ => return None,
    };
    let shown = (a.displacement_um.as_deref()?, b.displacement_um.as_deref()?);
    Some([drive, shown])
}

/// How close two samples of a channel must be (from the first recording's values).
fn tolerance(x: &[f64]) -> f64 {
    let (lo, hi) = x.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    SAME_OF_SPAN * (hi - lo) + SAME_OF_VALUE * lo.abs().max(hi.abs())
}

/// The longest stretch `a` and `b` share around where `a`'s middle [`WINDOW`] samples (or
/// `b`'s) sit in the other, if either does.
pub fn shared(a: &Recording, b: &Recording) -> Option<Shared> {
    let pairs = channels(a, b)?;
    let tol = pairs.map(|(x, _)| tolerance(x));
    let same = |i: usize, j: usize| pairs.iter().zip(&tol).all(|((x, y), t)| (x[i] - y[j]).abs() <= *t);
    let (na, nb) = (pairs[0].0.len(), pairs[0].1.len());
    let window = WINDOW.min(na).min(nb);
    if window < MIN_WINDOW {
        return None;
    }
    // Where a's window from `at` starts in b (`flip`: b's window from `at` in a), as (i in a,
    // j in b).
    let find = |at: usize, flip: bool| -> Option<(usize, usize)> {
        let place = |o: usize| if flip { (o, at) } else { (at, o) };
        let n_other = if flip { na } else { nb };
        (0..=n_other - window).map(place).find(|&(i, j)| (0..window).all(|k| same(i + k, j + k)))
    };
    let (i, j) = find((na - window) / 2, false).or_else(|| find((nb - window) / 2, true))?;
    let back = (1..=i.min(j)).take_while(|&d| same(i - d, j - d)).count();
    let ahead = (0..(na - i).min(nb - j)).take_while(|&d| same(i + d, j + d)).count();
    Some(Shared { first_at: i - back, second_at: j - back, samples: back + ahead })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(name: &str, n: usize, seed: u64) -> Recording {
        let mut state = seed;
        let mut noise = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.01
        };
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-4).collect();
        let i: Vec<f64> = t.iter().map(|t| (2.0 * std::f64::consts::PI * 5.0 * t).sin()).collect();
        let y: Vec<f64> = i.iter().map(|i| 20.0 + 10.0 * i + noise()).collect();
        Recording { current_a: Some(i), displacement_um: Some(y), ..Recording::with_time(name, n, 1e-4) }
    }

    /// A slice of a file, reprinted to seven digits, is found with its place and length; the same
    /// drive recorded again (other noise) is not.
    #[test]
    fn a_reprinted_slice_is_found_and_a_new_recording_of_the_same_drive_is_not() {
        let fit = recording("fit", 5000, 1);
        let mut slice = fit.clone();
        let cut = |v: &Option<Vec<f64>>| {
            v.as_ref().map(|v| v[1200..3200].iter().map(|x| format!("{x:.7e}").parse().unwrap()).collect())
        };
        slice.time_s = fit.time_s[1200..3200].iter().map(|t| t + 7.0).collect();
        slice.current_a = cut(&fit.current_a);
        slice.displacement_um = cut(&fit.displacement_um);
        assert_eq!(shared(&slice, &fit), Some(Shared { first_at: 0, second_at: 1200, samples: 2000 }));
        assert_eq!(shared(&fit, &slice), Some(Shared { first_at: 1200, second_at: 0, samples: 2000 }));
        assert_eq!(shared(&recording("again", 5000, 2), &fit), None);
    }
}
