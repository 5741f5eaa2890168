//! The actuator's parameter set: every stage's parameters in one value, so one file serves every
//! model spec ([`crate::chain::Actuator`] validates the stages a spec uses), and the Terfenol-D
//! demo set.

use crate::amplifier::{FirstOrderAmpParams, SecondOrderAmpParams};
use crate::error::{check, ParamError};
use crate::field::CoilField;
use crate::magnetization::{AnhystereticParams, JaParams, LinearMagnetization, PreisachParams};
use crate::magnetostriction::QuadraticParams;
use crate::mechanics::{MassSpringDamper, SecondOrderZoh};
use crate::slow::{AftereffectParams, ThermalParams};

/// Mechanics as the workbench identifies it: resonance and damping of y_free → y.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ModalMechanics {
    /// Natural frequency f_n [Hz]; at a sample period, high enough that the f32 step decays
    /// ([`ModalMechanics::discretised`]).
    pub natural_frequency_hz: f32,
    /// Damping ratio ζ, at least [`ModalMechanics::MIN_DAMPING_RATIO`].
    pub damping_ratio: f32,
}

impl ModalMechanics {
    /// Smallest damping ratio accepted (a resonance gain of 500; real actuators' modes: 0.01 and
    /// up). Undamped, the step's f32 transition matrix set the amplitude: a free oscillation grew
    /// 2.48× over 1e8 samples; and the states stay below 500 times the largest free
    /// displacement the other bounds allow, so finite.
    pub const MIN_DAMPING_RATIO: f32 = 1e-3;

    /// Largest damping ratio accepted: beyond it the mode is a first-order lag of τ = 2ζ/ω_n
    /// (a real actuator's modes: ζ below 10), and far beyond (ζ ≳ 1e8) the overdamped step's
    /// slow pole ω_n (ζ − √(ζ² − 1)) cancels to 0 even in f64 (a 1e-30 kg mass stepped to 1e-29 µm
    /// where a lag reaches 2.8 µm).
    pub const MAX_DAMPING_RATIO: f32 = 1e3;

    /// Largest natural frequency accepted [Hz]: far above any rod's first mode and any sample
    /// rate, and low enough that ω_n² stays finite in f32 (at 1e30 Hz the unit mass 1/ω_n² was 0
    /// and the set was refused as `mech.mass_kg`, a name the parameter file does not have).
    pub const MAX_NATURAL_FREQUENCY_HZ: f32 = 1e9;
    /// Smallest natural frequency accepted [Hz], for the same reason at the other end (1/ω_n²
    /// overflows below about 1e-20 Hz); at a sample period [`Self::discretised`] asks more.
    pub const MIN_NATURAL_FREQUENCY_HZ: f32 = 1e-6;

    /// The unit-stiffness mass-spring-damper with this f_n and ζ (static gain 1).
    pub fn unit_gain(&self) -> Result<MassSpringDamper, ParamError> {
        const NAME: &str = "mech.natural_frequency_hz";
        let fn_hz =
            check(NAME, self.natural_frequency_hz, |f| f >= Self::MIN_NATURAL_FREQUENCY_HZ, ">= 1e-6 Hz")?;
        let fn_hz = check(
            NAME,
            fn_hz,
            |f| f <= Self::MAX_NATURAL_FREQUENCY_HZ,
            "<= 1e9 Hz (a mode above every sample rate does not show: leave `mech` out)",
        )?;
        let zeta =
            check("mech.damping_ratio", self.damping_ratio, |z| z >= Self::MIN_DAMPING_RATIO, ">= 1e-3")?;
        let zeta = check(
            "mech.damping_ratio",
            zeta,
            |z| z <= Self::MAX_DAMPING_RATIO,
            "<= 1e3 (more damped, the mode is a first-order lag of 2 damping_ratio / (2 pi f_n))",
        )?;
        let w = 2.0 * core::f32::consts::PI * fn_hz;
        Ok(MassSpringDamper {
            mass_kg: 1.0 / (w * w),
            damping_n_s_per_m: 2.0 * zeta / w,
            stiffness_n_per_m: 1.0,
        })
    }

    /// [`Self::unit_gain`] discretised at `dt_s`, refused by f_n when a free oscillation would
    /// not decay in f32: it decays by ζ 2π f_n dt_s per sample, and for a mode far below the
    /// sample rate (f_n dt_s ≲ 1e-4 at the smallest ζ) the rounding of the step's coefficients
    /// is as large.
    pub fn discretised(&self, dt_s: f32) -> Result<SecondOrderZoh, ParamError> {
        let zoh = SecondOrderZoh::new(self.unit_gain()?, dt_s)?;
        if !zoh.decays() {
            return Err(ParamError::OutOfRange(
                "mech.natural_frequency_hz",
                "high enough against the sample rate that the f32 step decays (damping_ratio * 2 pi * f_n * dt_s above about 1e-7)",
            ));
        }
        Ok(zoh)
    }
}

/// One complete parameter set (every stage; the spec decides which are used).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ActuatorParams {
    /// Sample period [s] the model is stepped at.
    pub dt_s: f32,
    /// `amplifier_dynamics`: first-order amplifier (000 eq. 19).
    pub amp: FirstOrderAmpParams,
    /// `amplifier_dynamics` with 002's second-order amplifier instead of the first-order one,
    /// when set (omit it in parameter files to keep the first-order model). Always serialised
    /// (TOML leaves a `None` field out by itself): postcard, which the firmware embeds the set
    /// in, has no field names and cannot skip a field on reading.
    #[cfg_attr(feature = "serde", serde(default))]
    pub amp_second_order: Option<SecondOrderAmpParams>,
    /// Coil field gain and bias.
    pub coil: CoilField,
    /// `eddy_current`: lumped eddy time constant τ [s] (see [`crate::field::eddy_time_constant_s`]).
    pub eddy_tau_s: f32,
    /// Minimal model: M = a + bH.
    pub linear: LinearMagnetization,
    /// `saturation`: Langevin curve.
    pub anhysteretic: AnhystereticParams,
    /// `hysteresis`: Jiles–Atherton.
    pub ja: JaParams,
    /// `preisach`: Preisach density.
    pub preisach: PreisachParams,
    /// Quadratic magnetostriction.
    pub magnetostriction: QuadraticParams,
    /// Active rod length [m]: free displacement = λ L. In [1e-4, 10] m: a 0.1 mm rod is
    /// already a film (the inverse divides the displacement by it).
    pub rod_length_m: f32,
    /// `mechanical_dynamics`.
    pub mech: ModalMechanics,
    /// `magnetic_aftereffect`.
    pub aftereffect: AftereffectParams,
    /// `thermal_drift`.
    pub thermal: ThermalParams,
    /// `sensor_delay` [samples], below [`MAX_DELAY_SAMPLES`]; a fraction interpolates linearly
    /// between samples (a sensor's delay need not be a whole number of our sample periods).
    #[cfg_attr(feature = "serde", serde(serialize_with = "whole_as_integer"))]
    pub delay_samples: f32,
}

/// Writes a whole number as an integer: parameter files from before fractional delays (and the
/// readers of their time) take `delay_samples` as one.
#[cfg(feature = "serde")]
fn whole_as_integer<S: serde::Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
    // Only in text formats (TOML/JSON for people); binary wire formats (postcard) keep the f32
    // their decoder expects.
    let whole = *v as u16; // saturating; `f32::fract` is not in core
    if s.is_human_readable() && f32::from(whole) == *v {
        s.serialize_u16(whole)
    } else {
        s.serialize_f32(*v)
    }
}

impl ActuatorParams {
    /// A Terfenol-D actuator in the range of the papers (000 Table 1 coil and mechanics scaled to
    /// a 10 kHz loop, 002 Table III J–A), the default for simulations and demos.
    pub const TERFENOL_DEMO: ActuatorParams = ActuatorParams {
        dt_s: 1e-4,
        amp: FirstOrderAmpParams { gain_a_per_v: 2.0, tau_s: 2e-4 },
        amp_second_order: None,
        coil: CoilField { turns_per_m: 13_541.7, bias_a_per_m: 20_000.0 }, // 1300 turns, 80 mm, k_f 1.2
        eddy_tau_s: 1.5e-4,
        linear: LinearMagnetization { offset_a_per_m: 0.0, susceptibility: 7.0 },
        anhysteretic: AnhystereticParams { ms_a_per_m: 6.0e5, a_a_per_m: 9000.0 },
        ja: JaParams::TSMA_ROD1_002,
        preisach: PreisachParams {
            ms_a_per_m: 6.0e5,
            coercive_a_per_m: 3000.0,
            spread_a_per_m: 10_000.0,
            interaction_spread_a_per_m: Some(10_000.0),
            reversible_fraction: None,
            reversible_field_a_per_m: None,
            h_max_a_per_m: 80_000.0,
        },
        magnetostriction: QuadraticParams {
            lambda_s: 1.0e-3,
            ms_a_per_m: 6.0e5,
            bias_m_a_per_m: 0.0,
            preload: None,
        },
        rod_length_m: 0.08,
        mech: ModalMechanics { natural_frequency_hz: 1584.0, damping_ratio: 0.3 },
        aftereffect: AftereffectParams { fraction: 0.1, tau_s: 0.2 },
        thermal: ThermalParams {
            coil_resistance_ohm: 6.0,
            thermal_resistance_c_per_w: 1.5,
            tau_s: 30.0,
            rod_length_m: 0.08,
            expansion_per_c: ThermalParams::TERFENOL_EXPANSION_PER_C,
            rod_tau_s: 0.0,
        },
        delay_samples: 3.0,
    };
}
