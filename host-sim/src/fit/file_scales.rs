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
/// file stands out so.
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
    let others: Vec<Recording> =
        files.iter().enumerate().filter(|(k, _)| *k != worst).map(|(_, r)| r.clone()).collect();
    let quiet = FitOptions { progress: false, ..opts };
    let Ok(without) = fit_constrained(joint.spec, &[*start, joint.params], &others, quiet, constraints)
    else {
        return Ok(None);
    };
    let rec = &files[worst];
    let (Some(y), Some(sim)) =
        (rec.displacement_um.as_deref(), demagnetised_run(joint.spec, &without.params, rec)?)
    else {
        return Ok(None);
    };
    let ratio = spread(y) / spread(&sim.displacement_um);
    if !(ratio.is_finite() && ratio > 0.0) || (1.0 / GAINS_DISAGREE..GAINS_DISAGREE).contains(&ratio) {
        return Ok(None);
    }
    let followed = without
        .fit
        .files
        .iter()
        .map(|s| s.nrmse)
        .fold((f64::MAX, f64::MIN), |(l, h), s| (l.min(s), h.max(s)));
    Ok(Some(Warning::GainsDisagree {
        file: rec.name.clone(),
        gain: ratio,
        joint_nrmse: scores[worst],
        others_nrmse: followed,
        doubted_from: GAINS_DISAGREE,
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
    let named = match &scale {
        Some(Warning::GainsDisagree { file, .. }) => Some(file.clone()),
        _ => None,
    };
    let mut doubts: Vec<Warning> =
        super::sign_doubts(joint.spec, &joint.params, files.iter().chain(val_files))?
            .into_iter()
            .filter(|w| match w {
                Warning::Data(DataDoubt::BothNegated { file, .. }) => Some(file) != named.as_ref(),
                _ => true,
            })
            .collect();
    doubts.extend(scale);
    Ok(doubts)
}
