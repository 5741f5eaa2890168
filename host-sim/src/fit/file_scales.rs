//! Files of one rig whose displacement per unit drive disagrees: a probe range switched for one
//! file, a sensitivity entered for another probe, a file of another rig. A joint fit bends every
//! parameter to split the difference (the law's curvature, the per-file start states) and can
//! even match each file's spread, so the check is a fit without the file the joint fit follows
//! worst, run on that file's drive.

use anyhow::Result;
use model_core::ActuatorParams;

use super::plausible::{demagnetised_run, spread};
use super::{fit_constrained, Constraints, FitOptions, FitResult};
use crate::data_doubts::DataDoubt;
use crate::recording::Recording;
use crate::signal::correlation;
use crate::simulation::{drive_for, run_model, Drive, Prepared};
use crate::warning::Warning;

/// How many times worse than every other file the joint fit must follow one file for it to be
/// checked (the check is one more fit): a file at 3× the others' probe gain stands out by 3.2×
/// in a black-box lab's joint fit, where the others bend to it too.
const OUTLIER_NRMSE: f64 = 2.5;

/// How many times the file's displacement spread may differ from what the other files' model
/// makes of its drive before the scales are said to disagree: a rig's files agree within tens
/// of percent once the model holds the drive's amplitude, bias and frequency; a range switch
/// moves one file by 3–10×.
const GAINS_DISAGREE: f64 = 2.0;

/// How far apart (a ratio) one file's displacement spread, against the joint fit's model run
/// on its drive, must stand from every other file's for it to be checked: a rig's own files at
/// different drives agree within tens of percent; a file at half the gain stands about 2× apart.
const ODD_SCALE: f64 = 1.6;

/// The file among `files` whose ratio of measured to modelled displacement spread (the joint
/// fit's model, run demagnetised on each file's drive) lies [`ODD_SCALE`] or more beyond every
/// other file's, on one side; `None` when none does.
fn odd_scale(joint: &FitResult, files: &[Recording]) -> Result<Option<usize>> {
    let mut logs = Vec::with_capacity(files.len());
    for rec in files {
        let (Some(y), Some(sim)) =
            (rec.displacement_um.as_deref(), demagnetised_run(joint.spec, &joint.params, rec)?)
        else {
            return Ok(None);
        };
        let ratio = spread(y) / spread(&sim.displacement_um);
        if !(ratio.is_finite() && ratio > 0.0) {
            return Ok(None);
        }
        logs.push(ratio.ln());
    }
    let apart = |k: usize| -> f64 {
        let others = logs.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, v)| *v);
        let (lo, hi) = others.fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(v), h.max(v)));
        (logs[k] - hi).max(lo - logs[k])
    };
    let k = (0..logs.len()).max_by(|&a, &b| apart(a).total_cmp(&apart(b)));
    Ok(k.filter(|&k| apart(k) >= ODD_SCALE.ln()))
}

/// The file among `files` whose displacement the other files' model, fitted without it
/// (from `start` and the joint fit's result), makes [`GAINS_DISAGREE`] times too small or too
/// large on its own drive, when the joint fit `joint` followed it [`OUTLIER_NRMSE`] times worse
/// than every other file, or its scale stands apart ([`odd_scale`]); or whose drive reads at
/// another scale ([`drive_scale`]). One more fit, only when a file stands out so; with two
/// files, two ([`pair_disagrees`]). With the warning, the parameters fitted without the file
/// (more than two files).
fn scale_outlier(
    start: &ActuatorParams,
    joint: &FitResult,
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
) -> Result<Option<(Warning, Option<ActuatorParams>)>> {
    let scores: Vec<f64> = joint.fit.files.iter().map(|s| s.nrmse).collect();
    let Some(worst) = (0..scores.len()).max_by(|&a, &b| scores[a].total_cmp(&scores[b])) else {
        return Ok(None);
    };
    let others_worst =
        scores.iter().enumerate().filter(|(k, _)| *k != worst).map(|(_, s)| *s).fold(0.0, f64::max);
    if files.len() < 2 {
        return Ok(None);
    }
    // The file the joint fit follows worst, or else the one whose scale stands apart (a file at
    // a lower gain reads small against its own range, and the others bend more).
    let worst = if scores[worst] >= OUTLIER_NRMSE * others_worst {
        worst
    } else {
        match odd_scale(joint, files)? {
            Some(k) => k,
            None => return Ok(None),
        }
    };
    let quiet = FitOptions { progress: false, ..opts };
    if files.len() == 2 {
        return Ok(pair_disagrees(start, joint, files, quiet, constraints)?.map(|w| (w, None)));
    }
    let others: Vec<Recording> =
        files.iter().enumerate().filter(|(k, _)| *k != worst).map(|(_, r)| r.clone()).collect();
    let Some((ratio, without)) = scale_without(start, joint, &others, &files[worst], quiet, constraints)?
    else {
        return Ok(None);
    };
    let drive = drive_scale(joint, &without, &files[worst], ratio)?;
    if let Some(d) = drive.filter(DriveScale::is_off) {
        let (file, column) = (files[worst].name.clone(), drive_column(joint, &files[worst])?);
        let DriveScale { scale, rescaled, as_logged } = d;
        let w = Warning::DriveScaleOff { file, column, scale, rescaled, as_logged, pair: None };
        return Ok(Some((w, Some(without.params))));
    }
    // A model that follows the file at no probe gain says nothing of its gain (a drive far
    // smaller than the others', which the model fitted to them does not carry to).
    let carries = drive.is_none_or(|d| d.as_logged <= GAIN_READING_CARRIES);
    if (1.0 / GAINS_DISAGREE..GAINS_DISAGREE).contains(&ratio) || !carries {
        return Ok(None);
    }
    let followed = without
        .fit
        .files
        .iter()
        .map(|s| s.nrmse)
        .fold((f64::MAX, f64::MIN), |(l, h), s| (l.min(s), h.max(s)));
    let w = Warning::GainsDisagree {
        file: files[worst].name.clone(),
        gain: ratio,
        joint_nrmse: scores[worst],
        others_nrmse: followed,
        doubted_from: GAINS_DISAGREE,
        pair: None,
    };
    Ok(Some((w, Some(without.params))))
}

/// `rec`'s displacement spread against what the model fitted to `others` (from `start` and the
/// joint fit's result) makes of its drive from the demagnetised rod, and that fit; `None` where
/// the fit or the run fails.
fn scale_without(
    start: &ActuatorParams,
    joint: &FitResult,
    others: &[Recording],
    rec: &Recording,
    quiet: FitOptions,
    constraints: &Constraints,
) -> Result<Option<(f64, FitResult)>> {
    let Ok(without) = fit_constrained(joint.spec, &[*start, joint.params], others, quiet, constraints) else {
        return Ok(None);
    };
    let (Some(y), Some(sim)) =
        (rec.displacement_um.as_deref(), demagnetised_run(joint.spec, &without.params, rec)?)
    else {
        return Ok(None);
    };
    let ratio = spread(y) / spread(&sim.displacement_um);
    Ok((ratio.is_finite() && ratio > 0.0).then_some((ratio, without)))
}

/// The drive scales first tried: 2^(k/4) for |k| ≤ 20 (1/32 to 32: a clamp or monitor at
/// another range, mA read as A), then refined between the best one's neighbours.
const DRIVE_SCALE_STEPS: i32 = 20;

/// How many times less of a file's spread (rms) the other files' model must leave unexplained
/// with the file's drive rescaled (displacement as logged) than with its drive as logged
/// (displacement at its best gain and zero) for the drive's scale to be said: a probe's gain
/// keeps the waveform's shape and a drive's scale does not (the strain is nonlinear in the
/// current), so a file whose displacement is off is followed best at its own drive.
const DRIVE_SCALE_BETTER: f64 = 2.0;

/// A drive scale within this ratio of 1 is the file's own.
const DRIVE_SCALE_OWN: f64 = 1.25;

/// The share of a file's displacement spread (rms) a rescaled drive may leave unexplained and
/// still be said: the other files' model then carries to this file's drive (4 % on the textbook
/// rig's files with a current at 0.1–10×), and the scale is no accident of a model that does
/// not (a legitimate drive far smaller than the others' was followed at 26 % with its current
/// × 1.3).
const DRIVE_SCALE_EXPLAINS: f64 = 0.1;

/// The share of a file's displacement spread (rms) the other files' model may leave
/// unexplained at the file's best probe gain for that gain to be read at all: a legitimate
/// drive a fifth of the others' (a small loop the model fitted to large ones does not carry
/// to) left 28 % and read as a 0.40× probe; files at 1/3–10× the probe gain leave 4 %.
const GAIN_READING_CARRIES: f64 = 0.2;

/// The file's drive column: the one the model is driven by.
fn drive_column(joint: &FitResult, rec: &Recording) -> Result<&'static str> {
    Ok(match drive_for(joint.spec, rec)? {
        Drive::Current => "current_A",
        Drive::CommandIdeal | Drive::CommandDynamic => "command_V",
    })
}

/// A file's drive scale as a model reads it ([`drive_scale`]).
#[derive(Clone, Copy)]
struct DriveScale {
    /// The scale its drive is followed best at.
    scale: f64,
    /// The share of its displacement's spread (rms) left unexplained so.
    rescaled: f64,
    /// The same with its drive as logged, at the displacement's best gain.
    as_logged: f64,
}

impl DriveScale {
    /// Another scale than the file's own, followed [`DRIVE_SCALE_BETTER`] times better than as
    /// logged and within [`DRIVE_SCALE_EXPLAINS`].
    fn is_off(&self) -> bool {
        let own = (1.0 / DRIVE_SCALE_OWN..=DRIVE_SCALE_OWN).contains(&self.scale);
        !own && self.rescaled * DRIVE_SCALE_BETTER <= self.as_logged && self.rescaled <= DRIVE_SCALE_EXPLAINS
    }
}

/// The scale of `rec`'s drive under which the model `without` follows its logged displacement
/// best, with the share of the displacement's spread left unexplained so and as logged (the
/// start of that run estimated at `probe_gain`); `None` where the runs fail.
fn drive_scale(
    joint: &FitResult,
    without: &FitResult,
    rec: &Recording,
    probe_gain: f64,
) -> Result<Option<DriveScale>> {
    let Some(y) = rec.displacement_um.as_deref() else { return Ok(None) };
    // The first tenth, where the start's estimate weighs most, left out.
    let y = &y[y.len() / 10..];
    // The share of y's spread (rms) the model leaves with the drive × g and the displacement
    // ÷ `probe`: as logged, and at the displacement's best gain and zero. Each run from the start
    // that best explains the file so read (a lab file starts mid-history, and a start estimated
    // from a displacement at another gain is not the rod's).
    let unexplained = |g: f64, probe: f64| -> Result<Option<(f64, f64)>> {
        let times = |v: &Option<Vec<f64>>, by: f64| v.as_ref().map(|v| v.iter().map(|x| x * by).collect());
        let scaled = Recording {
            current_a: times(&rec.current_a, g),
            command_v: times(&rec.command_v, g),
            displacement_um: times(&rec.displacement_um, 1.0 / probe),
            ..rec.clone()
        };
        let prep = Prepared::new(joint.spec, &scaled)?;
        let Ok(sim) = run_model(joint.spec, &without.params, &prep, false) else { return Ok(None) };
        let m = &sim.displacement_um[sim.displacement_um.len() - y.len()..];
        Ok(Some(shares_unexplained(y, m)))
    };
    let Some((_, as_logged)) = unexplained(1.0, probe_gain)? else { return Ok(None) };
    let mut best = (1.0, f64::INFINITY);
    for k in -DRIVE_SCALE_STEPS..=DRIVE_SCALE_STEPS {
        let g = 2f64.powf(k as f64 / 4.0);
        if let Some((at_g, _)) = unexplained(g, 1.0)? {
            if at_g < best.1 {
                best = (g, at_g);
            }
        }
    }
    // Golden-section between the best scale's neighbours, in log g: one new run a step, the
    // other inner point kept.
    let at = |x: f64| -> Result<f64> { Ok(unexplained(x.exp(), 1.0)?.map_or(f64::INFINITY, |u| u.0)) };
    let (mut lo, mut hi) = (best.0.ln() - 0.25 * 2f64.ln(), best.0.ln() + 0.25 * 2f64.ln());
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - golden * (hi - lo), lo + golden * (hi - lo));
    let (mut ua, mut ub) = (at(a)?, at(b)?);
    for step in 0..=12 {
        for (x, u) in [(a, ua), (b, ub)] {
            if u < best.1 {
                best = (x.exp(), u);
            }
        }
        if step == 12 {
            break;
        }
        if ua < ub {
            (hi, b, ub) = (b, a, ua);
            a = hi - golden * (hi - lo);
            ua = at(a)?;
        } else {
            (lo, a, ua) = (a, b, ub);
            b = lo + golden * (hi - lo);
            ub = at(b)?;
        }
    }
    Ok(Some(DriveScale { scale: best.0, rescaled: best.1, as_logged }))
}

/// The share of `y`'s spread (rms about its mean) that `m` leaves unexplained: as it is (about
/// the means), and at `m`'s best gain, √(1 − ρ²) (1 where they do not rise together).
fn shares_unexplained(y: &[f64], m: &[f64]) -> (f64, f64) {
    let n = y.len().max(1) as f64;
    let (my, mm) = (y.iter().sum::<f64>() / n, m.iter().sum::<f64>() / n);
    let (mut syy, mut see) = (0.0, 0.0);
    for (a, b) in y.iter().zip(m) {
        syy += (a - my) * (a - my);
        see += ((a - my) - (b - mm)) * ((a - my) - (b - mm));
    }
    let rho = correlation(y, m);
    let at_gain = if rho > 0.0 { (1.0 - rho * rho).sqrt() } else { 1.0 };
    ((see / syy).sqrt(), at_gain)
}

/// Two files' drive scales, each read by the other's model (`b_drive` b's by a's, `a_drive`
/// a's by b's): b's against a's, and the worse shares of the readings that say so, when one
/// reading says so ([`DriveScale::is_off`]) and the other mirrors it ([`PAIR_MIRROR`]) or says
/// nothing (a model fitted to held steps alone need not carry to a multisine's drive).
fn pair_drive_scales(b_drive: Option<DriveScale>, a_drive: Option<DriveScale>) -> Option<(f64, f64, f64)> {
    let decisive = |d: &Option<DriveScale>| d.filter(DriveScale::is_off);
    let vague = |d: &Option<DriveScale>| d.is_none_or(|d| d.rescaled > DRIVE_SCALE_EXPLAINS);
    let mirrored = |b: &DriveScale, a: &DriveScale| (b.scale * a.scale).ln().abs() <= PAIR_MIRROR.ln();
    match (decisive(&b_drive), decisive(&a_drive)) {
        // A reading's scale multiplies its file's drive up to the other's: b's drive against
        // a's is 1/that from b's reading, that from a's.
        (Some(b), Some(a)) if mirrored(&b, &a) => {
            // The geometric mean of both readings.
            Some(((a.scale / b.scale).sqrt(), b.rescaled.max(a.rescaled), b.as_logged.min(a.as_logged)))
        }
        (Some(b), None) if vague(&a_drive) => Some((1.0 / b.scale, b.rescaled, b.as_logged)),
        (None, Some(a)) if vague(&b_drive) => Some((a.scale, a.rescaled, a.as_logged)),
        _ => None,
    }
}

/// How far the two files' scales, each judged by the other's model, may fail to mirror each
/// other (a gain g reads g one way and 1/g the other) and still be one scale's difference: a
/// model fitted to one file's drive and run on another's (a sine's on a chirp's) can miss by
/// more than any gain, and then it says nothing of the scales.
const PAIR_MIRROR: f64 = 1.5;

/// Two files: neither can be told the odd one, so each is judged by the other's model, and the
/// pair said to disagree when both readings do, [`GAINS_DISAGREE`] or more apart, and mirror
/// each other within [`PAIR_MIRROR`] (a second file's gain g reads g one way and 1/g the other;
/// a model that cannot carry one file's drive to the other's reads them at random).
fn pair_disagrees(
    start: &ActuatorParams,
    joint: &FitResult,
    files: &[Recording],
    quiet: FitOptions,
    constraints: &Constraints,
) -> Result<Option<Warning>> {
    let (a, b) = (&files[0], &files[1]);
    let Some((b_by_a, from_a)) = scale_without(start, joint, std::slice::from_ref(a), b, quiet, constraints)?
    else {
        return Ok(None);
    };
    let Some((a_by_b, from_b)) = scale_without(start, joint, std::slice::from_ref(b), a, quiet, constraints)?
    else {
        return Ok(None);
    };
    // A drive at another scale first: each file's drive read by the other's model, mirrored.
    let (b_drive, a_drive) =
        (drive_scale(joint, &from_a, b, b_by_a)?, drive_scale(joint, &from_b, a, a_by_b)?);
    if let Some((scale, rescaled, as_logged)) = pair_drive_scales(b_drive, a_drive) {
        return Ok(Some(Warning::DriveScaleOff {
            file: b.name.clone(),
            column: drive_column(joint, b)?,
            scale,
            rescaled,
            as_logged,
            pair: Some(a.name.clone()),
        }));
    }
    let disagree = |r: f64| !(1.0 / GAINS_DISAGREE..GAINS_DISAGREE).contains(&r);
    let mirrored = (b_by_a * a_by_b).ln().abs() <= PAIR_MIRROR.ln();
    if !(disagree(b_by_a) && disagree(a_by_b) && mirrored) {
        return Ok(None);
    }
    let followed = |f: &FitResult| f.fit.files.first().map_or(f64::NAN, |s| s.nrmse);
    let scores: Vec<f64> = joint.fit.files.iter().map(|s| s.nrmse).collect();
    Ok(Some(Warning::GainsDisagree {
        file: b.name.clone(),
        // b's scale against a's: the geometric mean of both readings.
        gain: (b_by_a / a_by_b).sqrt(),
        joint_nrmse: scores.get(1).copied().unwrap_or(f64::NAN),
        others_nrmse: (followed(&from_a), followed(&from_b)),
        doubted_from: GAINS_DISAGREE,
        pair: Some(a.name.clone()),
    }))
}

/// [`super::sign_doubts`] and [`scale_outlier`] on the fit files (the sign doubts on `val_files`
/// too): a file named at another scale is not also said to read better negated (a poor joint fit
/// of it says nothing of its wiring, and negating it would damage good data).
pub fn sign_and_scale_doubts(
    start: &ActuatorParams,
    joint: &FitResult,
    files: &[Recording],
    val_files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
) -> Result<Vec<Warning>> {
    let (scale, without) = scale_outlier(start, joint, files, opts, constraints)?.unzip();
    let named: Vec<String> = match &scale {
        Some(Warning::GainsDisagree { file, pair, .. }) => {
            std::iter::once(file.clone()).chain(pair.clone()).collect()
        }
        Some(Warning::DriveScaleOff { file, pair, .. }) => {
            std::iter::once(file.clone()).chain(pair.clone()).collect()
        }
        _ => Vec::new(),
    };
    // The other files judged by the model fitted without the named one: the joint fit bent
    // every parameter to it, and a good file can read better negated under that model.
    let judge = without.flatten().unwrap_or(joint.params);
    let mut doubts: Vec<Warning> = super::sign_doubts(joint.spec, &judge, files.iter().chain(val_files))?
        .into_iter()
        .filter(|w| match w {
            Warning::Data(DataDoubt::BothNegated { file, .. }) => !named.contains(file),
            _ => true,
        })
        .collect();
    doubts.extend(scale);
    Ok(doubts)
}
