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
/// than every other file, or its scale stands apart ([`odd_scale`]). One more fit, only when a
/// file stands out so; with two files, two ([`pair_disagrees`]).
pub fn scale_outlier(
    start: &ActuatorParams,
    joint: &FitResult,
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
) -> Result<Option<Warning>> {
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
        return pair_disagrees(start, joint, files, quiet, constraints);
    }
    let others: Vec<Recording> =
        files.iter().enumerate().filter(|(k, _)| *k != worst).map(|(_, r)| r.clone()).collect();
    let Some((ratio, without)) = scale_without(start, joint, &others, &files[worst], quiet, constraints)?
    else {
        return Ok(None);
    };
    if (1.0 / GAINS_DISAGREE..GAINS_DISAGREE).contains(&ratio) {
        return Ok(None);
    }
    let followed = without
        .fit
        .files
        .iter()
        .map(|s| s.nrmse)
        .fold((f64::MAX, f64::MIN), |(l, h), s| (l.min(s), h.max(s)));
    Ok(Some(Warning::GainsDisagree {
        file: files[worst].name.clone(),
        gain: ratio,
        joint_nrmse: scores[worst],
        others_nrmse: followed,
        doubted_from: GAINS_DISAGREE,
        pair: None,
    }))
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
    let scale = scale_outlier(start, joint, files, opts, constraints)?;
    let named: Vec<String> = match &scale {
        Some(Warning::GainsDisagree { file, pair, .. }) => {
            std::iter::once(file.clone()).chain(pair.clone()).collect()
        }
        _ => Vec::new(),
    };
    let mut doubts: Vec<Warning> =
        super::sign_doubts(joint.spec, &joint.params, files.iter().chain(val_files))?
            .into_iter()
            .filter(|w| match w {
                Warning::Data(DataDoubt::BothNegated { file, .. }) => !named.contains(file),
                _ => true,
            })
            .collect();
    doubts.extend(scale);
    Ok(doubts)
}
