//! A measured drive current carries its sensor's noise. At a slow drive the true current moves
//! less per sample than the noise does, so the logged current turns back at almost every
//! sample; a Jiles–Atherton law (no wiping-out) opens a minor loop at each turn and relaxes
//! towards its anhysteretic curve, a loop the rod never ran. Here the current's white-noise
//! level is estimated from the file, and the field's turns smaller than a multiple of it are
//! taken as noise: the law then stays on its branch ([`model_core::JaBranch`]).
//!
//! The noise also reaches the law's output through its slope, sample by sample (the rod saw
//! the true current), and a fit or a start-state estimate then prefers states where the slope
//! is low (errors in the variables). So the model is driven by the logged current smoothed to
//! its noise ([`denoised`]): a local quadratic fit whose width is chosen by Stein's unbiased
//! estimate of its error against the true current, which the noise level gives, over the whole
//! file or, where the drive steps, between its steps.

use std::sync::{Arc, Mutex};

use realfft::RealFftPlanner;

/// A turn of the field is a reversal when it moves back by more than this many noise rms (of
/// the current, through the coil): white noise moves back that far about once in 10¹⁵ samples.
pub const REVERSAL_IN_NOISE_RMS: f64 = 8.0;

/// Half-widths (samples) the drive's smoother tries: a local quadratic over 2m + 1 samples (the
/// widest for a hold of the drive, where no width costs bias).
const SMOOTHER_HALF_WIDTHS: [usize; 15] = [2, 3, 4, 6, 8, 11, 16, 22, 32, 45, 64, 90, 128, 181, 256];

/// A sample-to-sample change of the drive beyond this many noise rms is a step, not noise (a
/// difference of white noise has rms √2 σ: 12 σ is 8.5 of its rms, once in 10¹⁶ samples).
const STEP_IN_NOISE_RMS: f64 = 12.0;

/// The logged current `x` with white noise of rms `sigma` smoothed to an estimate of the true
/// current, and the widest half-width used; `None` where nothing beats the logged current itself
/// or without noise. Two smoothers are tried and the one with the lower estimated error kept
/// (Stein's unbiased risk estimate against the true current): one width over the whole file
/// ([`smoothed_whole`]), and each stretch between the drive's steps smoothed on its own
/// ([`smoothed_between_steps`]): a held current is smoothed wide without rounding its steps.
pub fn denoised(x: &[f64], sigma: f64) -> Option<(Vec<f64>, usize)> {
    if sigma.is_nan() || sigma <= 0.0 || x.len() < 5 {
        return None;
    }
    let whole = smoothed_whole(x, sigma);
    let between = smoothed_between_steps(x, sigma);
    let best = match (whole, between) {
        (Some(w), Some(b)) => Some(if b.0 < w.0 { b } else { w }),
        (w, b) => w.or(b),
    };
    best.map(|(_, smooth, m)| (smooth, m))
}

/// How many logged currents [`read`] keeps (a diagnosis prepares its fit and validation files
/// again for every candidate; a Python session may pass many), and how many of their samples at
/// most, counting each with its smoothed twin (4 M values, 32 MB: a 2 M-sample current is kept
/// alone, a longer one not at all).
const READINGS_KEPT: usize = 32;
const READINGS_KEPT_SAMPLES: usize = 4_000_000;

/// A logged current's white-noise rms ([`white_noise_rms`]) and the current smoothed to it
/// ([`denoised`]), or `None` where nothing beats the logged current.
pub type Reading = (f64, Option<Arc<[f64]>>);

/// The most recent readings, each with its current (found again by its values' bits): the
/// newest last.
static READINGS: Mutex<Vec<(Arc<[f64]>, Reading)>> = Mutex::new(Vec::new());

/// [`white_noise_rms`] and [`denoised`] of the logged current `x`, worked out once per distinct
/// current: a fit, its candidates and its checks prepare the same files many times, and the
/// smoother's widths cost a tenth of a second on a 30 000-sample file. A pure function of `x`.
pub fn read(x: &[f64]) -> Reading {
    let same =
        |kept: &[f64]| kept.len() == x.len() && kept.iter().zip(x).all(|(a, b)| a.to_bits() == b.to_bits());
    if let Ok(kept) = READINGS.lock() {
        if let Some((_, reading)) = kept.iter().rev().find(|(k, _)| same(k)) {
            return reading.clone();
        }
    }
    let noise = white_noise_rms(x);
    let reading: Reading = (noise, denoised(x, noise).map(|(smooth, _)| Arc::<[f64]>::from(smooth)));
    if let Ok(mut kept) = READINGS.lock() {
        if x.len() <= READINGS_KEPT_SAMPLES / 2 {
            let samples = |kept: &[(Arc<[f64]>, Reading)]| kept.iter().map(|(k, _)| k.len()).sum::<usize>();
            while !kept.is_empty()
                && (kept.len() >= READINGS_KEPT || samples(&kept) + x.len() > READINGS_KEPT_SAMPLES / 2)
            {
                kept.remove(0);
            }
            kept.push((Arc::from(x), reading.clone()));
        }
    }
    reading
}

/// The local quadratic (Savitzky–Golay) fit whose half-width m minimises Stein's unbiased risk
/// estimate ‖x − Sx‖² − nσ² + 2σ² tr S of the true current (near the ends the window narrows to
/// the samples there are): its risk, the smoothed `x` and m; `None` where no width beats the
/// logged current itself (risk nσ²). A smoother can only round what it cannot tell from noise: a
/// width is chosen only where its bias costs less than the noise it removes.
fn smoothed_whole(x: &[f64], sigma: f64) -> Option<(f64, Vec<f64>, usize)> {
    let n = x.len();
    let variance = sigma * sigma;
    let mut best: Option<(f64, Vec<f64>, usize)> = None;
    for m in SMOOTHER_HALF_WIDTHS {
        if 2 * m + 1 > n {
            break;
        }
        let (smooth, trace) = savitzky_golay(x, m);
        let residual: f64 = x.iter().zip(&smooth).map(|(a, b)| (a - b) * (a - b)).sum();
        let risk = residual - n as f64 * variance + 2.0 * variance * trace;
        if risk < n as f64 * variance && best.as_ref().is_none_or(|b| risk < b.0) {
            best = Some((risk, smooth, m));
        }
    }
    best
}

/// `x` cut at its steps (changes beyond [`STEP_IN_NOISE_RMS`]) and each stretch smoothed on its
/// own ([`smoothed_whole`], or left as logged where nothing beats it): the summed risk, the
/// smoothed `x` and the widest half-width; `None` without a step.
fn smoothed_between_steps(x: &[f64], sigma: f64) -> Option<(f64, Vec<f64>, usize)> {
    let step = STEP_IN_NOISE_RMS * sigma;
    let mut cuts: Vec<usize> = (1..x.len()).filter(|&k| (x[k] - x[k - 1]).abs() > step).collect();
    if cuts.is_empty() {
        return None;
    }
    cuts.push(x.len());
    let (mut risk, mut out, mut widest, mut from) = (0.0, Vec::with_capacity(x.len()), 0, 0);
    for to in cuts {
        let stretch = &x[from..to];
        match smoothed_whole(stretch, sigma) {
            Some((r, smooth, m)) => {
                risk += r;
                out.extend(smooth);
                widest = widest.max(m);
            }
            None => {
                risk += stretch.len() as f64 * sigma * sigma;
                out.extend_from_slice(stretch);
            }
        }
        from = to;
    }
    Some((risk, out, widest))
}

/// `x` smoothed by a local quadratic over 2m + 1 samples (m' = min(m, k, n − 1 − k) at sample
/// k), and the smoother's trace Σ_k w₀(m').
fn savitzky_golay(x: &[f64], m: usize) -> (Vec<f64>, f64) {
    let n = x.len();
    // Weights of the symmetric quadratic fit's centre value: 3(3m² + 3m − 1 − 5j²)/((2m + 1)(4m² + 4m − 3)).
    let weights = |m: usize| -> Vec<f64> {
        let mf = m as f64;
        let den = (2.0 * mf + 1.0) * (4.0 * mf * mf + 4.0 * mf - 3.0);
        (0..=m).map(|j| 3.0 * (3.0 * mf * mf + 3.0 * mf - 1.0 - 5.0 * (j * j) as f64) / den).collect()
    };
    let full = weights(m);
    let mut trace = 0.0;
    let out = (0..n)
        .map(|k| {
            let mk = m.min(k).min(n - 1 - k);
            if mk < 2 {
                trace += 1.0;
                return x[k];
            }
            let w = if mk == m {
                std::borrow::Cow::Borrowed(&full)
            } else {
                std::borrow::Cow::Owned(weights(mk))
            };
            trace += w[0];
            w[0] * x[k] + (1..=mk).map(|j| w[j] * (x[k - j] + x[k + j])).sum::<f64>()
        })
        .collect();
    (out, trace)
}

/// Segment length of the noise estimate (shorter files: the largest power of two that fits).
const SEGMENT: usize = 512;
/// Shortest segment judged; a shorter file is taken as noise-free.
const MIN_SEGMENT: usize = 64;

/// The rms of `x`'s white noise [x's unit], the lower of two estimates that a drive can only
/// raise: [`top_band_rms`], which a drive with sharp edges in every segment (a fast square)
/// reads high, and [`second_difference_rms`], which a drive moving fast between samples reads
/// high. 0 for a file under 64 samples.
pub fn white_noise_rms(x: &[f64]) -> f64 {
    if x.len() < MIN_SEGMENT {
        return 0.0;
    }
    top_band_rms(x).min(second_difference_rms(x))
}

/// The noise rms from the median absolute second difference (white noise of variance σ² has
/// second differences of variance 6σ²; a normal's median |x| is 0.6745 of its σ): a step moves
/// only the two differences at its edge.
fn second_difference_rms(x: &[f64]) -> f64 {
    let mut d2: Vec<f64> = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).collect();
    let mid = d2.len() / 2;
    let (_, median, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    *median / 0.6745 / 6f64.sqrt()
}

/// The noise rms from each Hann-windowed segment's periodogram over the top quarter of the
/// band (3/8 to 1/2 of the sample rate, above any drive a file resolves): its median / ln 2 (a
/// periodogram bin of white noise is exponential: the median is ln 2 of its mean, and a tone in
/// the band moves the median little), the lower quartile over segments (a segment holding a
/// step's edge reads high).
fn top_band_rms(x: &[f64]) -> f64 {
    let n = x.len();
    let segment = if n >= SEGMENT { SEGMENT } else { 1 << (usize::BITS - 1 - n.leading_zeros()) };
    let window: Vec<f64> = (0..segment)
        .map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / segment as f64).cos())
        .collect();
    let w2: f64 = window.iter().map(|w| w * w).sum();
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(segment);
    let (mut buf, mut spectrum) = (fft.make_input_vec(), fft.make_output_vec());
    let top_quarter = 3 * segment / 8..segment / 2; // Nyquist bin left out: it is not exponential
    let mut variances = Vec::new();
    for start in (0..=n - segment).step_by(segment / 2) {
        let seg = &x[start..start + segment];
        let mean = seg.iter().sum::<f64>() / segment as f64;
        for ((b, v), w) in buf.iter_mut().zip(seg).zip(&window) {
            *b = (v - mean) * w;
        }
        if fft.process(&mut buf, &mut spectrum).is_err() {
            return 0.0;
        }
        // E|X_j|² = σ² Σw² for white noise of variance σ².
        let mut bins: Vec<f64> = spectrum[top_quarter.clone()].iter().map(|c| c.norm_sqr() / w2).collect();
        bins.sort_by(f64::total_cmp);
        variances.push(bins[bins.len() / 2] / std::f64::consts::LN_2);
    }
    variances.sort_by(f64::total_cmp);
    let variance = variances[variances.len() / 4];
    if variance.is_finite() {
        variance.sqrt()
    } else {
        0.0
    }
}

/// The direction (+1 rising, −1 falling) of each step k → k + 1 of `h` once its turns back by
/// no more than `threshold` are taken as noise: a zigzag decided on the whole run, each turn at
/// the branch's furthest sample. The steps before the first move beyond `threshold` take the
/// first branch's direction. `None` when every turn of `h` is beyond the threshold (the
/// directions are then the steps' own signs, and a plain run is the same).
pub fn branch_directions(h: &[f32], threshold: f32) -> Option<Vec<f32>> {
    let n = h.len();
    if n < 2 {
        return None;
    }
    // Turns: (index of the branch's furthest sample, direction of the branch that follows).
    let mut turns: Vec<(usize, f32)> = Vec::new();
    let (mut hi, mut lo) = (0, 0);
    let mut dir = 0.0f32;
    for k in 1..n {
        if h[k] > h[hi] {
            hi = k;
        }
        if h[k] < h[lo] {
            lo = k;
        }
        if dir == 0.0 {
            if h[hi] - h[lo] > threshold {
                dir = if hi > lo { 1.0 } else { -1.0 };
                turns.push((0, dir));
                if dir > 0.0 {
                    lo = hi;
                } else {
                    hi = lo;
                }
            }
        } else if dir > 0.0 && h[hi] - h[k] > threshold {
            turns.push((hi, -1.0));
            dir = -1.0;
            lo = k;
        } else if dir < 0.0 && h[k] - h[lo] > threshold {
            turns.push((lo, 1.0));
            dir = 1.0;
            hi = k;
        }
    }
    if turns.is_empty() {
        turns.push((0, 1.0));
    }
    let mut dirs = vec![0.0f32; n - 1];
    for (j, &(from, d)) in turns.iter().enumerate() {
        let to = turns.get(j + 1).map_or(n - 1, |t| t.0);
        dirs[from..to].iter_mut().for_each(|x| *x = d);
    }
    let own_signs = dirs.iter().enumerate().all(|(k, &d)| {
        let dh = h[k + 1] - h[k];
        dh == 0.0 || (dh > 0.0) == (d > 0.0)
    });
    (!own_signs).then_some(dirs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    fn sine(n: usize, per: f64, amp: f64) -> Vec<f64> {
        (0..n).map(|k| amp * (2.0 * std::f64::consts::PI * k as f64 / per).sin()).collect()
    }

    fn with_noise(x: &[f64], sigma: f64, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let normal = Normal::new(0.0, sigma).unwrap();
        x.iter().map(|v| v + normal.sample(&mut rng)).collect()
    }

    /// 2 mA on a 0.8 A sine and on a square of 0.8 A (its edges leak into the top band), and a
    /// 12-bit quantised current (an LSB of 8 V/4096 gives q/√12): each read within 15 %.
    #[test]
    fn the_current_noise_is_read_beneath_the_drive() {
        let slow = sine(20_000, 10_000.0, 0.8);
        let est = white_noise_rms(&with_noise(&slow, 2e-3, 1));
        assert!((est / 2e-3 - 1.0).abs() < 0.15, "sine: {est}");
        let square: Vec<f64> = (0..20_000).map(|k| if (k / 500) % 2 == 0 { 0.8 } else { -0.8 }).collect();
        let est = white_noise_rms(&with_noise(&square, 2e-3, 2));
        assert!((est / 2e-3 - 1.0).abs() < 0.15, "square: {est}");
        let lsb = 8.0 / 4096.0;
        let mut rng = StdRng::seed_from_u64(3);
        let quantised: Vec<f64> = sine(20_000, 10_000.0, 0.8)
            .iter()
            .map(|v| ((v + rng.random_range(-lsb..lsb)) / lsb).round() * lsb)
            .collect();
        let est = white_noise_rms(&quantised);
        let expected = ((2.0 * lsb).powi(2) / 12.0 + lsb * lsb / 12.0).sqrt();
        assert!((est / expected - 1.0).abs() < 0.15, "quantised: {est} vs {expected}");
        assert_eq!(white_noise_rms(&slow[..50]), 0.0);
        assert!(white_noise_rms(&slow) < 1e-6, "clean: {}", white_noise_rms(&slow));
    }

    /// The smoother takes a slow sine's noise down to a fraction of it and leaves a fast one
    /// (20 samples a period) nearly as logged: each within its noise of the true current, and a
    /// clean current is not touched.
    #[test]
    fn the_drive_is_smoothed_to_its_noise() {
        let rms = |a: &[f64], b: &[f64]| {
            (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
        };
        let sigma = 2e-3;
        for (per, at_most) in [(10_000.0, 0.25), (200.0, 0.6), (20.0, 1.0)] {
            let truth = sine(20_000, per, 0.8);
            let noisy = with_noise(&truth, sigma, 4);
            let error = match denoised(&noisy, sigma) {
                Some((smooth, m)) => {
                    assert!(m >= 2, "period {per}: half-width {m}");
                    rms(&smooth, &truth)
                }
                None => rms(&noisy, &truth),
            };
            assert!(error <= at_most * sigma, "period {per} samples: {:.3} of the noise left", error / sigma);
        }
        assert!(denoised(&sine(20_000, 10_000.0, 0.8), 0.0).is_none());
    }

    /// A staircase (holds of 2 500 samples, steps of 0.4–0.8 A) keeps its steps sharp and loses
    /// most of its noise on the holds: one width over the whole file could do neither.
    #[test]
    fn held_steps_are_smoothed_between_them() {
        let sigma = 2e-3;
        let levels = [0.0, 0.8, -0.8, 0.4, 0.0, 0.8];
        let truth: Vec<f64> = (0..15_000).map(|k| levels[k / 2500]).collect();
        let noisy = with_noise(&truth, sigma, 5);
        let (smooth, m) = denoised(&noisy, sigma).expect("smoothed");
        assert!(m >= 128, "half-width {m}");
        let worst_step = (1..truth.len())
            .filter(|&k| truth[k] != truth[k - 1])
            .map(|k| (smooth[k] - truth[k]).abs().max((smooth[k - 1] - truth[k - 1]).abs()))
            .fold(0.0, f64::max);
        assert!(worst_step < 5.0 * sigma, "a step rounded by {worst_step}");
        let rms = (smooth.iter().zip(&truth).map(|(a, b)| (a - b) * (a - b)).sum::<f64>()
            / truth.len() as f64)
            .sqrt();
        assert!(rms < 0.2 * sigma, "{:.3} of the noise left", rms / sigma);
    }

    /// A kept reading is the one worked out afresh, bit for bit, however often it is asked for.
    #[test]
    fn a_kept_reading_is_the_fresh_one() {
        let x = with_noise(&sine(20_000, 10_000.0, 0.8), 2e-3, 9);
        let sigma = white_noise_rms(&x);
        let fresh = denoised(&x, sigma).map(|(smooth, _)| smooth);
        for _ in 0..2 {
            let (noise, smooth) = read(&x);
            assert_eq!(noise.to_bits(), sigma.to_bits());
            assert_eq!(smooth.as_deref(), fresh.as_deref());
        }
    }

    /// The noisy sine's branches turn at its peaks, within the noise's reach of them; a clean
    /// sine needs no branches.
    #[test]
    fn branches_turn_where_the_drive_does() {
        let per = 4000.0;
        let clean = sine(12_000, per, 0.8);
        let as_f32 = |x: &[f64]| x.iter().map(|&v| v as f32).collect::<Vec<f32>>();
        assert_eq!(branch_directions(&as_f32(&clean), 0.016), None);
        let dirs = branch_directions(&as_f32(&with_noise(&clean, 2e-3, 4)), 0.016).expect("noise turns back");
        let turns: Vec<usize> = (1..dirs.len()).filter(|&k| dirs[k] != dirs[k - 1]).collect();
        let peaks = [1000.0, 3000.0, 5000.0, 7000.0, 9000.0, 11_000.0];
        assert_eq!(turns.len(), peaks.len(), "{turns:?}");
        // Within 2 mA of the crest a sine of 0.8 A spans ±0.07 rad of phase (±45 samples).
        for (t, p) in turns.iter().zip(peaks) {
            assert!((*t as f64 - p).abs() < 60.0, "turn at {t}, peak at {p}");
        }
        assert_eq!(dirs[0], 1.0);
        assert_eq!(dirs[2000], -1.0);
    }
}
