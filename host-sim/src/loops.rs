//! Magnetization loops (docs/formats.md): B–H or M–H points in field order — full
//! loops, minor loops or single branches, unevenly spaced — and fitting the magnetization
//! models of model-core (the same code the firmware runs) along the file's own field path.

use std::path::Path;

use anyhow::{bail, Result};
use model_core::field::MU0;
use model_core::magnetization::{
    Anhysteretic, AnhystereticParams, JaParams, JaState, JaVariant, JilesAtherton, LinearMagnetization,
    Preisach, PreisachParams, MAX_SUBSTEPS,
};
use model_core::{ActuatorParams, MagnetizationLaw, ModelSpec};

use crate::files::{echo, Input};
use crate::located;
use crate::progress::Progress;
use crate::results::StartScore;
use crate::search::{minimize, Bound, Fidelity, Local, Plan, SearchOptions, Start};
use crate::warning::Warning;

/// The loop fit's search: two swarms (seeds `seed`, `seed + 1`), each best refined by a 5 % and
/// a 1 % simplex on every point.
const PLAN: Plan = Plan {
    particles: (10, 4),
    swarm_iters: 25.0,
    swarms: 2,
    simplex_iters_per_dim: 80.0,
    local_searches: 2,
    finalists: 2,
    local: &[Local::Simplex(0.05, Fidelity::Full), Local::Simplex(0.01, Fidelity::Full)],
    tolerance: (1e-7, 1e-20),
};

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

/// The separator a loop file's first line uses: a tab, a comma, or (refused by [`parse`] with a
/// hint, but still a loop file) a semicolon when the line has no comma.
fn separator(first: &str) -> char {
    if first.contains('\t') {
        '\t'
    } else if first.contains(';') && !first.contains(',') {
        ';'
    } else {
        ','
    }
}

/// Whether `text` looks like a loop file (named loop columns, or two columns with an H/B header
/// or none; separated by a semicolon too, so that such a file is told what is wrong with it).
pub fn looks_like_loop(text: &str) -> bool {
    let first = text.lines().next().unwrap_or("").to_ascii_lowercase();
    // A recording may log the field too: its displacement makes it a recording.
    if first.contains("displacement_um") {
        return false;
    }
    if first.contains("field_a_per_m") {
        return true;
    }
    if first.contains("time_s") {
        return false;
    }
    let sep = separator(&first);
    let fields: Vec<&str> = first.split(sep).collect();
    fields.len() == 2
        && (fields.iter().all(|f| f.trim().parse::<f64>().is_ok()) || first.trim_start().starts_with('h'))
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
    let sep = separator(first);
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
    let rho = crate::analysis::correlation(&f.h, &f.magnetization());
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
/// whole loop from an end of the field's range: the H path's total variation from there at
/// least 1.8 × its range.
fn clockwise(f: &LoopFile) -> Option<Warning> {
    let (h_lo, h_hi) = span(&f.h);
    // From the first point at an end of the field's range: an initial magnetization curve before
    // it (from the demagnetized state) is not part of the loop, and closing it back to its start
    // would add its own area.
    let near_end = |h: f64| (h - h_lo).min(h_hi - h) <= 0.02 * (h_hi - h_lo);
    let first = f.h.iter().position(|&h| near_end(h))?;
    let all_m = f.magnetization();
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
fn off_centre(f: &LoopFile) -> Option<Warning> {
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

/// The magnetization model a loop fit identifies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoopModel {
    /// M = a + bH.
    Linear,
    /// Langevin.
    Anhysteretic,
    /// Jiles–Atherton, in one of its variants.
    JilesAtherton(JaVariant),
    /// Preisach.
    Preisach,
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

/// |α| from which a J–A loop fit is said to be at the model's limit |α| < 1.
const ALPHA_LIMIT_WARNING: f64 = 0.999;

/// Largest saturation magnetization of any bulk material [A/m]: Fe–Co alloys, μ0 M_s ≈ 2.45 T.
/// The loop fit's M_s range ends here (or at 1.5× the file's largest |M| if a file exceeds it).
pub const MAX_SATURATION_A_PER_M: f64 = 1.95e6;

/// The J–A mean-field ratio α·M_s/(3a) the loop fit searches, instead of α: below 1 the
/// anhysteretic curve is single-valued (the physics limit, whatever the material's scale), and
/// down to −1 a negative α (002) may at most halve the initial susceptibility.
const MEAN_FIELD_RATIO: (f64, f64) = (-1.0, 0.99);

impl LoopModel {
    /// From a model spec (only the magnetization stage counts) and the parameter set that says
    /// which J–A variant.
    pub fn from_spec(spec: ModelSpec, params: &ActuatorParams) -> Result<Self> {
        if let Some(e) = spec.effects().find(|e| e.info().law.is_none()) {
            bail!(
                "a magnetization loop fits the magnetization stage only; `{e}` needs displacement recordings"
            );
        }
        Ok(match spec.law() {
            MagnetizationLaw::Linear => LoopModel::Linear,
            MagnetizationLaw::Anhysteretic => LoopModel::Anhysteretic,
            MagnetizationLaw::JilesAtherton => LoopModel::JilesAtherton(params.ja.variant),
            MagnetizationLaw::Preisach => LoopModel::Preisach,
        })
    }

    /// This model's parameters in a parameter set, in the order of its bounds (the inverse of
    /// [`LoopFit::apply_to`]).
    pub fn values_of(self, p: &ActuatorParams) -> Vec<f64> {
        let v: Vec<f32> = match self {
            LoopModel::Linear => vec![p.linear.offset_a_per_m, p.linear.susceptibility],
            LoopModel::Anhysteretic => vec![p.anhysteretic.ms_a_per_m, p.anhysteretic.a_a_per_m],
            LoopModel::JilesAtherton(_) => {
                let j = p.ja;
                vec![j.ms_a_per_m, j.a_a_per_m, j.alpha, j.k_a_per_m, j.c]
            }
            LoopModel::Preisach => {
                let q = p.preisach;
                let su = q.interaction_spread_a_per_m.unwrap_or(q.spread_a_per_m);
                vec![
                    q.ms_a_per_m,
                    q.coercive_a_per_m,
                    q.spread_a_per_m,
                    su,
                    q.h_max_a_per_m,
                    q.reversible_fraction_or_default(),
                    q.reversible_field_or_default(),
                ]
            }
        };
        v.into_iter().map(f64::from).collect()
    }

    /// The search's parameter names and bounds, given the loop's field and magnetization scale.
    /// M_s lies between the largest measured |M| (less 10 % for noise) and the largest
    /// saturation of any material; J–A searches the mean-field ratio α·M_s/(3a) in
    /// [`MEAN_FIELD_RATIO`] instead of α, so no point of its box is multivalued. The field
    /// scales (a, k, the Preisach fields) span the data's range and the model's own limits.
    fn bounds(self, h_max: f64, m_max: f64) -> Vec<Bound> {
        // Within what the models accept (a weak sample's M_s below theirs is held at their floor,
        // a loop far from saturation, and said as a parameter at its range's end).
        let (ms_min, ms_max) = (f64::from(model_core::error::MS_MIN), f64::from(model_core::error::MS_MAX));
        let ms = Bound::log(
            "ms_a_per_m",
            (0.9 * m_max).clamp(ms_min, 0.5 * ms_max),
            MAX_SATURATION_A_PER_M.max(1.5 * m_max).min(ms_max),
        );
        let field = |name, lo: f64, hi: f64| Bound::log(name, lo.max(1.0), hi.max(10.0));
        match self {
            LoopModel::Linear => {
                vec![Bound::lin("offset_a_per_m", -m_max, m_max), Bound::log("susceptibility", 1e-3, 1e6)]
            }
            LoopModel::Anhysteretic => vec![ms, field("a_a_per_m", 1e-4 * h_max, 10.0 * h_max)],
            LoopModel::JilesAtherton(v) => vec![
                ms,
                field("a_a_per_m", 1e-4 * h_max, 10.0 * h_max),
                Bound::lin("mean_field_ratio", MEAN_FIELD_RATIO.0, MEAN_FIELD_RATIO.1),
                field("k_a_per_m", 1e-4 * h_max, 5.0 * h_max),
                // The total-magnetization form weighs reversibility by c/(1 + c): c near 1 is common.
                Bound::lin("c", 0.0, if v.is_total_magnetization() { 0.9999 } else { 0.99 }),
            ],
            LoopModel::Preisach => vec![
                ms,
                field("coercive_a_per_m", 1e-3 * h_max, 0.8 * h_max),
                field("spread_a_per_m", 1e-3 * h_max, 2.0 * h_max),
                field("interaction_spread_a_per_m", 1e-3 * h_max, 2.0 * h_max),
                // The relay plane's range is the field where the material saturates, which can lie
                // well inside the measured range (hard magnets): fitted, since the fixed grid's
                // resolution is 2·H_max/31 and a plane wider than needed blurs the switching.
                Bound::log("h_max_a_per_m", 0.2 * h_max, 1.05 * h_max),
                // The reversible part: what moves at once after a reversal (ferrites, soft steel).
                Bound::lin("reversible_fraction", 0.0, 0.9),
                field("reversible_field_a_per_m", 1e-3 * h_max, 2.0 * h_max),
            ],
        }
    }

    /// The model's parameters (as [`run`] takes them) from the search's: J–A's α from the ratio.
    fn model_values(self, v: &[f64]) -> Vec<f64> {
        match self {
            LoopModel::JilesAtherton(_) => vec![v[0], v[1], 3.0 * v[1] * v[2] / v[0], v[3], v[4]],
            _ => v.to_vec(),
        }
    }

    /// The search's parameters from the model's (the inverse of `model_values`).
    fn search_values(self, v: &[f64]) -> Vec<f64> {
        match self {
            LoopModel::JilesAtherton(_) => vec![v[0], v[1], v[2] * v[0] / (3.0 * v[1]), v[3], v[4]],
            _ => v.to_vec(),
        }
    }

    /// A start read off the loops' shape (search parameters), as Jiles, Thoelke & Devine (1992)
    /// seed J–A from measured loop features: M_s just above the largest |M|, the pinning k at
    /// the coercivity and a at the field of half the largest |M|, a middling mean-field ratio and
    /// reversibility. `None` for other models or loops that show no coercivity.
    fn start_from_features(self, files: &[LoopFile]) -> Option<Vec<f64>> {
        if !matches!(self, LoopModel::JilesAtherton(_)) {
            return None;
        }
        let f = files.first()?;
        let m = f.magnetization();
        let feat = features(&f.h, &m);
        let m_max = feat.max_magnetization_a_per_m;
        let h_half =
            f.h.iter()
                .zip(&m)
                .filter(|(_, m)| m.abs() >= 0.5 * m_max)
                .map(|(h, _)| h.abs())
                .fold(f64::INFINITY, f64::min);
        let hc = feat.coercivity_a_per_m;
        (hc.is_finite() && hc > 0.0 && h_half.is_finite() && h_half > 0.0)
            .then(|| vec![1.05 * m_max, h_half, 0.5, hc, 0.2])
    }

    /// The model's parameter names, in [`run`]'s order.
    fn names(self) -> &'static [&'static str] {
        match self {
            LoopModel::Linear => &["offset_a_per_m", "susceptibility"],
            LoopModel::Anhysteretic => &["ms_a_per_m", "a_a_per_m"],
            LoopModel::JilesAtherton(_) => &["ms_a_per_m", "a_a_per_m", "alpha", "k_a_per_m", "c"],
            LoopModel::Preisach => &[
                "ms_a_per_m",
                "coercive_a_per_m",
                "spread_a_per_m",
                "interaction_spread_a_per_m",
                "h_max_a_per_m",
                "reversible_fraction",
                "reversible_field_a_per_m",
            ],
        }
    }
}

/// Why a model run along a path is not a valid result.
#[derive(Debug, Clone, PartialEq)]
pub struct RunError(pub String);

/// The model's magnetization along the file's field path. The rod starts demagnetised at
/// H = 0, follows the initial curve to the first point, then the path; a closed path (ends
/// where it starts) is run twice and the second pass returned (the loop's steady state).
pub fn run(model: LoopModel, p: &[f64], h: &[f64], h_max: f64) -> Result<Vec<f64>, RunError> {
    let closed = (h[0] - h[h.len() - 1]).abs() <= 0.02 * h_max;
    let lead: Vec<f64> = (1..=50).map(|k| h[0] * k as f64 / 50.0).collect();
    let passes = if closed { 2 } else { 1 };
    let path = lead.iter().chain((0..passes).flat_map(|_| h.iter()));
    let mut out = Vec::with_capacity(lead.len() + passes * h.len());
    match model {
        LoopModel::Linear => {
            let lm =
                LinearMagnetization::new(p[0] as f32, p[1] as f32).map_err(|e| RunError(e.to_string()))?;
            out.extend(path.map(|&x| lm.magnetization(x as f32) as f64));
        }
        LoopModel::Anhysteretic => {
            let an =
                Anhysteretic::new(AnhystereticParams { ms_a_per_m: p[0] as f32, a_a_per_m: p[1] as f32 })
                    .map_err(|e| RunError(e.to_string()))?;
            out.extend(path.map(|&x| an.magnetization(x as f32) as f64));
        }
        LoopModel::JilesAtherton(variant) => {
            let jp = JaParams {
                ms_a_per_m: p[0] as f32,
                a_a_per_m: p[1] as f32,
                alpha: p[2] as f32,
                k_a_per_m: p[3] as f32,
                c: p[4] as f32,
                variant,
            };
            let ja = JilesAtherton::new(jp).map_err(|e| RunError(e.to_string()))?;
            let mut s = JaState::default();
            // A loop file's points are far apart next to a small a or k: step the field between
            // them in legs of at most a quarter of what one J–A call integrates to its accuracy
            // (the mean field can lengthen the effective step), so the sub-step cap never cuts
            // the integration short and no fit can profit from an unresolved loop.
            let leg = 0.25 * MAX_SUBSTEPS as f64 * ja.max_substep_a_per_m() as f64;
            let mut last = 0.0f64;
            out.extend(path.map(|&x| {
                let legs = ((x - last).abs() / leg).ceil().clamp(1.0, 1e6) as u32;
                for j in 1..legs {
                    ja.step(&mut s, (last + (x - last) * j as f64 / legs as f64) as f32);
                }
                last = x;
                ja.step(&mut s, x as f32) as f64
            }));
        }
        LoopModel::Preisach => {
            let pr = Preisach::new(PreisachParams {
                ms_a_per_m: p[0] as f32,
                coercive_a_per_m: p[1] as f32,
                spread_a_per_m: p[2] as f32,
                interaction_spread_a_per_m: Some(p[3] as f32),
                reversible_fraction: Some(p[5] as f32),
                reversible_field_a_per_m: Some(p[6] as f32),
                h_max_a_per_m: p[4] as f32,
            })
            .map_err(|e| RunError(e.to_string()))?;
            let mut s = pr.demagnetized();
            out.extend(path.map(|&x| pr.step(&mut s, x as f32) as f64));
        }
    }
    let tail = out.split_off(out.len() - h.len());
    if tail.iter().any(|v| !v.is_finite()) {
        return Err(RunError("the integration produced a non-finite magnetization".into()));
    }
    Ok(tail)
}

/// rms(a − b) / (max − min of a).
fn nrmse(a: &[f64], b: &[f64]) -> f64 {
    crate::fit::nrmse(a, b)
}

/// A loop fit's outcome.
#[derive(Debug, Clone)]
pub struct LoopFit {
    /// The model.
    pub model: LoopModel,
    /// Identified (name, value).
    pub params: Vec<(&'static str, f64)>,
    /// NRMSE per file on its own channel.
    pub nrmse: Vec<f64>,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Doubts about the result; those that [`Warning::invalidates`] make it invalid (no
    /// parameter file may be written from it).
    pub warnings: Vec<Warning>,
    /// The search stopped at `--time-limit`: the best point so far.
    pub time_limited: bool,
    /// How the start values scored, and whether they were returned.
    pub start: StartScore,
}

impl LoopFit {
    /// The identified values in order.
    pub fn values(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.1).collect()
    }

    /// The parameter set with this fit's magnetization model written in (`M_s` also normalises
    /// the magnetostriction), to seed a displacement fit.
    pub fn apply_to(&self, base: &ActuatorParams) -> ActuatorParams {
        let mut p = *base;
        let v = self.values();
        match self.model {
            LoopModel::Linear => {
                p.linear.offset_a_per_m = v[0] as f32;
                p.linear.susceptibility = v[1] as f32;
            }
            LoopModel::Anhysteretic => {
                p.anhysteretic = AnhystereticParams { ms_a_per_m: v[0] as f32, a_a_per_m: v[1] as f32 };
                p.magnetostriction.ms_a_per_m = v[0] as f32;
            }
            LoopModel::JilesAtherton(variant) => {
                p.ja = JaParams {
                    ms_a_per_m: v[0] as f32,
                    a_a_per_m: v[1] as f32,
                    alpha: v[2] as f32,
                    k_a_per_m: v[3] as f32,
                    c: v[4] as f32,
                    variant,
                };
                p.anhysteretic.ms_a_per_m = v[0] as f32;
                p.magnetostriction.ms_a_per_m = v[0] as f32;
            }
            LoopModel::Preisach => {
                p.preisach.ms_a_per_m = v[0] as f32;
                p.preisach.coercive_a_per_m = v[1] as f32;
                p.preisach.spread_a_per_m = v[2] as f32;
                p.preisach.interaction_spread_a_per_m = Some(v[3] as f32);
                p.preisach.h_max_a_per_m = v[4] as f32;
                p.preisach.reversible_fraction = Some(v[5] as f32);
                p.preisach.reversible_field_a_per_m = Some(v[6] as f32);
                p.magnetostriction.ms_a_per_m = v[0] as f32;
            }
        }
        p
    }
}

/// Why J–A values cannot be used: α·M_s/(3a) ≥ 1 (the anhysteretic is multivalued).
fn multivalued(model: LoopModel, v: &[f64]) -> Option<f64> {
    // Only J–A has a mean field (the other laws have fewer values: index them only for J–A).
    let LoopModel::JilesAtherton(_) = model else { return None };
    let ratio = v[2] * v[0] / (3.0 * v[1]);
    (ratio >= 1.0).then_some(ratio)
}

/// Mean NRMSE over `files` of the model at `values` (its own parameters), or why it cannot run.
fn mean_nrmse(
    model: LoopModel,
    values: &[f64],
    files: &[LoopFile],
    h_max: f64,
) -> Result<Vec<f64>, RunError> {
    files
        .iter()
        .map(|f| run(model, values, &f.h, h_max).map(|m| nrmse(&f.value, &f.channel_from_m(&m))))
        .collect()
}

/// Fits `model` to the loops jointly, starting from (and never ending worse than) the model's
/// parameters in `start`.
pub fn fit(
    model: LoopModel,
    files: &[LoopFile],
    start: &ActuatorParams,
    opts: SearchOptions,
) -> Result<LoopFit> {
    fit_shown(model, files, start, opts, false)
}

/// As [`fit`], showing its progress on stderr when `show` (a bar on a terminal, else a line
/// every 5 s: a fit on a long loop takes minutes).
pub fn fit_shown(
    model: LoopModel,
    files: &[LoopFile],
    start: &ActuatorParams,
    opts: SearchOptions,
    show: bool,
) -> Result<LoopFit> {
    let h_max = files.iter().flat_map(|f| f.h.iter()).fold(0.0f64, |a, v| a.max(v.abs()));
    let m_max = files.iter().flat_map(|f| f.magnetization()).fold(0.0f64, |a, v| a.max(v.abs()));
    if !(h_max > 0.0 && m_max > 0.0) {
        bail!("the loop has no field or no magnetization excursion");
    }
    let bounds = model.bounds(h_max, m_max);
    // Through no more points than parameters any law passes, whatever the material.
    let points: usize = files.iter().map(|f| f.h.len()).sum();
    if points <= bounds.len() {
        bail!(
            "{points} loop points in all ({}) for the {} parameters of the law: a fit through no more points than \
             parameters is not determined by them; give the whole loop (both branches, tens of points or more), \
             or raise --max-samples if it cut the file",
            files.iter().map(|f| format!("{}: {}", f.name, f.h.len())).collect::<Vec<_>>().join(", "),
            bounds.len()
        );
    }
    let targets: Vec<Vec<f64>> = files.iter().map(|f| f.value.clone()).collect();
    let cost = |_: &(), v: &[f64], _: Fidelity| -> f64 {
        let p = model.model_values(v);
        let mut sum = 0.0;
        for (f, t) in files.iter().zip(&targets) {
            match run(model, &p, &f.h, h_max) {
                Ok(m) => {
                    let e = nrmse(t, &f.channel_from_m(&m));
                    sum += e * e;
                }
                Err(_) => return 10.0,
            }
        }
        let c = sum / files.len() as f64;
        if c.is_finite() {
            c
        } else {
            f64::MAX / 4.0
        }
    };
    // The start: scored as given; the search starts from it clamped into the box.
    let start_values = model.values_of(start);
    let start_score = match multivalued(model, &start_values) {
        Some(ratio) => Err(format!(
            "α·M_s/(3a) = {ratio:.2} ≥ 1: the anhysteretic curve is multivalued there, not a valid J–A model"
        )),
        None => mean_nrmse(model, &start_values, files, h_max).map_err(|e| e.0),
    };
    let mut starts: Vec<Start<()>> = match &start_score {
        Ok(_) => vec![Start::new(model.search_values(&start_values), ())],
        Err(_) => Vec::new(),
    };
    starts.extend(model.start_from_features(files).map(|values| Start::new(values, ())));
    // The bar's length: both swarms, then each local search's simplex runs (at most).
    let d = bounds.len() as u64;
    let swarm_iters = ((PLAN.swarm_iters * opts.effort).round() as u64).max(2);
    let simplex = ((PLAN.simplex_iters_per_dim * d as f64 * opts.effort).round() as u64).max(20);
    let planned =
        PLAN.swarms as u64 * (PLAN.particles.0 + PLAN.particles.1 * d as usize) as u64 * (swarm_iters + 1)
            + PLAN.local_searches as u64 * PLAN.local.len() as u64 * simplex;
    let progress = Progress::new(&format!("loop fit ({points} points)"), planned, show);
    let found = minimize(&bounds, &cost, None, &(), &starts, &PLAN, opts, &progress)?;
    progress.finish_and_clear();
    // As a parameter set holds them (f32), and as the model runs them: what is reported is what
    // `--params-out` writes, at the NRMSE it was scored at.
    let mut best: Vec<f64> = model.model_values(&found.best).iter().map(|&v| v as f32 as f64).collect();
    let mut warnings = Vec::new();
    let mut per_file = Vec::new();
    for f in files {
        match run(model, &best, &f.h, h_max) {
            Ok(m) => per_file.push(nrmse(&f.value, &f.channel_from_m(&m))),
            Err(RunError(e)) => {
                warnings.push(Warning::IntegrationFailed { file: f.name.clone(), why: e });
                per_file.push(f64::NAN);
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mut kept = false;
    if let Ok(start_nrmse) = &start_score {
        let found_mean = mean(&per_file);
        if found_mean.is_nan() || found_mean > mean(start_nrmse) {
            kept = true;
            best = start_values.clone();
            per_file = start_nrmse.clone();
            warnings.retain(|w| !matches!(w, Warning::IntegrationFailed { .. }));
            warnings.push(Warning::StartKept { start_nrmse: mean(start_nrmse), found_nrmse: found_mean });
        }
    }
    let params: Vec<(&'static str, f64)> = model.names().iter().copied().zip(best.iter().copied()).collect();
    if !kept {
        for (b, v) in bounds.iter().zip(&found.best) {
            if b.at_edge(*v) {
                // The search's own coordinate for J–A's α, said as the ratio it is.
                let param = if b.name == "mean_field_ratio" { "α·M_s/(3a)" } else { b.name };
                warnings.push(Warning::AtEdge { param, value: *v, lo: b.lo, hi: b.hi });
                if b.name == "mean_field_ratio" && *v > 0.0 {
                    warnings.push(Warning::SquarerThanJa { ratio: *v });
                }
            }
        }
        // J–A's α is not searched (its ratio is), but the model holds it in (−1, 1): a fit
        // pressed against that limit is held by it, not by the loop.
        if let (LoopModel::JilesAtherton(_), Some(&alpha)) = (model, best.get(2)) {
            if alpha.abs() >= ALPHA_LIMIT_WARNING {
                warnings.push(Warning::AlphaAtLimit { alpha });
            }
        }
    }
    // A loop whose largest |M| is below the smallest M_s the models hold.
    let ms_floor = f64::from(model_core::error::MS_MIN);
    if m_max < ms_floor && !matches!(model, LoopModel::Linear) {
        warnings.push(Warning::WeakLoop { max_magnetization_a_per_m: m_max, ms_floor_a_per_m: ms_floor });
    }
    if let Some(ratio) = multivalued(model, &best) {
        warnings.push(Warning::Multivalued { ratio });
    }
    // First: an offset explains the edge and squareness warnings it causes.
    warnings.splice(0..0, files.iter().filter_map(off_centre).chain(files.iter().filter_map(clockwise)));
    let start = match start_score {
        Ok(e) => StartScore { nrmse: Some(mean(&e)), kept, refused: None, seen_mode: None },
        Err(why) => StartScore { nrmse: None, kept: false, refused: Some(why), seen_mode: None },
    };
    Ok(LoopFit {
        model,
        params,
        nrmse: per_file,
        evaluations: found.evaluations,
        warnings,
        time_limited: found.time_limited,
        start,
    })
}

/// The loop chart of one file: measured and modelled, H in kA/m.
pub fn chart(f: &LoopFile, m: &[f64], label: &str) -> crate::plots::Chart {
    use crate::plots::{Chart, Series};
    let modelled = f.channel_from_m(m);
    let (unit, scale) = match f.channel {
        LoopChannel::FluxDensity => ("flux density B [T]", 1.0),
        LoopChannel::Magnetization => ("magnetization M [kA/m]", 1e-3),
    };
    Chart {
        title: format!("{} — {label}", f.name),
        x_label: "field H [kA/m]".into(),
        y_label: unit.into(),
        y_range: None,
        series: vec![
            Series {
                label: "measured".into(),
                points: f.h.iter().zip(&f.value).map(|(h, v)| (h * 1e-3, v * scale)).collect(),
                color: 0,
            },
            Series {
                label: format!("model {label}"),
                points: f.h.iter().zip(&modelled).map(|(h, v)| (h * 1e-3, v * scale)).collect(),
                color: 1,
            },
        ],
    }
}

/// A self-contained HTML page for a loop fit: parameters, warnings, per-file error, loops
/// overlaid, and coercivity, remanence and largest |M| side by side.
pub fn html(
    spec: &str,
    fit: &LoopFit,
    files: &[LoopFile],
    val_files: &[LoopFile],
) -> Result<(String, Vec<f64>)> {
    use std::fmt::Write as _;
    let reach = |fs: &[&LoopFile]| fs.iter().flat_map(|f| f.h.iter()).fold(0.0f64, |a, v| a.max(v.abs()));
    // As `gma fit` scores them: the fit files at their own reach, validation files at the reach
    // of all files.
    let h_fit = reach(&files.iter().collect::<Vec<_>>());
    let h_all = reach(&files.iter().chain(val_files).collect::<Vec<_>>());
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>gma loop fit — {spec}</title>\
         <style>body{{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}td.l{{text-align:left}}.w{{color:#b00}}</style>\
         </head><body><h1>Magnetization loop fit — <code>{spec}</code></h1><p>{} evaluations; {} fit file(s), {} \
         validation file(s) (scored, never fitted).</p><table><tr><th>parameter</th><th>value</th></tr>",
        fit.evaluations,
        files.len(),
        val_files.len()
    );
    for (n, v) in &fit.params {
        let _ = write!(h, "<tr><td class=l>{n}</td><td>{v:.5e}</td></tr>");
    }
    h.push_str("</table>");
    for w in &fit.warnings {
        let _ = write!(h, "<p class=w>warning: {}</p>", w.to_string().replace('<', "&lt;"));
    }
    let mut val_nrmse = Vec::new();
    let roles =
        files.iter().map(|f| (f, "fit", h_fit)).chain(val_files.iter().map(|f| (f, "validation", h_all)));
    for (f, role, h_max) in roles {
        let m = run(fit.model, &fit.values(), &f.h, h_max)
            .map_err(|e| crate::error::InRecording::error(&f.name, e.0))?;
        let e = nrmse(&f.value, &f.channel_from_m(&m));
        if role == "validation" {
            val_nrmse.push(e);
        }
        let (a, b) = (features(&f.h, &f.magnetization()), features(&f.h, &m));
        let _ = write!(
            h,
            "<h2>{} ({role})</h2><p>NRMSE {:.3} % ({})</p><table><tr><th></th><th>measured</th><th>model</th></tr>\
             <tr><td class=l>{COERCIVITY_LABEL}</td><td>{}</td><td>{}</td></tr>\
             <tr><td class=l>{REMANENCE_LABEL}</td><td>{}</td><td>{}</td></tr>\
             <tr><td class=l>largest |M| [A/m]</td><td>{}</td><td>{}</td></tr></table>{}",
            f.name.replace('<', "&lt;"),
            e * 100.0,
            f.channel.name(),
            feature_text(a.coercivity_a_per_m),
            feature_text(b.coercivity_a_per_m),
            feature_text(a.remanence_a_per_m),
            feature_text(b.remanence_a_per_m),
            feature_text(a.max_magnetization_a_per_m),
            feature_text(b.max_magnetization_a_per_m),
            crate::plots::svg(&chart(f, &m, spec), (900, 520))?
        );
    }
    h.push_str("</body></html>");
    Ok((h, val_nrmse))
}
