//! What a fit says about its own result: a strain scale off its physical range, a mode the files
//! cannot resolve, an amplifier gain no file constrained, effects a set was never fitted with, a
//! search coil of another scale.

use model_core::effects::STRAIN_SCALE;
use model_core::{ActuatorParams, Effect, ModelSpec};

use super::constraints::Constraints;
use super::free_params::MODE_FREQUENCY;
use crate::channels::FLUX_SCALE_RANGE;
use crate::field_units::fields_in_kilo;
use crate::recording::Recording;
use crate::score::FileScore;
use crate::simulation::{model_input, Drive};
use crate::warning::Warning;

/// A λ_s the fit identified outside the physical range (the registry's for it, narrower than
/// [`LAMBDA_RANGE`], which only keeps the solve finite) is said: the strain scale is where a
/// displacement in the wrong unit lands. Nothing when λ_s was held (`--fix`).
pub fn strain_scale_doubt(
    spec: ModelSpec,
    params: &ActuatorParams,
    constraints: &Constraints,
) -> Option<Warning> {
    let lambda_s = params.magnetostriction.lambda_s as f64;
    let (lo, hi) = (STRAIN_SCALE.lo, STRAIN_SCALE.hi);
    (!constraints.is_fixed(STRAIN_SCALE.key) && !(lo..=hi).contains(&lambda_s)).then(|| {
        Warning::StrainScaleUnlikely { lambda_s, lo, hi, fields_in_kilo: fields_in_kilo(spec, params) }
    })
}

/// A mechanical mode that none of `files` can show (above each one's Nyquist frequency) is said:
/// the mechanics is then a static gain, and a time column in ms read as seconds lands there. A
/// mode above some files' Nyquist frequency only is said with those files.
pub fn unresolved_mode<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Option<Warning> {
    if !spec.has(Effect::MechanicalDynamics) {
        return None;
    }
    mode_above_nyquist(params.mech.natural_frequency_hz as f64, false, files)
}

/// As [`unresolved_mode`] for the lowest mode the search tries: none can show in `files`, so
/// `diagnose` cannot judge mechanical dynamics there.
pub fn unsearchable_mode<'a>(files: impl IntoIterator<Item = &'a Recording>) -> Option<Warning> {
    let lowest = Effect::MechanicalDynamics.info().params.iter().find(|p| p.key == MODE_FREQUENCY)?.lo;
    mode_above_nyquist(lowest, true, files)
}

fn mode_above_nyquist<'a>(
    natural_frequency_hz: f64,
    lowest_searched: bool,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Option<Warning> {
    let steps: Vec<(&str, f64)> =
        files.into_iter().map(|r| (r.name.as_str(), r.dt_s())).filter(|(_, dt)| *dt > 0.0).collect();
    let step_s = steps.iter().map(|(_, dt)| *dt).reduce(f64::min)?;
    let nyquist_hz = 0.5 / step_s;
    if natural_frequency_hz > nyquist_hz {
        return Some(Warning::ModeAboveNyquist { natural_frequency_hz, nyquist_hz, step_s, lowest_searched });
    }
    // Above some files' Nyquist frequency only (files of one rig at several rates): those
    // cannot show it, and a joint fit may put it where their aliases fit best.
    let slow: Vec<(&str, f64)> =
        steps.into_iter().filter(|(_, dt)| natural_frequency_hz > 0.5 / dt).collect();
    let top_slow_nyquist_hz = slow.iter().map(|(_, dt)| 0.5 / dt).reduce(f64::max)?;
    (!lowest_searched).then(|| Warning::ModeAboveSomeFiles {
        natural_frequency_hz,
        files: slow.iter().map(|(name, _)| name.to_string()).collect(),
        nyquist_hz: top_slow_nyquist_hz,
    })
}

/// A command-driven recording among `files` that `params` drive through an amplifier gain their
/// file (`source`) marks as not fitted.
pub fn unfitted_gain(
    spec: ModelSpec,
    params: &ActuatorParams,
    source: &crate::params::ParamSource,
    files: &[Recording],
) -> Option<Warning> {
    if !source.parameters_not_fitted.contains(&model_core::effects::AMPLIFIER_GAIN.key) {
        return None;
    }
    let rec = files.iter().find(|r| model_input(spec, r).is_ok_and(|d| d != Drive::Current))?;
    Some(Warning::UnfittedGain {
        file: rec.name.clone(),
        params: source.parameters_source.clone(),
        gain: params.amp.gain_a_per_v as f64,
    })
}

/// A parameter set run with effects the model it was fitted as lacks
/// ([`crate::params::effects_not_fitted`]): their values are start values.
pub fn unfitted_effects(spec: ModelSpec, source: &crate::params::ParamSource) -> Option<Warning> {
    (!source.effects_not_fitted.is_empty()).then(|| Warning::EffectsNotFitted {
        params: source.parameters_source.clone(),
        model: spec.to_string(),
        effects: source.effects_not_fitted.clone(),
    })
}

/// The recordings whose search-coil magnetization scale ended at an end of
/// [`FLUX_SCALE_RANGE`] (scored as `scores`, in order).
pub fn flux_scale_doubts(files: &[Recording], scores: &[FileScore]) -> Vec<Warning> {
    let (lo, hi) = FLUX_SCALE_RANGE;
    files
        .iter()
        .zip(scores)
        .filter_map(|(rec, s)| {
            let scale = s.flux?.scale;
            (scale <= lo || scale >= hi).then(|| Warning::FluxScaleAtBound { file: rec.name.clone(), scale })
        })
        .collect()
}
