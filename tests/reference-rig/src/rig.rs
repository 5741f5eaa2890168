//! The rig: configuration ([`Rig`]), its default Terfenol-D parameter set, and the
//! simulation that couples amplifier, coil, thermal model, field diffusion with per-shell
//! hysteresis, magnetic aftereffect, magnetostriction, mechanics and sensors.

use crate::drive::Drive;
use crate::integrator::{DormandPrince, IntegrationError, OdeSystem};
use crate::magnetics::{
    JaParams, JaVariant, Material, PreisachParams, ShellState, DEFAULT_REVERSAL_THRESHOLD, MU0,
};
use crate::mechanics::Mechanics;
use crate::recording::Recording;
use crate::sensor::{FluxChain, SearchCoil, Sensor, SensorChain, SensorSwitches};
use std::f64::consts::PI;

/// How the amplifier drives the coil.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AmplifierMode {
    /// Voltage amplifier: τ dv/dt = G u − v, output clamped to ±rail; the coil then obeys
    /// L di/dt = v − R(T) i. The current limit folds the output voltage back to R i while
    /// |i| ≥ I_max and the voltage would push it further.
    Voltage,
    /// Current-controlled amplifier: τ di/dt = clamp(G_i u, ±I_max) − i (the coil's own
    /// dynamics are inside the current loop).
    Current,
}

/// Power amplifier.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Amplifier {
    /// Voltage or current mode.
    pub mode: AmplifierMode,
    /// Voltage gain G [V/V] (voltage mode).
    pub voltage_gain: f64,
    /// Transconductance G_i [A/V] (current mode).
    pub current_gain_a_per_v: f64,
    /// Time constant τ of the first-order lag (s).
    pub tau_s: f64,
    /// Output voltage rail (V) (voltage mode).
    pub rail_v: f64,
    /// Output current limit I_max (A).
    pub current_limit_a: f64,
}

/// Drive coil and magnetic circuit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coil {
    /// Number of turns N.
    pub turns: f64,
    /// Coil (and rod) length L_c (m).
    pub length_m: f64,
    /// Flux-leakage factor k_f ≥ 1: H = N i / (k_f L_c).
    pub leakage_factor: f64,
    /// Resistance R0 at the reference temperature (Ω).
    pub resistance_ohm: f64,
    /// Inductance L (H).
    pub inductance_h: f64,
    /// Temperature coefficient of the copper resistance [1/°C] (0.0039).
    pub temperature_coefficient_per_c: f64,
    /// Bias field of the permanent magnet H_bias [A/m].
    pub bias_field_a_per_m: f64,
}

impl Coil {
    /// Field per ampere n = N / (k_f L_c) [1/m].
    pub fn turns_per_m(&self) -> f64 {
        self.turns / (self.leakage_factor * self.length_m)
    }
}

/// The Terfenol-D rod.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rod {
    /// Radius R (m).
    pub radius_m: f64,
    /// Active length L (m).
    pub length_m: f64,
    /// Electrical conductivity σ [S/m].
    pub conductivity_s_per_m: f64,
    /// Number of radial shells of the field-diffusion discretisation.
    pub shells: usize,
    /// Thermal expansion coefficient α_T [1/°C].
    pub thermal_expansion_per_c: f64,
}

/// Which magnetization law the shells follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// A Jiles–Atherton variant.
    JilesAtherton(JaVariant),
    /// The Preisach model.
    Preisach,
}

impl Law {
    /// Parse a name as used by the binary: `ja-original`, `ja-bulk`, `ja-inverse`,
    /// `preisach`.
    pub fn from_name(s: &str) -> Option<Law> {
        if s == "preisach" {
            return Some(Law::Preisach);
        }
        JaVariant::ALL.iter().find(|v| v.name() == s).map(|&v| Law::JilesAtherton(v))
    }
}

/// Magnetization-law coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialConfig {
    /// The law.
    pub law: Law,
    /// J–A coefficients (also the anhysteretic law when hysteresis is switched off).
    pub ja: JaParams,
    /// Preisach coefficients.
    pub preisach: PreisachParams,
}

/// Magnetostriction, pre-stress and ΔE effect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Magnetostriction {
    /// Saturation magnetostriction λ_s (1): λ = (3/2) λ_s g (M/M_s)².
    pub lambda_s: f64,
    /// Compressive pre-stress p = −σ0 > 0 (Pa).
    pub prestress_pa: f64,
    /// Pre-stress p_opt of the largest strain gain (Pa): g(p) = (p/p_opt) e^(1 − p/p_opt).
    pub optimal_prestress_pa: f64,
    /// Young's modulus of the demagnetised rod E0 (Pa).
    pub young_demag_pa: f64,
    /// ΔE gain κ: E(M) = E0 (1 + κ (M/M_s)²) (1).
    pub delta_e_gain: f64,
}

/// Magnetic aftereffect (magnetic viscosity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aftereffect {
    /// Share w of the magnetization change that arrives late (1), 0 ≤ w < 1.
    pub fraction: f64,
    /// Central time constant τ (s).
    pub tau_s: f64,
    /// Ratio r between neighbouring time constants τ/r, τ, τ r (≥ 1).
    pub spread: f64,
}

/// Coil and rod temperatures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thermal {
    /// Ambient temperature T_amb [°C].
    pub ambient_c: f64,
    /// Reference temperature T0 of R0, of the strain and of the sensors' zero [°C].
    pub reference_c: f64,
    /// Coil temperature at t = 0 [°C].
    pub initial_coil_c: f64,
    /// Rod temperature at t = 0 [°C].
    pub initial_rod_c: f64,
    /// Heat capacity of the coil C_th [J/°C].
    pub coil_heat_capacity_j_per_c: f64,
    /// Thermal resistance coil–ambient R_th [°C/W].
    pub coil_thermal_resistance_c_per_w: f64,
    /// Time constant of the rod following the coil temperature (s).
    pub rod_time_constant_s: f64,
}

/// Quasi-static field history applied to the rod before t = 0.
#[derive(Clone, Debug, PartialEq)]
pub struct PreHistory {
    /// Fields visited in turn, relative to the bias field [A/m]; afterwards the rod goes to
    /// its field at t = 0.
    pub fields_rel_a_per_m: Vec<f64>,
}

/// Switches, one per effect, so that a test suite can hide one effect at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    /// Amplifier lag (off: a 1 µs lag, the ODE needs a continuous current).
    pub amplifier_lag: bool,
    /// Amplifier current limit.
    pub current_limit: bool,
    /// Coil heating by R i² and R(T).
    pub coil_heating: bool,
    /// Rod temperature following the coil and its thermal expansion.
    pub rod_thermal_expansion: bool,
    /// Field diffusion into the conducting rod (off: uniform field).
    pub eddy_currents: bool,
    /// Hysteresis (off: anhysteretic Langevin law with the J–A a, α, M_s).
    pub hysteresis: bool,
    /// Pre-stress: magnetoelastic mean field and strain-gain factor (off: α̃ = α, g = 1).
    pub prestress: bool,
    /// ΔE effect (off: E = E0).
    pub delta_e: bool,
    /// Magnetic aftereffect.
    pub aftereffect: bool,
    /// Mechanical dynamics (off: static elastic chain).
    pub mechanics: bool,
    /// Second mechanical mode (off: rigid stem, one mode).
    pub second_mode: bool,
    /// Pre-history (off: the rod starts demagnetised and follows the initial curve to its
    /// field at t = 0).
    pub prehistory: bool,
    /// Sensor noise.
    pub sensor_noise: bool,
    /// Sensor quantisation.
    pub sensor_quantisation: bool,
    /// Sensor offset and drift.
    pub sensor_offset_drift: bool,
    /// Displacement transport delay.
    pub sensor_delay: bool,
}

impl Effects {
    /// Every effect on.
    pub const ALL: Effects = Effects {
        amplifier_lag: true,
        current_limit: true,
        coil_heating: true,
        rod_thermal_expansion: true,
        eddy_currents: true,
        hysteresis: true,
        prestress: true,
        delta_e: true,
        aftereffect: true,
        mechanics: true,
        second_mode: true,
        prehistory: true,
        sensor_noise: true,
        sensor_quantisation: true,
        sensor_offset_drift: true,
        sensor_delay: true,
    };

    /// Names of the switches, as accepted by [`Effects::set`].
    pub const NAMES: [&'static str; 16] = [
        "amplifier_lag",
        "current_limit",
        "coil_heating",
        "rod_thermal_expansion",
        "eddy_currents",
        "hysteresis",
        "prestress",
        "delta_e",
        "aftereffect",
        "mechanics",
        "second_mode",
        "prehistory",
        "sensor_noise",
        "sensor_quantisation",
        "sensor_offset_drift",
        "sensor_delay",
    ];

    /// Only the actuator physics, no measurement artefacts (noise, quantisation, offset,
    /// drift, delay off).
    pub fn clean_sensor() -> Effects {
        Effects {
            sensor_noise: false,
            sensor_quantisation: false,
            sensor_offset_drift: false,
            sensor_delay: false,
            ..Effects::ALL
        }
    }

    /// Set the switch called `name`; false if there is none.
    pub fn set(&mut self, name: &str, on: bool) -> bool {
        let f = match name {
            "amplifier_lag" => &mut self.amplifier_lag,
            "current_limit" => &mut self.current_limit,
            "coil_heating" => &mut self.coil_heating,
            "rod_thermal_expansion" => &mut self.rod_thermal_expansion,
            "eddy_currents" => &mut self.eddy_currents,
            "hysteresis" => &mut self.hysteresis,
            "prestress" => &mut self.prestress,
            "delta_e" => &mut self.delta_e,
            "aftereffect" => &mut self.aftereffect,
            "mechanics" => &mut self.mechanics,
            "second_mode" => &mut self.second_mode,
            "prehistory" => &mut self.prehistory,
            "sensor_noise" => &mut self.sensor_noise,
            "sensor_quantisation" => &mut self.sensor_quantisation,
            "sensor_offset_drift" => &mut self.sensor_offset_drift,
            "sensor_delay" => &mut self.sensor_delay,
            _ => return false,
        };
        *f = on;
        true
    }
}

/// Integrator settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solver {
    /// Relative tolerance of the Dormand–Prince error control.
    pub rtol: f64,
    /// Largest internal step (s) (also limited to the sample period).
    pub max_step_s: f64,
    /// Reversal threshold of the hysteresis branch direction [A/m] (see
    /// [`Material::with_reversal_threshold`]).
    pub reversal_threshold_a_per_m: f64,
}

/// A complete rig configuration. [`Rig::default`] is a documented Terfenol-D set.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// Sample rate of the recording (Hz).
    pub sample_rate_hz: f64,
    /// Recording length (s).
    pub duration_s: f64,
    /// Seed of the sensor noise and drift.
    pub seed: u64,
    /// Command voltage.
    pub drive: Drive,
    /// Power amplifier.
    pub amplifier: Amplifier,
    /// Coil and magnetic circuit.
    pub coil: Coil,
    /// Rod geometry and conductivity.
    pub rod: Rod,
    /// Magnetization law.
    pub material: MaterialConfig,
    /// Magnetostriction and pre-stress.
    pub magnetostriction: Magnetostriction,
    /// Magnetic aftereffect.
    pub aftereffect: Aftereffect,
    /// Thermal model.
    pub thermal: Thermal,
    /// Mechanics.
    pub mechanics: Mechanics,
    /// Sensors.
    pub sensor: Sensor,
    /// A search coil on the rod (`flux_density_T` in the recording), or none.
    pub search_coil: Option<SearchCoil>,
    /// Pre-history of the rod.
    pub prehistory: PreHistory,
    /// Effect switches.
    pub effects: Effects,
    /// Integrator settings.
    pub solver: Solver,
}

impl Default for Rig {
    /// Terfenol-D actuator: Ø 8 mm × 80 mm rod, 1000 turns, 20 kA/m magnet bias, 8 MPa
    /// pre-stress, voltage amplifier (gain 5, 50 µs, ±30 V, 2 A limit), resonances near
    /// 1.0 and 2.9 kHz, sampled at 10 kHz; a 1 V, 50 Hz sine command for 0.2 s.
    fn default() -> Self {
        Rig {
            sample_rate_hz: 10_000.0,
            duration_s: 0.2,
            seed: 1,
            drive: Drive::sine(1.0, 50.0),
            amplifier: Amplifier {
                mode: AmplifierMode::Voltage,
                voltage_gain: 5.0,
                current_gain_a_per_v: 1.0,
                tau_s: 50e-6,
                rail_v: 30.0,
                current_limit_a: 2.0,
            },
            coil: Coil {
                turns: 1000.0,
                length_m: 0.08,
                leakage_factor: 1.1,
                resistance_ohm: 5.5,
                inductance_h: 6e-3,
                temperature_coefficient_per_c: 0.0039,
                bias_field_a_per_m: 20e3,
            },
            rod: Rod {
                radius_m: 4e-3,
                length_m: 0.08,
                conductivity_s_per_m: 1.6e6,
                shells: 8,
                thermal_expansion_per_c: 12e-6,
            },
            material: MaterialConfig {
                law: Law::JilesAtherton(JaVariant::BulkVenkataraman),
                ja: JaParams {
                    ms_a_per_m: 7.6e5,
                    a_a_per_m: 7000.0,
                    k_a_per_m: 3500.0,
                    alpha: 0.01,
                    c: 0.18,
                },
                preisach: PreisachParams {
                    ms_a_per_m: 7.6e5,
                    coercive_a_per_m: 3000.0,
                    coercive_spread_a_per_m: 1500.0,
                    interaction_spread_a_per_m: 25e3,
                    reversible_fraction: 0.1,
                    reversible_field_a_per_m: 30e3,
                },
            },
            magnetostriction: Magnetostriction {
                lambda_s: 1.0e-3,
                prestress_pa: 8e6,
                optimal_prestress_pa: 10e6,
                young_demag_pa: 25e9,
                delta_e_gain: 1.2,
            },
            aftereffect: Aftereffect { fraction: 0.06, tau_s: 0.2, spread: 4.0 },
            thermal: Thermal {
                ambient_c: 22.0,
                reference_c: 22.0,
                initial_coil_c: 22.0,
                initial_rod_c: 22.0,
                coil_heat_capacity_j_per_c: 40.0,
                coil_thermal_resistance_c_per_w: 4.0,
                rod_time_constant_s: 90.0,
            },
            mechanics: Mechanics {
                m1_kg: 0.12,
                m2_kg: 0.2,
                k2_n_per_m: 1.5e7,
                ks_n_per_m: 1.0e6,
                c1_n_s_per_m: 80.0,
                c2_n_s_per_m: 60.0,
                cs_n_s_per_m: 30.0,
            },
            sensor: Sensor {
                displacement_noise_um: 0.02,
                displacement_quantum_um: 0.005,
                displacement_offset_um: 25.0,
                drift_rate_um_per_s: 0.05,
                drift_walk_um_per_sqrt_s: 0.02,
                delay_samples: 3,
                current_noise_a: 2e-3,
                current_quantum_a: 0.5e-3,
                current_offset_a: 1e-3,
                temperature_noise_c: 0.02,
            },
            search_coil: None,
            prehistory: PreHistory { fields_rel_a_per_m: vec![50e3, -35e3, 15e3] },
            effects: Effects::ALL,
            solver: Solver {
                rtol: 1e-5,
                max_step_s: 1e-4,
                reversal_threshold_a_per_m: DEFAULT_REVERSAL_THRESHOLD,
            },
        }
    }
}

/// Why a simulation was refused or stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum RigError {
    /// A parameter is out of range; the message names it.
    InvalidParameter(String),
    /// The integrator failed.
    Integration(IntegrationError),
    /// A state became NaN or infinite.
    NonFinite {
        /// Time (s).
        t: f64,
    },
}

impl std::fmt::Display for RigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RigError::InvalidParameter(s) => write!(f, "invalid parameter: {s}"),
            RigError::Integration(e) => write!(f, "{e}"),
            RigError::NonFinite { t } => write!(f, "the state became non-finite at t = {t:.6} s"),
        }
    }
}

impl std::error::Error for RigError {}

impl From<IntegrationError> for RigError {
    fn from(e: IntegrationError) -> Self {
        RigError::Integration(e)
    }
}

fn check(ok: bool, what: &str) -> Result<(), RigError> {
    if ok {
        Ok(())
    } else {
        Err(RigError::InvalidParameter(what.to_string()))
    }
}

impl Rig {
    /// The mean-field contribution of the pre-stress, 9 λ_s σ0 / (2 μ0 M_s²) with σ0 = −p
    /// (compression), or 0 when the effect is off.
    pub fn stress_alpha(&self) -> f64 {
        if !self.effects.prestress {
            return 0.0;
        }
        let ms = self.material.ja.ms_a_per_m;
        -9.0 * self.magnetostriction.lambda_s * self.magnetostriction.prestress_pa / (2.0 * MU0 * ms * ms)
    }

    /// Strain-gain factor of the pre-stress g(p) = (p/p_opt) e^(1 − p/p_opt) (1 when off).
    pub fn prestress_gain(&self) -> f64 {
        if !self.effects.prestress {
            return 1.0;
        }
        let r = self.magnetostriction.prestress_pa / self.magnetostriction.optimal_prestress_pa;
        r * (1.0 - r).exp()
    }

    /// The compiled magnetization law of the shells, as the effect switches select it.
    pub fn material_law(&self) -> Material {
        let ja = self.material.ja;
        let law = if !self.effects.hysteresis {
            Material::anhysteretic(ja, self.stress_alpha())
        } else {
            match self.material.law {
                Law::JilesAtherton(v) => Material::jiles_atherton(v, ja, self.stress_alpha()),
                Law::Preisach => Material::preisach(self.material.preisach),
            }
        };
        law.with_reversal_threshold(self.solver.reversal_threshold_a_per_m)
    }

    /// Check every parameter; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), RigError> {
        let fin = |x: f64| x.is_finite();
        check(fin(self.sample_rate_hz) && self.sample_rate_hz > 0.0, "sample_rate_hz > 0")?;
        check(
            fin(self.duration_s) && self.duration_s * self.sample_rate_hz >= 3.0,
            "duration: at least 3 samples",
        )?;
        check(self.duration_s * self.sample_rate_hz <= 1e8, "duration: at most 1e8 samples")?;
        let a = &self.amplifier;
        check(fin(a.tau_s) && a.tau_s > 0.0, "amplifier.tau_s > 0")?;
        check(fin(a.current_limit_a) && a.current_limit_a > 0.0, "amplifier.current_limit_a > 0")?;
        check(fin(a.rail_v) && a.rail_v > 0.0, "amplifier.rail_v > 0")?;
        check(fin(a.voltage_gain) && fin(a.current_gain_a_per_v), "amplifier gains finite")?;
        let c = &self.coil;
        check(c.turns > 0.0 && c.length_m > 0.0 && c.leakage_factor >= 1.0, "coil geometry")?;
        check(c.resistance_ohm > 0.0 && c.inductance_h > 0.0, "coil.resistance_ohm, inductance_h > 0")?;
        check(
            fin(c.bias_field_a_per_m) && c.temperature_coefficient_per_c >= 0.0,
            "coil bias / temperature coefficient",
        )?;
        let r = &self.rod;
        check(
            r.radius_m > 0.0 && r.length_m > 0.0 && r.conductivity_s_per_m > 0.0,
            "rod geometry/conductivity",
        )?;
        check((1..=64).contains(&r.shells), "rod.shells in 1..=64")?;
        let ja = &self.material.ja;
        check(ja.ms_a_per_m > 0.0 && ja.a_a_per_m > 0.0 && ja.k_a_per_m > 0.0, "ja: M_s, a, k > 0")?;
        check((0.0..1.0).contains(&ja.c), "ja.c in [0, 1)")?;
        let alpha_eff = ja.alpha + self.stress_alpha();
        check(
            alpha_eff * ja.ms_a_per_m / (3.0 * ja.a_a_per_m) < 0.9,
            "ja.alpha (with stress): α̃ M_s / (3a) must stay below 0.9",
        )?;
        let p = &self.material.preisach;
        check(
            p.ms_a_per_m > 0.0
                && p.coercive_a_per_m >= 0.0
                && p.coercive_spread_a_per_m > 0.0
                && p.interaction_spread_a_per_m > 0.0,
            "preisach: M_s > 0, μ_c ≥ 0, s_c > 0, s_u > 0",
        )?;
        check(
            (0.0..1.0).contains(&p.reversible_fraction) && p.reversible_field_a_per_m > 0.0,
            "preisach reversible part",
        )?;
        let m = &self.magnetostriction;
        check(
            m.lambda_s >= 0.0 && m.prestress_pa >= 0.0 && m.optimal_prestress_pa > 0.0,
            "magnetostriction",
        )?;
        check(m.young_demag_pa > 0.0 && m.delta_e_gain > -1.0, "Young's modulus / ΔE gain")?;
        let ae = &self.aftereffect;
        check((0.0..1.0).contains(&ae.fraction) && ae.tau_s > 0.0 && ae.spread >= 1.0, "aftereffect")?;
        let t = &self.thermal;
        check(t.coil_heat_capacity_j_per_c > 0.0 && t.coil_thermal_resistance_c_per_w > 0.0, "thermal coil")?;
        check(t.rod_time_constant_s > 0.0, "thermal.rod_time_constant_s > 0")?;
        let me = &self.mechanics;
        check(me.m1_kg > 0.0 && me.m2_kg > 0.0 && me.k2_n_per_m > 0.0 && me.ks_n_per_m >= 0.0, "mechanics")?;
        check(
            me.c1_n_s_per_m >= 0.0 && me.c2_n_s_per_m >= 0.0 && me.cs_n_s_per_m >= 0.0,
            "mechanics damping",
        )?;
        let s = &self.sensor;
        check(s.delay_samples <= 64, "sensor.delay_samples <= 64")?;
        check(s.displacement_quantum_um >= 0.0 && s.current_quantum_a >= 0.0, "sensor quanta >= 0")?;
        check(self.solver.rtol > 0.0 && self.solver.max_step_s > 0.0, "solver: rtol, max_step_s > 0")?;
        check(self.solver.reversal_threshold_a_per_m >= 0.0, "solver.reversal_threshold_a_per_m >= 0")?;
        Ok(())
    }

    /// Rod stiffness k1 = E(M) A / L for a normalised magnetization m = M/M_s.
    pub fn rod_stiffness(&self, m: f64) -> f64 {
        let ms = &self.magnetostriction;
        let e = if self.effects.delta_e {
            ms.young_demag_pa * (1.0 + ms.delta_e_gain * m * m)
        } else {
            ms.young_demag_pa
        };
        e * PI * self.rod.radius_m * self.rod.radius_m / self.rod.length_m
    }

    /// The rod's magnetic state at t = 0 (one shell; all shells start equal), after the
    /// pre-history, at the field the initial current produces.
    pub fn initial_shell_state(&self, law: &Material) -> ShellState {
        let h_end = self.coil.turns_per_m() * self.initial_current() + self.coil.bias_field_a_per_m;
        let mut s = law.virgin();
        if self.effects.prehistory {
            for &rel in &self.prehistory.fields_rel_a_per_m {
                law.sweep_to(&mut s, self.coil.bias_field_a_per_m + rel, 64);
            }
        }
        law.sweep_to(&mut s, h_end, 64);
        s
    }

    /// The steady coil current for the command at t = 0 (A).
    pub fn initial_current(&self) -> f64 {
        let a = &self.amplifier;
        let u0 = self.drive.value(0.0);
        let i = match a.mode {
            AmplifierMode::Voltage => {
                (a.voltage_gain * u0).clamp(-a.rail_v, a.rail_v) / self.coil.resistance_ohm
            }
            AmplifierMode::Current => a.current_gain_a_per_v * u0,
        };
        if self.effects.current_limit {
            i.clamp(-a.current_limit_a, a.current_limit_a)
        } else {
            i
        }
    }

    /// Run the simulation and return the recording.
    pub fn simulate(&self) -> Result<Recording, RigError> {
        self.validate()?;
        let law = self.material_law();
        let shell0 = self.initial_shell_state(&law);
        let mut sys = RigSystem::new(self, law, shell0);
        let mut y = sys.initial_state(self);
        let dt = 1.0 / self.sample_rate_hz;
        let n = (self.duration_s * self.sample_rate_hz).round() as usize;
        let h_max = self.solver.max_step_s.min(dt);
        let mut dp = DormandPrince::new(self.solver.rtol, sys.atol(), h_max.min(1e-6), h_max);
        let sw = SensorSwitches {
            noise: self.effects.sensor_noise,
            quantisation: self.effects.sensor_quantisation,
            offset_drift: self.effects.sensor_offset_drift,
            delay: self.effects.sensor_delay,
        };
        let mut sensor = SensorChain::new(self.sensor, sw, self.seed, dt);
        let mut flux = self.search_coil.map(|c| (c, FluxChain::new(c, sw, self.seed)));
        let mut rec = Recording { dt_s: dt, ..Recording::default() };
        for k in 0..n {
            let t = k as f64 * dt;
            if k > 0 {
                dp.integrate(&mut sys, (k - 1) as f64 * dt, t, &mut y)?;
                if y.iter().any(|v| !v.is_finite()) {
                    return Err(RigError::NonFinite { t });
                }
            }
            let o = sys.outputs(t, &y);
            let (x_m, i_m, temp_m) = sensor.measure(t, o.x_out_m * 1e6, y[I], y[TC]);
            let vals = [o.u, i_m, x_m, temp_m, o.x_out_m, o.mbar, o.hs, o.h_core];
            if vals.iter().any(|v| !v.is_finite()) {
                return Err(RigError::NonFinite { t });
            }
            rec.time_s.push(t);
            rec.command_v.push(o.u);
            rec.current_a.push(i_m);
            rec.displacement_um.push(x_m);
            rec.temperature_c.push(temp_m);
            rec.true_current_a.push(y[I]);
            rec.true_displacement_um.push(o.x_out_m * 1e6);
            rec.coil_temperature_c.push(y[TC]);
            rec.rod_temperature_c.push(y[TR]);
            rec.mean_magnetization_a_per_m.push(o.mbar);
            rec.surface_field_a_per_m.push(o.hs);
            rec.core_field_a_per_m.push(o.h_core);
            if let Some((coil, chain)) = flux.as_mut() {
                // The coil links the rod's flux and, between rod and winding, μ0 H_s.
                let b = MU0 * (o.h_mean + o.m_obs + (coil.area_ratio - 1.0) * o.hs);
                let measured = chain.measure(t, b);
                if !(b.is_finite() && measured.is_finite()) {
                    return Err(RigError::NonFinite { t });
                }
                rec.flux_density_t.get_or_insert_with(Vec::new).push(measured);
                rec.true_flux_density_t.get_or_insert_with(Vec::new).push(b);
            }
        }
        rec.stats = dp.stats();
        Ok(rec)
    }
}

// State layout.
const VA: usize = 0; // amplifier output voltage [V]
const I: usize = 1; // coil current [A]
const TC: usize = 2; // coil temperature [°C]
const TR: usize = 3; // rod temperature [°C]
const H0: usize = 4; // shell fields [A/m], then shell magnetizations, aftereffect, mechanics
const AE_TERMS: usize = 3;

struct Outputs {
    u: f64,
    x_out_m: f64,
    mbar: f64,
    /// Magnetization after the aftereffect (what the strain and the flux see).
    m_obs: f64,
    hs: f64,
    /// Area-averaged field in the rod.
    h_mean: f64,
    h_core: f64,
}

/// The coupled ODE system (private: the configuration is the public interface).
struct RigSystem<'a> {
    rig: &'a Rig,
    law: Material,
    shells: Vec<ShellState>,
    n_shells: usize,
    weights: Vec<f64>,
    dr2: f64,
    n_per_m: f64,
    diffusion_den: f64, // σ μ0
    ae_tau: [f64; AE_TERMS],
    ae_w: f64,
    strain_gain: f64,
    amp_tau: f64,
    m_idx: usize,
    ae_idx: usize,
    mech_idx: usize,
    dim: usize,
}

impl<'a> RigSystem<'a> {
    fn new(rig: &'a Rig, law: Material, shell0: ShellState) -> Self {
        let fx = &rig.effects;
        let n_shells = if fx.eddy_currents { rig.rod.shells } else { 1 };
        let nn = (n_shells * n_shells) as f64;
        let weights = (0..n_shells).map(|j| (2 * j + 1) as f64 / nn).collect();
        let dr = rig.rod.radius_m / n_shells as f64;
        let m_idx = H0 + n_shells;
        let ae_idx = m_idx + n_shells;
        let mech_idx = ae_idx + AE_TERMS;
        let ae = &rig.aftereffect;
        RigSystem {
            rig,
            law,
            shells: vec![shell0; n_shells],
            n_shells,
            weights,
            dr2: dr * dr,
            n_per_m: rig.coil.turns_per_m(),
            diffusion_den: rig.rod.conductivity_s_per_m * MU0,
            ae_tau: [ae.tau_s / ae.spread, ae.tau_s, ae.tau_s * ae.spread],
            ae_w: ae.fraction / AE_TERMS as f64,
            strain_gain: 1.5 * rig.magnetostriction.lambda_s * rig.prestress_gain(),
            amp_tau: if fx.amplifier_lag { rig.amplifier.tau_s } else { 1e-6 },
            m_idx,
            ae_idx,
            mech_idx,
            dim: mech_idx + 4,
        }
    }

    fn atol(&self) -> Vec<f64> {
        let mut a = vec![0.0; self.dim];
        a[VA] = 1e-6;
        a[I] = 1e-7;
        a[TC] = 1e-6;
        a[TR] = 1e-6;
        for j in 0..self.n_shells {
            a[H0 + j] = 1e-2;
            a[self.m_idx + j] = 1e-1;
        }
        for k in 0..AE_TERMS {
            a[self.ae_idx + k] = 1e-1;
        }
        let mi = self.mech_idx;
        a[mi] = 1e-12;
        a[mi + 1] = 1e-9;
        a[mi + 2] = 1e-12;
        a[mi + 3] = 1e-9;
        a
    }

    fn initial_state(&self, rig: &Rig) -> Vec<f64> {
        let mut y = vec![0.0; self.dim];
        let i0 = rig.initial_current();
        y[VA] = match rig.amplifier.mode {
            AmplifierMode::Voltage => (rig.amplifier.voltage_gain * rig.drive.value(0.0))
                .clamp(-rig.amplifier.rail_v, rig.amplifier.rail_v),
            AmplifierMode::Current => 0.0,
        };
        y[I] = i0;
        y[TC] = rig.thermal.initial_coil_c;
        y[TR] = rig.thermal.initial_rod_c;
        for j in 0..self.n_shells {
            y[H0 + j] = self.shells[j].h;
            y[self.m_idx + j] = self.shells[j].m;
        }
        let mbar = self.shells[0].m;
        for k in 0..AE_TERMS {
            y[self.ae_idx + k] = mbar;
        }
        let (x_free, k1) = self.free_displacement(&y, mbar);
        let (x1, x2) = rig.mechanics.static_positions(k1, x_free, rig.effects.second_mode);
        let mi = self.mech_idx;
        y[mi] = x1;
        y[mi + 2] = x2;
        y
    }

    fn mean_m(&self, y: &[f64]) -> f64 {
        (0..self.n_shells).map(|j| self.weights[j] * y[self.m_idx + j]).sum()
    }

    /// Magnetization seen by the strain: the aftereffect mixes in the lagging terms.
    fn observed_m(&self, y: &[f64], mbar: f64) -> f64 {
        if !self.rig.effects.aftereffect {
            return mbar;
        }
        let lag: f64 = (0..AE_TERMS).map(|k| y[self.ae_idx + k]).sum();
        (1.0 - self.ae_w * AE_TERMS as f64) * mbar + self.ae_w * lag
    }

    /// Free displacement L (λ + ε_T) (m) and rod stiffness [N/m].
    fn free_displacement(&self, y: &[f64], mbar: f64) -> (f64, f64) {
        let rig = self.rig;
        let m = self.observed_m(y, mbar) / self.law.ms();
        let lambda = self.strain_gain * m * m;
        let eps_t = if rig.effects.rod_thermal_expansion {
            rig.rod.thermal_expansion_per_c * (y[TR] - rig.thermal.reference_c)
        } else {
            0.0
        };
        (rig.rod.length_m * (lambda + eps_t), rig.rod_stiffness(m))
    }

    fn outputs(&self, t: f64, y: &[f64]) -> Outputs {
        let rig = self.rig;
        let mbar = self.mean_m(y);
        let x_out_m = if rig.effects.mechanics {
            y[self.mech_idx + 2]
        } else {
            let (xf, k1) = self.free_displacement(y, mbar);
            rig.mechanics.static_positions(k1, xf, rig.effects.second_mode).1
        };
        Outputs {
            u: rig.drive.value(t),
            x_out_m,
            mbar,
            m_obs: self.observed_m(y, mbar),
            hs: self.n_per_m * y[I] + rig.coil.bias_field_a_per_m,
            h_mean: (0..self.n_shells).map(|j| self.weights[j] * y[H0 + j]).sum(),
            h_core: y[H0],
        }
    }

    fn resistance(&self, t_coil: f64) -> f64 {
        let c = &self.rig.coil;
        if self.rig.effects.coil_heating {
            c.resistance_ohm
                * (1.0 + c.temperature_coefficient_per_c * (t_coil - self.rig.thermal.reference_c))
        } else {
            c.resistance_ohm
        }
    }
}

impl OdeSystem for RigSystem<'_> {
    fn rhs(&mut self, t: f64, y: &[f64], dy: &mut [f64]) {
        let rig = self.rig;
        let fx = &rig.effects;
        let amp = &rig.amplifier;
        let u = rig.drive.value(t);
        let i = y[I];
        let r = self.resistance(y[TC]);
        // Amplifier and coil.
        match amp.mode {
            AmplifierMode::Voltage => {
                dy[VA] = (amp.voltage_gain * u - y[VA]) / self.amp_tau;
                let mut v = y[VA].clamp(-amp.rail_v, amp.rail_v);
                if fx.current_limit {
                    let il = amp.current_limit_a;
                    if (i >= il && v > r * i) || (i <= -il && v < r * i) {
                        v = r * i;
                    }
                }
                dy[I] = (v - r * i) / rig.coil.inductance_h;
            }
            AmplifierMode::Current => {
                dy[VA] = 0.0;
                let mut target = amp.current_gain_a_per_v * u;
                if fx.current_limit {
                    target = target.clamp(-amp.current_limit_a, amp.current_limit_a);
                }
                dy[I] = (target - i) / self.amp_tau;
            }
        }
        // Thermal: C dT/dt = R i² − (T − T_amb)/R_th; the rod follows the coil.
        let th = &rig.thermal;
        dy[TC] = if fx.coil_heating {
            (r * i * i - (y[TC] - th.ambient_c) / th.coil_thermal_resistance_c_per_w)
                / th.coil_heat_capacity_j_per_c
        } else {
            0.0
        };
        dy[TR] = if fx.rod_thermal_expansion { (y[TC] - y[TR]) / th.rod_time_constant_s } else { 0.0 };
        // Field: surface value from the coil, diffusion into the shells.
        let hs = self.n_per_m * i + rig.coil.bias_field_a_per_m;
        let dhs = self.n_per_m * dy[I];
        let n = self.n_shells;
        let mi = self.m_idx;
        if fx.eddy_currents {
            // Finite volumes on equal-width annuli (cell j: r ∈ [jΔr, (j+1)Δr]):
            // σ dB_j/dt = [2(j+1)(H_{j+1} − H_j) − 2j(H_j − H_{j−1})] / ((2j+1)Δr²),
            // the outer face sees the surface value at distance Δr/2 (factor 4N).
            for j in 0..n {
                let hj = y[H0 + j];
                let inner = if j > 0 { 2.0 * j as f64 * (hj - y[H0 + j - 1]) } else { 0.0 };
                let outer = if j + 1 < n {
                    2.0 * (j + 1) as f64 * (y[H0 + j + 1] - hj)
                } else {
                    4.0 * n as f64 * (hs - hj)
                };
                let lap = (outer - inner) / ((2 * j + 1) as f64 * self.dr2);
                let up = self.law.direction(&self.shells[j], hj);
                let chi = self.law.susceptibility(&self.shells[j], hj, y[mi + j], up);
                let dh = lap / (self.diffusion_den * (1.0 + chi));
                dy[H0 + j] = dh;
                dy[mi + j] = chi * dh;
            }
        } else {
            let up = self.law.direction(&self.shells[0], y[H0]);
            let chi = self.law.susceptibility(&self.shells[0], y[H0], y[mi], up);
            dy[H0] = dhs;
            dy[mi] = chi * dhs;
        }
        let mbar = self.mean_m(y);
        // Aftereffect: three lagging copies of the mean magnetization.
        for k in 0..AE_TERMS {
            dy[self.ae_idx + k] =
                if fx.aftereffect { (mbar - y[self.ae_idx + k]) / self.ae_tau[k] } else { 0.0 };
        }
        // Mechanics.
        let me = self.mech_idx;
        if fx.mechanics {
            let (xf, k1) = self.free_displacement(y, mbar);
            let s = [y[me], y[me + 1], y[me + 2], y[me + 3]];
            let (a1, a2) = rig.mechanics.accelerations(k1, xf, s, fx.second_mode);
            dy[me] = s[1];
            dy[me + 1] = a1;
            dy[me + 2] = s[3];
            dy[me + 3] = a2;
        } else {
            dy[me..me + 4].fill(0.0);
        }
    }

    fn accepted(&mut self, _t: f64, y: &mut [f64]) -> bool {
        let mut changed = false;
        let rig = self.rig;
        if rig.effects.current_limit && rig.amplifier.mode == AmplifierMode::Voltage {
            let il = rig.amplifier.current_limit_a;
            if y[I].abs() > il {
                y[I] = y[I].clamp(-il, il);
                changed = true;
            }
        }
        for j in 0..self.n_shells {
            // Preisach: M integrated on the accepted path, not the integrator's (see
            // `Material::branch_m`); set to the Everett sum by `commit` at a reversal.
            let m = self.law.branch_m(&self.shells[j], y[H0 + j]).unwrap_or(y[self.m_idx + j]);
            changed |= self.law.commit(&mut self.shells[j], y[H0 + j], m) || m != y[self.m_idx + j];
            y[self.m_idx + j] = self.shells[j].m;
        }
        changed
    }
}
