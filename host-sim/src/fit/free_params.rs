//! Which parameters a model spec identifies on given files, with the registry's bounds and scales.

use anyhow::Result;
use model_core::effects::{Param, Scale, AMPLIFIER_GAIN, ROD_THERMAL_LAG, STRAIN_SCALE};
use model_core::{ActuatorParams, Effect, ModelSpec};

use crate::recording::Recording;
use crate::search::Bound;
use crate::simulation::{prepare, Drive};

/// One identified parameter: its bounds and scale ([`Bound`], named as in parameter files,
/// e.g. `ja.k_a_per_m`) and how to read and write it in a parameter set.
#[derive(Clone, Copy)]
pub struct FreeParam {
    /// Name, range and scale.
    pub bound: Bound,
    /// Reads it from a parameter set.
    pub get: fn(&ActuatorParams) -> f64,
    /// Writes it into a parameter set.
    pub set: fn(&mut ActuatorParams, f64),
}

impl FreeParam {
    /// Name as in parameter files.
    pub fn name(&self) -> &'static str {
        self.bound.name
    }

    /// Maps a value to [0, 1] (clamped; 0.5 for a value the scale cannot map).
    pub fn to_unit(&self, v: f64) -> f64 {
        self.bound.to_unit(v)
    }

    /// Maps [0, 1] back to a value (clamped into the bounds).
    pub fn from_unit(&self, u: f64) -> f64 {
        self.bound.from_unit(u)
    }
}

impl std::fmt::Debug for FreeParam {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.bound)
    }
}

impl FreeParam {
    /// From the registry's description of a parameter.
    pub fn of(p: &'static Param) -> Self {
        FreeParam {
            bound: Bound { name: p.key, lo: p.lo, hi: p.hi, log: p.scale == Scale::Log, swarm_holds: None },
            get: p.get,
            set: p.set,
        }
    }
}

/// What the recordings give, where it decides which parameters a fit can identify.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Given {
    /// The files give the command, not the current: the amplifier gain is identified.
    pub command_driven: bool,
    /// A file logs the coil's temperature: with `thermal_drift` the rod's lag behind the coil is
    /// identified (the thermometer pins the coil's own lag).
    pub coil_temperature: bool,
}

impl Given {
    /// What `files` give.
    pub fn by(files: &[Recording], command_driven: bool) -> Self {
        Given { command_driven, coil_temperature: logs_coil_temperature(files) }
    }
}

/// Whether any of `files` logs the coil's temperature (`temperature_C`).
pub fn logs_coil_temperature(files: &[Recording]) -> bool {
    files.iter().any(|r| r.temperature_c.is_some())
}

/// The continuous parameters `spec` identifies, from the effect registry: the strain scale, the
/// magnetization law's, the amplifier gain when the files give the command, not the current,
/// each effect's in chain order, and the rod's thermal lag when they log the coil's temperature.
pub fn free_params(spec: ModelSpec, given: Given) -> Vec<FreeParam> {
    let mut v: Vec<&'static Param> = vec![&STRAIN_SCALE];
    v.extend(spec.law().params());
    if given.command_driven {
        v.push(&AMPLIFIER_GAIN);
    }
    v.extend(spec.effects().flat_map(|e| e.info().params));
    if given.coil_temperature && spec.has(Effect::ThermalDrift) {
        v.push(&ROD_THERMAL_LAG);
    }
    v.into_iter().map(FreeParam::of).collect()
}

/// The parameters a fit of `spec` identifies only when the files give what they need, which
/// `given` lacks: the amplifier gain (files that give the command alone) and the rod's thermal
/// lag (a logged coil temperature, with `thermal_drift`).
pub fn not_fitted(spec: ModelSpec, given: Given) -> Vec<&'static str> {
    let free: Vec<&str> = free_params(spec, given).iter().map(FreeParam::name).collect();
    free_params(spec, Given { command_driven: true, coil_temperature: true })
        .iter()
        .map(FreeParam::name)
        .filter(|n| !free.contains(n))
        .collect()
}

/// Every parameter `spec` identifies on these files (λ_s first), with the registry's ranges.
pub fn identifiable(spec: ModelSpec, files: &[Recording]) -> Result<Vec<FreeParam>> {
    Ok(free_params(spec, given_by(spec, files)?))
}

/// What `files` give a fit of `spec`.
pub(crate) fn given_by(spec: ModelSpec, files: &[Recording]) -> Result<Given> {
    let command_driven = prepare(spec, files)?.iter().any(|p| p.drive != Drive::Current);
    Ok(Given::by(files, command_driven))
}

/// The mechanical mode's parameters, which a mode seen in the data starts (see `resonance`).
pub(crate) const MODE_FREQUENCY: &str = "mech.natural_frequency_hz";

pub(crate) const MODE_DAMPING: &str = "mech.damping_ratio";
