//! The effect registry: one descriptor per physical effect a model can include — its name and
//! alias, its place in the chain, the magnetization law it selects, the parameters it brings
//! (key, unit, identification range; defaults are [`ActuatorParams::TERFENOL_DEMO`]'s values),
//! the residual signature by which a diagnosis recognises its absence, and what the inverse
//! compensator does with it. Spec parsing, suggestions, the workbench's free parameters and
//! diagnosis candidates, help texts and the docs' effect table are all generated from here.
//!
//! Adding an effect: a variant of [`Effect`], its [`EffectInfo`] in [`EFFECTS`] (chain order),
//! and its stage in [`crate::chain`] (parameters in [`ActuatorParams`], state, step). The
//! registry test fails until every variant has exactly one descriptor.

use core::fmt;

pub use crate::magnetization::JaVariant;
use crate::params::ActuatorParams;

/// One physical effect a model can include (serialised as its registry name).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// Langevin anhysteretic magnetization instead of the linear one.
    Saturation,
    /// Jiles–Atherton irreversible magnetization (implies saturation).
    Hysteresis,
    /// Rate-dependent field lag in the rod.
    EddyCurrent,
    /// Preisach (relay-plane) hysteresis instead of the linear or Jiles–Atherton magnetization.
    Preisach,
    /// Mass-spring-damper between strain and displacement.
    MechanicalDynamics,
    /// Command voltage → coil current dynamics.
    AmplifierDynamics,
    /// Slow magnetization creep.
    MagneticAftereffect,
    /// Coil heating → thermal expansion of the rod.
    ThermalDrift,
    /// Pure transport delay of the displacement measurement.
    SensorDelay,
}

/// Where an effect acts, from the drive to the measured displacement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    /// Command voltage → coil current.
    Amplifier,
    /// Coil field → field in the rod.
    RodField,
    /// Field → magnetization (the magnetization law).
    Magnetization,
    /// Slow changes of the magnetization.
    MagnetizationCreep,
    /// Free strain → displacement.
    Mechanics,
    /// Coil heating → thermal strain.
    Thermal,
    /// The displacement sensor.
    Sensor,
}

/// The magnetization law of a model: the minimal linear law, or the one its effects select.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum MagnetizationLaw {
    /// M = a + bH (the minimal model).
    Linear,
    /// Langevin anhysteretic curve.
    Anhysteretic,
    /// Jiles–Atherton hysteresis.
    JilesAtherton,
    /// Preisach hysteresis.
    Preisach,
}

/// The first-order residual signature of an effect a model lacks (what a diagnosis correlates
/// the residual with).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signature {
    /// A lag: −dy/dt.
    Lag,
    /// A resonance: −ÿ (and −dy/dt).
    Resonance,
    /// Loop opening: sign(dH/dt).
    Branch,
    /// Saturation: the cubic field excursion (H − H̄)³.
    Cubic,
    /// Creep: lowpass(y) − y.
    Creep,
    /// Heating: the accumulated ∫i² dt.
    Heating,
    /// None (an alternative law, not a missing effect).
    None,
}

/// What the drive's inverse compensator does with an effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Inverse {
    /// Inverted in the feedforward.
    Inverted,
    /// Left out of the feedforward: the drive's feedback handles it (the current loop is the
    /// amplifier; the displacement PID takes mechanics and sensor delay).
    LeftToFeedback,
}

/// When a diagnosis tries adding an effect to a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidacy {
    /// Whenever the model lacks it.
    Always,
    /// When every recording has the command column (the effect acts between command and current).
    NeedsCommand,
    /// When it refines the model's magnetization law (Linear → Anhysteretic → Jiles–Atherton).
    RefinesLaw,
    /// Never: an alternative, not missing physics.
    Never,
}

/// How a parameter is identified.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Searched uniformly between its bounds.
    Linear,
    /// Searched uniformly in log between its (positive) bounds.
    Log,
}

/// One identifiable parameter: its key in parameter files, unit, identification range and
/// access to its value in a parameter set.
#[derive(Clone, Copy)]
pub struct Param {
    /// Key as in parameter files (`table.key`).
    pub key: &'static str,
    /// Unit (`1` for dimensionless).
    pub unit: &'static str,
    /// Lower bound of the identification range.
    pub lo: f64,
    /// Upper bound of the identification range.
    pub hi: f64,
    /// How it is searched.
    pub scale: Scale,
    /// Reads it from a parameter set.
    pub get: fn(&ActuatorParams) -> f64,
    /// Writes it into a parameter set.
    pub set: fn(&mut ActuatorParams, f64),
}

impl fmt::Debug for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} [{}, {}] {}", self.key, self.lo, self.hi, self.unit)
    }
}

macro_rules! param {
    ($key:literal, $unit:literal, $lo:expr, $hi:expr, $scale:ident, $($field:ident).+) => {
        Param {
            key: $key,
            unit: $unit,
            lo: $lo,
            hi: $hi,
            scale: Scale::$scale,
            get: |p| p.$($field).+ as f64,
            set: |p, v| p.$($field).+ = v as _,
        }
    };
}

/// One effect's descriptor.
#[derive(Debug, Clone, Copy)]
pub struct EffectInfo {
    /// The effect.
    pub effect: Effect,
    /// Name in model specs, JSON and parameter tables.
    pub name: &'static str,
    /// Short name accepted in model specs (and used in canonical spec text).
    pub alias: Option<&'static str>,
    /// What it adds to a model, in a few words (help texts, docs).
    pub adds: &'static str,
    /// Where it acts.
    pub stage: Stage,
    /// The magnetization law it selects, for a law.
    pub law: Option<MagnetizationLaw>,
    /// Another effect it brings with it (hysteresis needs the anhysteretic curve).
    pub implies: Option<Effect>,
    /// The parameters it brings, identified when it is in a model (a law's are in
    /// [`MagnetizationLaw::params`]).
    pub params: &'static [Param],
    /// How its absence shows in a residual.
    pub signature: Signature,
    /// What the inverse compensator does with it.
    pub inverse: Inverse,
    /// When a diagnosis tries adding it.
    pub candidacy: Candidacy,
}

/// Every effect, in chain order (drive → displacement): the order of canonical spec text.
pub const EFFECTS: [EffectInfo; 9] = [
    EffectInfo {
        effect: Effect::AmplifierDynamics,
        name: "amplifier_dynamics",
        alias: Some("amp"),
        adds: "command voltage → coil current dynamics (first order, or second order with `[amp_second_order]`); the drive becomes `command_V`",
        stage: Stage::Amplifier,
        law: None,
        implies: None,
        params: &[param!("amp.tau_s", "s", 1e-6, 1e-2, Log, amp.tau_s)],
        signature: Signature::Lag,
        inverse: Inverse::LeftToFeedback,
        candidacy: Candidacy::NeedsCommand,
    },
    EffectInfo {
        effect: Effect::EddyCurrent,
        name: "eddy_current",
        alias: Some("eddy"),
        adds: "rate-dependent lag of the field in the rod (first order)",
        stage: Stage::RodField,
        law: None,
        implies: None,
        params: &[param!("eddy_tau_s", "s", 1e-6, 1e-2, Log, eddy_tau_s)],
        signature: Signature::Lag,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::Always,
    },
    EffectInfo {
        effect: Effect::Saturation,
        name: "saturation",
        alias: Some("anhysteretic"),
        adds: "Langevin anhysteretic magnetization M = M_s L(H/a) instead of the linear one",
        stage: Stage::Magnetization,
        law: Some(MagnetizationLaw::Anhysteretic),
        implies: None,
        params: &[],
        signature: Signature::Cubic,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::RefinesLaw,
    },
    EffectInfo {
        effect: Effect::Hysteresis,
        name: "hysteresis",
        alias: None,
        adds: "Jiles–Atherton hysteresis (implies `saturation`; its form by `[ja] variant`, below)",
        stage: Stage::Magnetization,
        law: Some(MagnetizationLaw::JilesAtherton),
        implies: Some(Effect::Saturation),
        params: &[],
        signature: Signature::Branch,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::RefinesLaw,
    },
    EffectInfo {
        effect: Effect::Preisach,
        name: "preisach",
        alias: None,
        adds: "Preisach (relay-plane) hysteresis instead of the linear magnetization; excludes `saturation` and `hysteresis`",
        stage: Stage::Magnetization,
        law: Some(MagnetizationLaw::Preisach),
        implies: None,
        params: &[],
        signature: Signature::None,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::Never,
    },
    EffectInfo {
        effect: Effect::MagneticAftereffect,
        name: "magnetic_aftereffect",
        alias: Some("aftereffect"),
        adds: "slow magnetization creep",
        stage: Stage::MagnetizationCreep,
        law: None,
        implies: None,
        params: &[
            param!("aftereffect.fraction", "1", 1e-3, 0.6, Log, aftereffect.fraction),
            param!("aftereffect.tau_s", "s", 1e-3, 30.0, Log, aftereffect.tau_s),
        ],
        signature: Signature::Creep,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::Always,
    },
    EffectInfo {
        effect: Effect::MechanicalDynamics,
        name: "mechanical_dynamics",
        alias: Some("mech"),
        adds: "unit-gain mass-spring-damper between free and output displacement",
        stage: Stage::Mechanics,
        law: None,
        implies: None,
        params: &[
            param!("mech.natural_frequency_hz", "Hz", 50.0, 2e4, Log, mech.natural_frequency_hz),
            param!("mech.damping_ratio", "1", 0.02, 5.0, Log, mech.damping_ratio),
        ],
        signature: Signature::Resonance,
        inverse: Inverse::LeftToFeedback,
        candidacy: Candidacy::Always,
    },
    EffectInfo {
        effect: Effect::ThermalDrift,
        name: "thermal_drift",
        alias: Some("thermal"),
        adds: "coil heating R i² → coil temperature → the rod's (behind it) → thermal expansion",
        stage: Stage::Thermal,
        law: None,
        implies: None,
        params: &[
            param!(
                "thermal.thermal_resistance_c_per_w",
                "°C/W",
                1e-3,
                100.0,
                Log,
                thermal.thermal_resistance_c_per_w
            ),
            param!("thermal.tau_s", "s", 0.05, 3000.0, Log, thermal.tau_s),
        ],
        signature: Signature::Heating,
        inverse: Inverse::Inverted,
        candidacy: Candidacy::Always,
    },
    EffectInfo {
        effect: Effect::SensorDelay,
        name: "sensor_delay",
        alias: Some("delay"),
        adds: "transport delay of the displacement measurement, in samples of the parameters' `dt_s` (a fraction interpolates between samples; a file at another rate gets the same time)",
        stage: Stage::Sensor,
        law: None,
        implies: None,
        params: &[param!("delay_samples", "samples", 0.0, 16.0, Linear, delay_samples)],
        signature: Signature::Lag,
        inverse: Inverse::LeftToFeedback,
        candidacy: Candidacy::Always,
    },
];

/// Words that name a set of effects: `linear` (none: the minimal model) and `ja`
/// (saturation + hysteresis).
pub const SHORTHANDS: [(&str, &[Effect]); 2] =
    [("linear", &[]), ("ja", &[Effect::Saturation, Effect::Hysteresis])];

/// The parameter-file key that selects the form of the J–A equations ([`JaVariant`] by name); a
/// file without it means the default, [`JaVariant::Bulk`], the only form before it existed.
pub const JA_VARIANT_KEY: &str = "ja.variant";

/// The strain scale λ_s: identified in every model (the workbench solves it in closed form).
pub const STRAIN_SCALE: Param =
    param!("magnetostriction.lambda_s", "1", 1e-5, 1e-2, Log, magnetostriction.lambda_s);

/// The ideal amplifier's gain: identified when recordings give the command and not the current.
pub const AMPLIFIER_GAIN: Param = param!("amp.gain_a_per_v", "A/V", 0.05, 50.0, Log, amp.gain_a_per_v);

/// The rod's thermal lag behind the coil (`thermal_drift`): identified only when the recordings
/// log the coil's temperature, which pins the coil's own lag (from the displacement alone the
/// two lags trade). Its default, 0, means the rod follows the coil at once.
pub const ROD_THERMAL_LAG: Param = param!("thermal.rod_tau_s", "s", 0.01, 3000.0, Log, thermal.rod_tau_s);

const LINEAR_PARAMS: [Param; 2] = [
    param!("linear.susceptibility", "1", 0.1, 200.0, Log, linear.susceptibility),
    param!("linear.offset_a_per_m", "A/m", -3e5, 3e5, Linear, linear.offset_a_per_m),
];
const ANHYSTERETIC_PARAMS: [Param; 1] =
    [param!("anhysteretic.a_a_per_m", "A/m", 500.0, 1e5, Log, anhysteretic.a_a_per_m)];
const JA_PARAMS: [Param; 4] = [
    param!("ja.a_a_per_m", "A/m", 500.0, 5e4, Log, ja.a_a_per_m),
    param!("ja.k_a_per_m", "A/m", 100.0, 3e4, Log, ja.k_a_per_m),
    param!("ja.alpha", "1", -0.1, 0.1, Linear, ja.alpha),
    param!("ja.c", "1", 0.0, 0.95, Linear, ja.c),
];
const PREISACH_PARAMS: [Param; 5] = [
    param!("preisach.coercive_a_per_m", "A/m", 100.0, 3e4, Log, preisach.coercive_a_per_m),
    param!("preisach.spread_a_per_m", "A/m", 500.0, 6e4, Log, preisach.spread_a_per_m),
    // Always identified: a set without it (the older tied density) starts from σ_u = σ.
    Param {
        key: "preisach.interaction_spread_a_per_m",
        unit: "A/m",
        lo: 500.0,
        hi: 1e5,
        scale: Scale::Log,
        get: |p| p.preisach.interaction_spread_a_per_m.unwrap_or(p.preisach.spread_a_per_m) as f64,
        set: |p, v| p.preisach.interaction_spread_a_per_m = Some(v as f32),
    },
    // The reversible part ρ M_s tanh(H/h_r): what carries a small signal about a bias (the
    // relays' swing grows as ΔH², Rayleigh). Searched since the Everett table is interpolated in
    // √E (before, the table's diagonal cells gave small loops a slope of their own and ρ was
    // not identifiable: the held-out rig validated worse with it searched).
    Param {
        key: "preisach.reversible_fraction",
        unit: "1",
        lo: 0.0,
        hi: 0.9,
        scale: Scale::Linear,
        get: |p| p.preisach.reversible_fraction_or_default() as f64,
        set: |p, v| p.preisach.reversible_fraction = Some(v as f32),
    },
    Param {
        key: "preisach.reversible_field_a_per_m",
        unit: "A/m",
        lo: 1e3,
        hi: 2e5,
        scale: Scale::Log,
        get: |p| p.preisach.reversible_field_or_default() as f64,
        set: |p, v| p.preisach.reversible_field_a_per_m = Some(v as f32),
    },
];

impl MagnetizationLaw {
    /// Every law, from the minimal one up.
    pub const ALL: [MagnetizationLaw; 4] = [
        MagnetizationLaw::Linear,
        MagnetizationLaw::Anhysteretic,
        MagnetizationLaw::JilesAtherton,
        MagnetizationLaw::Preisach,
    ];

    /// The law of a set of effects: the most specific law any of them selects, else linear.
    pub fn of(effects: impl Iterator<Item = Effect>) -> MagnetizationLaw {
        effects.filter_map(|e| e.info().law).max().unwrap_or(MagnetizationLaw::Linear)
    }

    /// The law's parameters the workbench identifies from displacement recordings (the
    /// saturation magnetization is fixed there: it normalises the magnetostriction).
    pub const fn params(self) -> &'static [Param] {
        match self {
            MagnetizationLaw::Linear => &LINEAR_PARAMS,
            MagnetizationLaw::Anhysteretic => &ANHYSTERETIC_PARAMS,
            MagnetizationLaw::JilesAtherton => &JA_PARAMS,
            MagnetizationLaw::Preisach => &PREISACH_PARAMS,
        }
    }

    /// Whether adding this law to a model whose law is `current` refines it (linear →
    /// anhysteretic → Jiles–Atherton); Preisach is an alternative, never a refinement.
    pub fn refines(self, current: MagnetizationLaw) -> bool {
        self != MagnetizationLaw::Preisach && current != MagnetizationLaw::Preisach && self > current
    }
}

impl Effect {
    /// Every effect, in chain order.
    pub const ALL: [Effect; EFFECTS.len()] = {
        let mut all = [Effect::Saturation; EFFECTS.len()];
        let mut k = 0;
        while k < EFFECTS.len() {
            all[k] = EFFECTS[k].effect;
            k += 1;
        }
        all
    };

    /// Its descriptor.
    pub const fn info(self) -> &'static EffectInfo {
        let mut k = 0;
        while k < EFFECTS.len() {
            if EFFECTS[k].effect as u8 == self as u8 {
                return &EFFECTS[k];
            }
            k += 1;
        }
        panic!("an effect without a descriptor in EFFECTS");
    }

    /// The name in model specs and JSON.
    pub const fn name(self) -> &'static str {
        self.info().name
    }

    /// The short name, if any.
    pub const fn alias(self) -> Option<&'static str> {
        self.info().alias
    }

    /// Looks up a name or alias.
    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s || e.alias() == Some(s))
    }

    pub(crate) const fn bit(self) -> u16 {
        1 << (self as u16)
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// The parameter-file format the tools write. 2: a `format_version` key, and the tables of
/// effects and magnetization laws ([`parameter_tables`]) optional (the demo set's values stand
/// in); 1 (no `format_version`): every table present. Readers accept every format up to this.
pub const PARAMETER_FILE_FORMAT: i64 = 2;

/// The parameter-file table (or top-level key) a parameter key lives in: `ja` for `ja.c`.
pub fn table_of(key: &str) -> &str {
    key.split('.').next().unwrap_or(key)
}

/// Every parameter of the effects and the magnetization laws.
fn stage_params() -> impl Iterator<Item = &'static Param> {
    let laws = MagnetizationLaw::ALL.iter().flat_map(|l| l.params());
    EFFECTS.iter().flat_map(|e| e.params).chain(laws)
}

/// The parameter-file tables (or top-level keys) that belong to one effect or magnetization
/// law, each once: a file may leave them out, so a file written before an effect existed loads.
pub fn parameter_tables() -> impl Iterator<Item = &'static str> {
    stage_params()
        .enumerate()
        .filter(|(i, p)| stage_params().take(*i).all(|q| table_of(q.key) != table_of(p.key)))
        .map(|(_, p)| table_of(p.key))
}

#[cfg(feature = "serde")]
impl serde::Serialize for Effect {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for Effect {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let word = <&str>::deserialize(d)?;
        Effect::from_name(word)
            .ok_or_else(|| serde::de::Error::custom(format_args!("unknown effect `{word}`")))
    }
}

/// Every word a model spec accepts: shorthands, names and aliases.
pub fn spec_words() -> impl Iterator<Item = &'static str> {
    SHORTHANDS.iter().map(|s| s.0).chain(EFFECTS.iter().flat_map(|e| core::iter::once(e.name).chain(e.alias)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fails to compile when a variant is added without a line here, and fails when a variant
    /// has no descriptor or two.
    #[test]
    fn the_registry_covers_every_effect_once() {
        let every = |e: Effect| match e {
            Effect::Saturation
            | Effect::Hysteresis
            | Effect::EddyCurrent
            | Effect::Preisach
            | Effect::MechanicalDynamics
            | Effect::AmplifierDynamics
            | Effect::MagneticAftereffect
            | Effect::ThermalDrift
            | Effect::SensorDelay => e,
        };
        let variants = [
            Effect::Saturation,
            Effect::Hysteresis,
            Effect::EddyCurrent,
            Effect::Preisach,
            Effect::MechanicalDynamics,
            Effect::AmplifierDynamics,
            Effect::MagneticAftereffect,
            Effect::ThermalDrift,
            Effect::SensorDelay,
        ];
        assert_eq!(variants.len(), EFFECTS.len());
        for v in variants.map(every) {
            assert_eq!(EFFECTS.iter().filter(|d| d.effect == v).count(), 1, "{v:?}");
            assert_eq!(v.info().effect, v);
        }
        // Chain order, and every word unique.
        assert!(EFFECTS.windows(2).all(|w| w[0].stage <= w[1].stage));
        let words: std::vec::Vec<&str> = spec_words().collect();
        for w in &words {
            assert_eq!(words.iter().filter(|x| *x == w).count(), 1, "`{w}` names two things");
        }
    }

    #[test]
    fn every_parameter_reads_back_what_it_writes_and_its_default_is_in_range() {
        let laws = MagnetizationLaw::ALL.iter().flat_map(|l| l.params());
        let all = EFFECTS.iter().flat_map(|e| e.params).chain(laws).chain([
            &STRAIN_SCALE,
            &AMPLIFIER_GAIN,
            &ROD_THERMAL_LAG,
        ]);
        for p in all {
            let mut set = ActuatorParams::TERFENOL_DEMO;
            let v = 0.5 * (p.lo + p.hi);
            (p.set)(&mut set, v);
            assert!(((p.get)(&set) - v).abs() <= 1e-6 * v.abs().max(1.0), "{}", p.key);
            let default = (p.get)(&ActuatorParams::TERFENOL_DEMO);
            // The rod's thermal lag defaults to 0, "none" (a fit starts it at its lower bound).
            let off = p.key == ROD_THERMAL_LAG.key && default == 0.0;
            assert!(
                off || (p.lo <= default && default <= p.hi),
                "{}: default {default} outside its range",
                p.key
            );
            assert!(p.scale != Scale::Log || p.lo > 0.0, "{}", p.key);
        }
    }
}
