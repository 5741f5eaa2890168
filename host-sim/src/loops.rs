//! Magnetization loops (docs/formats.md): B–H or M–H points in field order — full
//! loops, minor loops or single branches, unevenly spaced — read and checked, and the features
//! (coercivity, remanence) of a loop. Fitting a model to one is `loop_fit`.

use std::path::Path;

use anyhow::Result;
use model_core::field::MU0;

use crate::columns::loop_separator;
use crate::files::{echo, Input};
use crate::located;
use crate::warning::Warning;

/// Which quantity the file gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopChannel {
    /// Flux density B [T].
    FluxDensity,
    /// Magnetization M [A/m].
    Magnetization,
}

impl LoopChannel {
    /// Contract name.
    pub fn name(self) -> &'static str {
        match self {
            LoopChannel::FluxDensity => "flux_density",
            LoopChannel::Magnetization => "magnetization",
        }
    }
}

/// A loop file, in SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopFile {
    /// Where it came from.
    pub name: String,
    /// Field H [A/m], in the file's order.
    pub h: Vec<f64>,
    /// The file's channel: B [T] or M [A/m].
    pub value: Vec<f64>,
    /// Which channel.
    pub channel: LoopChannel,
}

impl LoopFile {
    /// Magnetization M [A/m] (M = B/μ0 − H for flux-density files).
    pub fn magnetization(&self) -> Vec<f64> {
        match self.channel {
            LoopChannel::Magnetization => self.value.clone(),
            LoopChannel::FluxDensity => self.h.iter().zip(&self.value).map(|(h, b)| b / MU0 - h).collect(),
        }
    }

    /// The file's channel from a magnetization.
    pub fn channel_from_m(&self, m: &[f64]) -> Vec<f64> {
        match self.channel {
            LoopChannel::Magnetization => m.to_vec(),
            LoopChannel::FluxDensity => self.h.iter().zip(m).map(|(h, m)| MU0 * (h + m)).collect(),
        }
    }
}

/// Unit factor to SI for a header such as `H(Oe)`, `H [kA/m]`, `B(mT)`, `M(A/m)`, or the unit
/// after a `/`, `_` or space (`H/Oe`, `B_T`, `H Oe`): a unit written outside brackets is read
/// too, never passed over as A/m. Err: why the header cannot be read, its unit named.
fn unit_factor(header: &str) -> std::result::Result<(char, f64), String> {
    let h = header.trim();
    let quantity = h.chars().next().ok_or("an empty header")?.to_ascii_uppercase();
    let rest = &h[quantity.len_utf8().min(h.len())..];
    let unit = match (h.find(['(', '[']), rest.find(['/', '_', ' '])) {
        (Some(i), _) => h[i + 1..].trim_end_matches([')', ']']).trim(),
        (None, Some(i)) => rest[i..].trim_start_matches(['/', '_', ' ']).trim(),
        (None, None) => "",
    };
    let f = match (quantity, unit) {
        ('H', "" | "A/m" | "A m^-1" | "A_per_m") => 1.0,
        ('H', "kA/m" | "kA_per_m") => 1e3,
        ('H', "Oe") => 1e3 / (4.0 * std::f64::consts::PI),
        ('B', "" | "T") => 1.0,
        ('B', "mT") => 1e-3,
        ('B', "G" | "Gs") => 1e-4,
        ('M', "" | "A/m" | "A_per_m") => 1.0,
        ('M', "kA/m" | "kA_per_m") => 1e3,
        ('H' | 'B' | 'M', _) => {
            let accepted = match quantity {
                'H' => "A/m, kA/m, Oe",
                'B' => "T, mT, G",
                _ => "A/m, kA/m",
            };
            return Err(format!("unit `{}` of {quantity} is not one of {accepted}", echo(unit)));
        }
        _ => return Err(format!("`{quantity}` is not a loop quantity (H, B or M)")),
    };
    Ok((quantity, f))
}

/// For a header that is not a recording's: a hint when its cells name loop quantities (H, B, M
/// with units, or the loop columns) in a layout a loop file does not have, or are a headerless
/// loop file's two numbers (read where only a recording can go, e.g. `simulate --drive`).
pub(crate) fn loop_header_hint(headers: &csv::StringRecord) -> Option<String> {
    if headers.len() == 2 && headers.iter().all(|c| c.trim().parse::<f64>().is_ok()) {
        return Some(
            ": the first line is two numbers, as in a magnetization-loop file without a header (H [A/m], B \
             [T]); this command reads a recording with a `time_s` column (docs/formats.md)"
                .to_string(),
        );
    }
    let loop_like = headers.iter().filter(|c| unit_factor(c).is_ok() || c.trim() == "field_A_per_m").count();
    (loop_like > 0).then(|| {
        ": if this is a magnetization loop, a loop file has two columns, H then B or M (e.g. \
         `H(A/m),B(T)`), or named columns `field_A_per_m` with `flux_density_T` or \
         `magnetization_A_per_m` (docs/formats.md)"
            .to_string()
    })
}

/// Largest loop file read [bytes] (a loop has hundreds to a few hundred thousand points).
const MAX_LOOP_BYTES: u64 = 256 << 20;

/// Reads a loop file (`-` is standard input); errors name the file and line.
pub fn read(path: &Path) -> Result<LoopFile> {
    Ok(read_input(Input::open(path)?, usize::MAX)?.0)
}

/// Reads an opened loop file, keeping at most `max_points` points (and saying so in the
/// warning returned).
pub fn read_input(input: Input, max_points: usize) -> Result<(LoopFile, Option<Warning>)> {
    let name = input.name.clone();
    let text = input.into_text(MAX_LOOP_BYTES)?;
    let mut f = parse(&name, &text)?;
    let cut = (f.h.len() > max_points).then_some(Warning::Truncated {
        file: name,
        found: f.h.len() as u64,
        kept: max_points,
        kept_s: None,
        after_trim_start: false,
    });
    if cut.is_some() {
        f.h.truncate(max_points);
        f.value.truncate(max_points);
        // What the whole file passed, its first points may not.
        check_content(&f, &format!(" in the first {max_points} points (--max-samples)"))?;
    }
    Ok((f, cut))
}

/// Parses loop text.
pub fn parse(name: &str, text: &str) -> Result<LoopFile> {
    // A spreadsheet's "CSV UTF-8" export starts with a byte order mark.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()).peekable();
    let Some(&(_, first)) = lines.peek() else { located!(name; "empty file") };
    let sep = loop_separator(first);
    if sep == ';' {
        located!(name, Some(1), None;
            "the file seems to separate columns with `;` (first line `{}`); loop files are comma- or \
             tab-separated, as in `{}`",
            echo(first),
            echo(&first.replace(';', ","))
        );
    }
    let cells: Vec<&str> = first.split(sep).map(str::trim).collect();
    let numeric = cells.iter().all(|c| c.parse::<f64>().is_ok());
    // Column indices and unit factors for H and the value.
    let (hi, vi, hf, vf, channel) = if numeric {
        if cells.len() != 2 {
            located!(name, Some(1), None; "{} unnamed columns; an unnamed loop file has two: H [A/m], B [T]", cells.len());
        }
        (0, 1, 1.0, 1.0, LoopChannel::FluxDensity)
    } else {
        lines.next();
        if let Some((a, b)) = duplicate(&cells) {
            located!(name, Some(1), Some(b as u64 + 1);
                "column `{}` appears twice (columns {} and {})", echo(cells[a]), a + 1, b + 1);
        }
        let find = |n: &str| cells.iter().position(|c| *c == n);
        if let Some(h) = find("field_A_per_m") {
            match (find("flux_density_T"), find("magnetization_A_per_m")) {
                (Some(b), _) => (h, b, 1.0, 1.0, LoopChannel::FluxDensity),
                (None, Some(m)) => (h, m, 1.0, 1.0, LoopChannel::Magnetization),
                _ => located!(name, Some(1), None;
                    "`field_A_per_m` needs `flux_density_T` or `magnetization_A_per_m` beside it"
                ),
            }
        } else if cells.len() == 2 {
            let (q0, f0) = match unit_factor(cells[0]) {
                Ok(q) => q,
                Err(why) => located!(name, Some(1), Some(1);
                    "header `{}`: {why} (e.g. `H(Oe)`; H first)", echo(cells[0])),
            };
            let (q1, f1) = match unit_factor(cells[1]) {
                Ok(q) => q,
                Err(why) => located!(name, Some(1), Some(2);
                    "header `{}`: {why} (e.g. `B(T)` or `M(kA/m)`)", echo(cells[1])),
            };
            if q0 != 'H' || !(q1 == 'B' || q1 == 'M') {
                located!(name, Some(1), None; "header `{}`: expected H then B or M", echo(first));
            }
            let ch = if q1 == 'B' { LoopChannel::FluxDensity } else { LoopChannel::Magnetization };
            (0, 1, f0, f1, ch)
        } else {
            located!(name, Some(1), None; "not a loop file: expected `field_A_per_m` and `flux_density_T` or `magnetization_A_per_m` columns, or two columns H, B");
        }
    };
    let ncols = cells.len();
    let (mut h, mut v) = (Vec::new(), Vec::new());
    for (idx, line) in lines {
        let lineno = idx + 1;
        let f: Vec<&str> = line.split(sep).map(str::trim).collect();
        if f.len() != ncols {
            located!(name, Some(lineno as u64), None; "{} fields, but the first line has {ncols}", f.len());
        }
        let num = |col: usize| -> Result<f64> {
            let at = (Some(lineno as u64), Some(col as u64 + 1));
            let Ok(x) = f[col].parse::<f64>() else {
                located!(name, at.0, at.1; "`{}` is not a number", echo(f[col]))
            };
            if !x.is_finite() {
                located!(name, at.0, at.1; "`{}` is not a finite number", echo(f[col]));
            }
            Ok(x)
        };
        let (hv, vv) = (num(hi)? * hf, num(vi)? * vf);
        if let Err(why) = plausible_point(channel, hv, vv) {
            located!(name, Some(lineno as u64), None; "{why}");
        }
        h.push(hv);
        v.push(vv);
    }
    if h.len() < 5 {
        located!(name; "{} points; a loop fit needs at least 5", h.len());
    }
    let f = LoopFile { name: name.to_string(), h, value: v, channel };
    check_content(&f, "")?;
    Ok(f)
}

/// The checks on a loop's points as a whole (`kept`: where they were cut, said in the message).
fn check_content(f: &LoopFile, kept: &str) -> Result<()> {
    let (name, what) = (&f.name, if f.channel == LoopChannel::FluxDensity { "B" } else { "M" });
    let (lo, hi) =
        f.value.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), x| (l.min(*x), u.max(*x)));
    if hi - lo <= 1e-9 * lo.abs().max(hi.abs()) {
        located!(name; "{what} does not vary{kept} (every point {lo:e}): a loop's {what} follows the field");
    }
    // A ferro- or ferrimagnet's magnetization rises with the field along a loop as a whole.
    let rho = crate::signal::correlation(&f.h, &f.magnetization());
    if rho < -0.5 {
        located!(name;
            "M falls as H rises{kept} (correlation {rho:.2}): a magnetic material's magnetization follows the \
             field; is the search coil or its integrator wired reversed, or the field's sign? negate {what} \
             (or H) in the file");
    }
    Ok(())
}

/// The smallest and largest of `v`.
fn span(v: &[f64]) -> (f64, f64) {
    v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), x| (l.min(*x), u.max(*x)))
}

/// A loop traversed clockwise in the H–M plane: a ferromagnet's loop runs counterclockwise (the
/// rising branch below the falling one), ∮ M dH < 0, so a positive area over 1 % of the loop's
/// bounding box says the rows are in reverse time order. Only for files that run (nearly) a
/// whole loop from an end of the field's range, or close on their first point: the H path's
/// total variation from there at least 1.8 × its range.
pub(crate) fn clockwise(f: &LoopFile) -> Option<Warning> {
    let (h_lo, h_hi) = span(&f.h);
    // From the first point at an end of the field's range: an initial magnetization curve before
    // it (from the demagnetized state) is not part of the loop, and closing it back to its start
    // would add its own area.
    let near_end = |h: f64| (h - h_lo).min(h_hi - h) <= 0.02 * (h_hi - h_lo);
    let all_m = f.magnetization();
    // A file that closes on its own first point (a whole cycle from mid-loop) is all loop.
    let (all_lo, all_hi) = span(&all_m);
    let (h_ends, m_ends) = ((f.h.first()?, f.h.last()?), (all_m.first()?, all_m.last()?));
    let closed = (h_ends.1 - h_ends.0).abs() <= 0.02 * (h_hi - h_lo)
        && (m_ends.1 - m_ends.0).abs() <= 0.02 * (all_hi - all_lo);
    let first = if closed { 0 } else { f.h.iter().position(|&h| near_end(h))? };
    let (h, m) = (&f.h[first..], &all_m[first..]);
    let (m_lo, m_hi) = span(m);
    let travel: f64 = h.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
    if travel < 1.8 * (h_hi - h_lo) {
        return None;
    }
    // ∮ M dH by trapezoids, closed from the last point back to the first.
    let n = h.len();
    let area: f64 = (0..n).map(|k| 0.5 * (m[k] + m[(k + 1) % n]) * (h[(k + 1) % n] - h[k])).sum();
    let share = area / ((h_hi - h_lo) * (m_hi - m_lo));
    (share > 0.01).then(|| Warning::LoopClockwise { file: f.name.clone(), share })
}

/// A loop driven symmetrically (H from −H_max to H_max within 5 %) whose magnetization is not
/// (its centre over 5 % of its half-swing off zero): a ferromagnet's symmetric loop is centred,
/// so it is most often a search coil integrator's offset, which the loop fit does not remove.
pub(crate) fn off_centre(f: &LoopFile) -> Option<Warning> {
    let (h_lo, h_hi) = span(&f.h);
    let (m_lo, m_hi) = span(&f.magnetization());
    let symmetric_drive = (h_hi + h_lo).abs() <= 0.05 * (h_hi - h_lo);
    let share = (m_hi + m_lo) / (m_hi - m_lo);
    (symmetric_drive && share.abs() > 0.05).then(|| Warning::LoopOffCentre {
        file: f.name.clone(),
        centre_a_per_m: 0.5 * (m_hi + m_lo),
        share,
        flux_density: f.channel == LoopChannel::FluxDensity,
    })
}

/// M/H at a loop's field extreme beyond which the loop is doubted. A Terfenol-D rod comes near
/// M_s ≈ 7.65e5 A/m at tens of kA/m (M/H of 15–150 there); with H in kA/m under an A/m header
/// the same loop reads 1000× that (1e4 and more for a loop to ±75 kA/m). Measured soft magnets
/// reach 1 100–5 500 (MnZn ferrites, M130 steel, an amorphous alloy: tests/data/measured-loops),
/// and stay below; a softer one (a permalloy at saturation) would be asked about too.
const MAX_SECANT_SUSCEPTIBILITY: f64 = 1e4;

/// A loop whose magnetization at its field extreme is over [`MAX_SECANT_SUSCEPTIBILITY`] times
/// that field: most often H in kA/m read as A/m (a J–A fit then returns a and k of a few A/m and
/// scores well: a plausible wrong answer), or a very soft magnet's loop.
pub(crate) fn field_in_kilo(f: &LoopFile) -> Option<Warning> {
    let (m_lo, m_hi) = span(&f.magnetization());
    let (h_lo, h_hi) = span(&f.h);
    let (h, m_peak) = (h_hi.max(-h_lo), m_hi.max(-m_lo));
    (h > 0.0 && m_peak / h > MAX_SECANT_SUSCEPTIBILITY).then(|| Warning::LoopFieldSmall {
        file: f.name.clone(),
        h_peak_a_per_m: h,
        m_peak_a_per_m: m_peak,
    })
}

/// Largest plausible field magnitude [A/m] (the strongest pulsed lab fields, ≈ 100 T).
const PLAUSIBLE_H: f64 = 1e8;
/// Largest plausible flux density [T] (as for a recording's `flux_density_T`).
const PLAUSIBLE_B: f64 = 1e2;
/// Largest plausible magnetization [A/m]: no material saturates beyond ≈ 2e6 A/m (Fe–Co:
/// μ0 M_s = 2.45 T), so five times that is a unit mistake.
const PLAUSIBLE_M: f64 = 1e7;

/// Whether one point (H [A/m] and the file's B [T] or M [A/m]) is physically plausible; the
/// error says why not, and which unit mistake it looks like.
fn plausible_point(channel: LoopChannel, h: f64, value: f64) -> std::result::Result<(), String> {
    if h.abs() > PLAUSIBLE_H {
        return Err(format!(
            "H = {h:e} A/m is beyond ±{PLAUSIBLE_H:e} A/m, not a plausible field: is H in A/m (a header \
             `H(kA/m)` or `H(Oe)` converts)?"
        ));
    }
    let m = match channel {
        LoopChannel::FluxDensity => {
            if value.abs() > PLAUSIBLE_B {
                return Err(format!(
                    "B = {value:e} T is beyond ±{PLAUSIBLE_B:e} T, not a plausible flux density: is B in T (a \
                     header `B(mT)` or `B(G)` converts)?"
                ));
            }
            value / MU0 - h
        }
        LoopChannel::Magnetization => value,
    };
    if m.abs() > PLAUSIBLE_M {
        let source = match channel {
            LoopChannel::FluxDensity => format!("M = B/μ0 − H = {m:e} A/m"),
            LoopChannel::Magnetization => format!("M = {m:e} A/m"),
        };
        return Err(format!(
            "{source} is beyond ±{PLAUSIBLE_M:e} A/m, more than any material (Fe–Co saturates at 1.95e6 \
             A/m): are B in T (or M in A/m) and H in A/m? (headers such as `B(mT)`, `M(kA/m)`, `H(Oe)` convert)"
        ));
    }
    Ok(())
}

/// The first pair of equal header cells (their indices), if any.
fn duplicate(cells: &[&str]) -> Option<(usize, usize)> {
    (0..cells.len()).find_map(|b| (0..b).find(|&a| cells[a] == cells[b]).map(|a| (a, b)))
}

/// Coercivity, remanence and saturation read from a loop (NaN when the path does not show it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LoopFeatures {
    /// Mean |H| where M crosses zero [A/m].
    pub coercivity_a_per_m: f64,
    /// Mean |M| where H crosses zero [A/m].
    pub remanence_a_per_m: f64,
    /// Largest |M| [A/m].
    pub max_magnetization_a_per_m: f64,
}

/// Reads the features from an (H, M) path by linear interpolation at the crossings.
pub fn features(h: &[f64], m: &[f64]) -> LoopFeatures {
    let crossings = |x: &[f64], y: &[f64]| -> f64 {
        let v: Vec<f64> = x
            .windows(2)
            .zip(y.windows(2))
            .filter(|(xw, _)| xw[0] * xw[1] < 0.0 || (xw[0] == 0.0 && xw[1] != 0.0))
            .map(|(xw, yw)| {
                let t = xw[0] / (xw[0] - xw[1]);
                (yw[0] + t * (yw[1] - yw[0])).abs()
            })
            .collect();
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    LoopFeatures {
        coercivity_a_per_m: crossings(m, h),
        remanence_a_per_m: crossings(h, m),
        max_magnetization_a_per_m: m.iter().fold(0.0f64, |a, v| a.max(v.abs())),
    }
}

/// The coercivity's label: the field where M crosses zero (intrinsic, H_cJ), not where B does.
pub const COERCIVITY_LABEL: &str = "coercivity H_cJ (M = 0) [A/m]";
/// The remanence's label: M where H crosses zero (B_r = μ0 M_r).
pub const REMANENCE_LABEL: &str = "remanence M_r (H = 0) [A/m]";

/// A loop feature as text: `—` where the loop has none (no crossing: NaN, null in JSON).
pub fn feature_text(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4e}")
    } else {
        "—".into()
    }
}
