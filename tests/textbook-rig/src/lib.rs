//! # textrig — the textbook rig
//!
//! An independent, continuous-time simulator of exactly the model physics the `gma` workbench
//! documents (docs/cli.md "Model specification", docs/formats.md "Keys"), written from the
//! documented equations and the papers only. Its recordings hold the workbench to its own
//! physics: a correct model must fit them to the noise floor and return the rig's parameters
//! ([`Params::to_gma_toml`] writes them as a gma parameter file).
//!
//! All dynamic states form one ODE system integrated by an adaptive Dormand–Prince 5(4)
//! ([`solver`]) with error control, f64, the drive evaluated at the stage times, the reversals
//! of the field located as events, the sensor delay read from the dense output.

// `!(x <= 1.0)` is meant: it is true for NaN too (a NaN error estimate rejects the step).
// Index loops over several state vectors at once read like the solver's equations.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod params;
pub mod preisach;
pub mod solver;
pub mod wave;

pub use params::{
    AftereffectParams, AmpParams, AmpSecondOrder, AnhystereticParams, CoilParams, JaParams, JaVariant,
    LinearParams, MagnetostrictionParams, MechParams, Params, PreisachParams, Preload, RigParams,
    ThermalParams,
};

use preisach::{Everett, Memory};
use rand::SeedableRng;
use rand_chacha::ChaCha20Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;
use std::fmt;
use wave::Signal;

/// Vacuum permeability [H/m] (4π·10⁻⁷, as docs/formats.md gives it).
pub const MU0: f64 = 4.0e-7 * PI;
/// The rig's behaviour, counted up whenever a change moves what it records (suites that cache
/// its recordings key them by it). 2: the mechanics start at rest at the free displacement.
pub const BEHAVIOUR: u32 = 2;
/// The current ADC's least significant bit [A]: 12 bits over ±4 A.
pub const CURRENT_LSB_A: f64 = 8.0 / 4096.0;
/// Reversals of the AC demagnetisation that stands in for the ideal demagnetised Preisach plane.
pub const PREISACH_DEMAG_REVERSALS: usize = 2000;

/// What went wrong; names the effect or the parameter.
#[derive(Clone, Debug, PartialEq)]
pub enum RigError {
    /// An effect name not in the documented table.
    UnknownEffect(String),
    /// A model spec that is malformed or contradictory.
    BadStructure(String),
    /// A parameter (or experiment setting) out of its range.
    BadParameter(String),
    /// The integration failed (step size underflow, non-finite state).
    Solver(String),
}

impl fmt::Display for RigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RigError::UnknownEffect(s) => write!(f, "unknown effect `{s}`"),
            RigError::BadStructure(s) => write!(f, "model structure: {s}"),
            RigError::BadParameter(s) => write!(f, "bad parameter: {s}"),
            RigError::Solver(s) => write!(f, "solver: {s}"),
        }
    }
}

impl std::error::Error for RigError {}

/// The drive's shape (times the amplitude, plus the offset).
#[derive(Clone, Debug, PartialEq)]
pub enum Waveform {
    /// sin 2πft.
    Sine {
        /// f [Hz].
        freq_hz: f64,
    },
    /// ±1 square wave starting low, with raised-cosine edges of `rise_s` (0: a jump).
    Square {
        /// f [Hz].
        freq_hz: f64,
        /// Edge duration [s].
        rise_s: f64,
    },
    /// Levels held for `hold_s` each, in order, repeated; jumps between them.
    Steps {
        /// Levels (times the amplitude).
        levels: Vec<f64>,
        /// Hold per level [s].
        hold_s: f64,
    },
    /// `tones` sines equally spaced over [f_lo, f_hi], random phases from the seed (lowest
    /// peak of 32 draws), scaled to a peak of 1.
    Multisine {
        /// Lowest tone [Hz].
        f_lo_hz: f64,
        /// Highest tone [Hz].
        f_hi_hz: f64,
        /// Number of tones.
        tones: usize,
    },
    /// Sine sweep from f0 to f1 over the run's duration, linear or logarithmic.
    Chirp {
        /// Start frequency [Hz].
        f0_hz: f64,
        /// End frequency [Hz].
        f1_hz: f64,
        /// Logarithmic sweep.
        log: bool,
    },
}

/// A drive: volts in command mode (structure with `amp`), amperes in current mode.
#[derive(Clone, Debug, PartialEq)]
pub struct Drive {
    /// Shape.
    pub waveform: Waveform,
    /// Amplitude [V or A].
    pub amplitude: f64,
    /// Offset (bias) [V or A].
    pub offset: f64,
}

/// Initial state at t = 0.
#[derive(Clone, Debug, PartialEq)]
pub enum Start {
    /// Irreversible state 0 at the field of t = 0 (J–A: the integrated state 0; Preisach: the
    /// AC-demagnetised plane, then the field raised from 0 to its t = 0 value).
    Demagnetised,
    /// The anhysteretic state at the field of t = 0 (M = M_an, J–A M_irr = M_an).
    Anhysteretic,
    /// Demagnetised, then `drive` for `duration_s` before t = 0 (not logged).
    History {
        /// The pre-drive.
        drive: Drive,
        /// Its duration [s].
        duration_s: f64,
    },
}

/// Noise and quantisation of the logged channels (never in the physics).
#[derive(Clone, Debug, PartialEq)]
pub struct Noise {
    /// Gaussian noise of the current ADC, in LSB rms (LSB = 8/4096 A).
    pub current_lsb_rms: f64,
    /// Quantise the logged current to the LSB (12-bit ADC over ±4 A, clipped at its rails).
    pub quantise_current: bool,
    /// Displacement noise [µm rms].
    pub displacement_um_rms: f64,
    /// Search-coil flux noise [T rms].
    pub flux_t_rms: f64,
    /// Thermometer noise [°C rms].
    pub temperature_c_rms: f64,
}

impl Noise {
    /// Clean channels: no noise, no quantisation (the logged current is exact).
    pub fn none() -> Noise {
        Noise {
            current_lsb_rms: 0.0,
            quantise_current: false,
            displacement_um_rms: 0.0,
            flux_t_rms: 0.0,
            temperature_c_rms: 0.0,
        }
    }

    /// A typical bench: the given current noise, quantised; 0.03 µm, 0.2 mT, 0.01 °C rms.
    pub fn typical(current_lsb_rms: f64) -> Noise {
        Noise {
            current_lsb_rms,
            quantise_current: true,
            displacement_um_rms: 0.03,
            flux_t_rms: 0.2e-3,
            temperature_c_rms: 0.01,
        }
    }
}

/// One simulated experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct Experiment {
    /// Model spec (effects joined by `+`, docs/cli.md).
    pub structure: String,
    /// The true parameters.
    pub params: Params,
    /// The drive.
    pub drive: Drive,
    /// Logged duration [s].
    pub duration_s: f64,
    /// Logging rate [Hz].
    pub rate_hz: f64,
    /// Initial state.
    pub start: Start,
    /// Noise of the logged channels.
    pub noise: Noise,
    /// Seed of the noise (and of the multisine phases).
    pub seed: u64,
    /// Log `flux_density_T`.
    pub log_flux: bool,
    /// Log `temperature_C`.
    pub log_temperature: bool,
}

/// Noise-free truth at the sample times.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Truth {
    /// True coil current [A].
    pub current_a: Vec<f64>,
    /// True displacement as a perfect sensor logs it (after the mechanics and the delay) [µm].
    pub displacement_um: Vec<f64>,
    /// Field in the rod H_rod (after the eddy lag), the field the magnetization law sees [A/m].
    pub field_a_per_m: Vec<f64>,
    /// Observed magnetization M_obs (after the aftereffect) [A/m].
    pub magnetization_a_per_m: Vec<f64>,
    /// Coil field H = turns_per_m · i + bias [A/m].
    pub coil_field_a_per_m: Vec<f64>,
    /// The magnetization law's M (before the aftereffect) [A/m].
    pub law_magnetization_a_per_m: Vec<f64>,
    /// Displacement before the delay [µm].
    pub undelayed_displacement_um: Vec<f64>,
    /// Flux density μ0 (H_rod + M_obs) [T].
    pub flux_density_t: Vec<f64>,
    /// Coil temperature [°C].
    pub temperature_c: Vec<f64>,
}

/// Solver statistics.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SolverStats {
    /// Accepted steps.
    pub accepted: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Right-hand-side evaluations.
    pub rhs_evals: usize,
    /// Field reversals located (hysteretic laws).
    pub events: usize,
    /// CPU (wall) time of the simulation [s].
    pub seconds: f64,
}

/// A recording: the logged channels, the truth, the solver statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// Sample times [s].
    pub time_s: Vec<f64>,
    /// Command [V] (command mode only).
    pub command_v: Option<Vec<f64>>,
    /// Logged current [A].
    pub current_a: Vec<f64>,
    /// Logged displacement [µm].
    pub displacement_um: Vec<f64>,
    /// Logged flux density [T].
    pub flux_density_t: Option<Vec<f64>>,
    /// Logged coil temperature [°C].
    pub temperature_c: Option<Vec<f64>>,
    /// Noise-free truth.
    pub truth: Truth,
    /// Solver statistics.
    pub stats: SolverStats,
}

impl Recording {
    /// The measurement CSV of docs/formats.md (only the columns present).
    pub fn write_csv<W: std::io::Write>(&self, w: W) -> std::io::Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(w);
        let dt = if self.time_s.len() > 1 { self.time_s[1] - self.time_s[0] } else { 1.0 };
        let dec = ((-dt.log10()).ceil().max(0.0) as usize) + 3;
        let mut head = String::from("time_s");
        if self.command_v.is_some() {
            head.push_str(",command_V");
        }
        head.push_str(",current_A,displacement_um");
        if self.temperature_c.is_some() {
            head.push_str(",temperature_C");
        }
        if self.flux_density_t.is_some() {
            head.push_str(",flux_density_T");
        }
        writeln!(w, "{head}")?;
        for k in 0..self.time_s.len() {
            write!(w, "{:.*}", dec, self.time_s[k])?;
            if let Some(c) = &self.command_v {
                write!(w, ",{}", c[k])?;
            }
            write!(w, ",{},{}", self.current_a[k], self.displacement_um[k])?;
            if let Some(c) = &self.temperature_c {
                write!(w, ",{}", c[k])?;
            }
            if let Some(c) = &self.flux_density_t {
                write!(w, ",{}", c[k])?;
            }
            writeln!(w)?;
        }
        w.flush()
    }
}

/// Solver settings.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverOptions {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per state = `rtol` × `atol_factor` × the state's physical scale
    /// (1 A, turns_per_m·1 A, M_s, the full-scale displacement, 1 °C, …).
    pub atol_factor: f64,
}

impl Default for SolverOptions {
    fn default() -> SolverOptions {
        SolverOptions { rtol: 1e-9, atol_factor: 1.0 }
    }
}

/// Magnetization law of a structure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Law {
    /// M = a + b H.
    Linear,
    /// M = M_s L(H/a).
    Langevin,
    /// Jiles–Atherton (form from `[ja] variant`).
    JilesAtherton,
    /// Lorentzian Preisach with the reversible part.
    Preisach,
}

/// The effects of a parsed structure.
#[derive(Clone, Debug, PartialEq)]
pub struct Effects {
    /// `amplifier_dynamics`.
    pub amp: bool,
    /// `eddy_current`.
    pub eddy: bool,
    /// The magnetization law.
    pub law: Law,
    /// `magnetic_aftereffect`.
    pub aftereffect: bool,
    /// `mechanical_dynamics`.
    pub mech: bool,
    /// `thermal_drift`.
    pub thermal: bool,
    /// `sensor_delay`.
    pub delay: bool,
}

impl Effects {
    /// Parse a model spec with the documented names and aliases.
    pub fn parse(spec: &str) -> Result<Effects, RigError> {
        if spec.trim().is_empty() {
            return Err(RigError::BadStructure("empty spec".into()));
        }
        let mut e = Effects {
            amp: false,
            eddy: false,
            law: Law::Linear,
            aftereffect: false,
            mech: false,
            thermal: false,
            delay: false,
        };
        let (mut sat, mut hyst, mut pre) = (false, false, false);
        for w in spec.split('+') {
            match w.trim() {
                "" => return Err(RigError::BadStructure(format!("empty effect name in `{spec}`"))),
                "linear" => {}
                "amplifier_dynamics" | "amp" => e.amp = true,
                "eddy_current" | "eddy" => e.eddy = true,
                "saturation" | "anhysteretic" => sat = true,
                "hysteresis" | "ja" => {
                    sat = true;
                    hyst = true
                }
                "preisach" => pre = true,
                "magnetic_aftereffect" | "aftereffect" => e.aftereffect = true,
                "mechanical_dynamics" | "mech" => e.mech = true,
                "thermal_drift" | "thermal" => e.thermal = true,
                "sensor_delay" | "delay" => e.delay = true,
                other => return Err(RigError::UnknownEffect(other.to_string())),
            }
        }
        if pre && (sat || hyst) {
            return Err(RigError::BadStructure("`preisach` excludes `saturation`/`hysteresis`".into()));
        }
        e.law = if pre {
            Law::Preisach
        } else if hyst {
            Law::JilesAtherton
        } else if sat {
            Law::Langevin
        } else {
            Law::Linear
        };
        Ok(e)
    }
}

/// Langevin function L(x) = coth x − 1/x.
pub fn langevin(x: f64) -> f64 {
    if x.abs() < 0.05 {
        let x2 = x * x;
        x * (1.0 / 3.0 - x2 * (1.0 / 45.0 - x2 * (2.0 / 945.0 - x2 * (1.0 / 4725.0 - x2 * 2.0 / 93555.0))))
    } else {
        1.0 / x.tanh() - 1.0 / x
    }
}

/// L'(x) = 1/x² − 1/sinh² x.
pub fn dlangevin(x: f64) -> f64 {
    if x.abs() < 0.05 {
        let x2 = x * x;
        1.0 / 3.0 - x2 * (1.0 / 15.0 - x2 * (2.0 / 189.0 - x2 * (1.0 / 675.0 - x2 * 2.0 / 10395.0)))
    } else {
        let s = x.sinh();
        1.0 / (x * x) - 1.0 / (s * s)
    }
}

/// Jiles–Atherton: the total M for a given M_irr (bulk and ja1986 forms):
/// M = c M_s L((H + αM)/a) + (1 − c) M_irr, solved by Newton.
pub fn ja_total_from_irr(p: &JaParams, h: f64, m_irr: f64) -> f64 {
    let mut m = m_irr;
    for _ in 0..100 {
        let x = (h + p.alpha * m) / p.a_a_per_m;
        let fv = m - p.c * p.ms_a_per_m * langevin(x) - (1.0 - p.c) * m_irr;
        let fd = 1.0 - p.c * p.alpha * p.ms_a_per_m / p.a_a_per_m * dlangevin(x);
        let dm = fv / fd;
        m -= dm;
        if dm.abs() <= 1e-15 * p.ms_a_per_m {
            break;
        }
    }
    m
}

/// Jiles–Atherton anhysteretic state at field `h`: M = M_s L((h + αM)/a).
pub fn ja_anhysteretic(p: &JaParams, h: f64) -> f64 {
    let mut m = p.ms_a_per_m * langevin(h / p.a_a_per_m);
    for _ in 0..100 {
        let x = (h + p.alpha * m) / p.a_a_per_m;
        let fv = m - p.ms_a_per_m * langevin(x);
        let fd = 1.0 - p.alpha * p.ms_a_per_m / p.a_a_per_m * dlangevin(x);
        let dm = fv / fd;
        m -= dm;
        if dm.abs() <= 1e-15 * p.ms_a_per_m {
            break;
        }
    }
    m
}

/// Jiles–Atherton: (total M, d(state)/dH) for the integrated state `s` (M_irr for `bulk` and
/// `ja1986`, M for `szewczyk` and `ja1986-ungated`) at field `h`, direction `delta` = ±1.
pub fn ja_slope(p: &JaParams, h: f64, s: f64, delta: f64) -> (f64, f64) {
    let (ms, a, al, k, c) = (p.ms_a_per_m, p.a_a_per_m, p.alpha, p.k_a_per_m, p.c);
    match p.variant {
        JaVariant::Bulk | JaVariant::Ja1986 => {
            let m = ja_total_from_irr(p, h, s);
            let x = (h + al * m) / a;
            let man = ms * langevin(x);
            let dman = ms / a * dlangevin(x);
            let d = man - s;
            let gate = delta * d > 0.0;
            let ds = if p.variant == JaVariant::Bulk {
                let dirr_dhe = if gate { d / (delta * k) } else { 0.0 };
                let chi_e = c * dman + (1.0 - c) * dirr_dhe;
                // dM_irr/dH = dM_irr/dH_e · dH_e/dH, dH_e/dH = 1 + α dM/dH = 1/(1 − αχ_e).
                dirr_dhe / (1.0 - al * chi_e)
            } else if gate {
                d / (delta * k - al * d)
            } else {
                0.0
            };
            (m, ds)
        }
        JaVariant::Szewczyk | JaVariant::Ja1986Ungated => {
            let m = s;
            let x = (h + al * m) / a;
            let man = ms * langevin(x);
            let dman = ms / a * dlangevin(x);
            let d = man - m;
            let irr = d / ((1.0 + c) * (delta * k - al * d));
            let rev = c / (1.0 + c) * dman;
            let ds = if p.variant == JaVariant::Szewczyk {
                if delta * d > 0.0 {
                    irr + rev
                } else {
                    rev
                }
            } else {
                (irr + rev).max(0.0)
            };
            (m, ds)
        }
    }
}

/// The state layout of a structure.
#[derive(Clone, Debug)]
struct Layout {
    n: usize,
    i: Option<usize>,
    x12: Option<usize>,
    hrod: Option<usize>,
    law: Option<usize>,
    mslow: Option<usize>,
    mech: Option<usize>,
    theta: Option<usize>,
    theta_r: Option<usize>,
}

/// Discrete (hybrid) state: the direction of the field and the relay memory.
#[derive(Clone, Debug)]
struct Disc {
    delta: f64,
    mem: Option<Memory>,
    /// The field's running extreme in the direction `delta`.
    h_ext: f64,
}

/// Everything observable at one instant.
#[derive(Clone, Copy, Debug, Default)]
struct Obs {
    u: f64,
    /// The free displacement [µm] (strain and thermal elongation, before the mechanics).
    y_free: f64,
    i: f64,
    h: f64,
    hrod: f64,
    field_rate: f64,
    m_law: f64,
    m_obs: f64,
    y: f64,
    theta: f64,
}

struct Plant {
    fx: Effects,
    p: Params,
    lay: Layout,
    ev: Option<Everett>,
    scale: Vec<f64>,
    strain_factor: f64,
}

impl Plant {
    fn new(fx: Effects, p: Params) -> Plant {
        let mut n = 0;
        let mut take = |k: usize| {
            let i = n;
            n += k;
            Some(i)
        };
        let second = fx.amp && p.amp_second_order.is_some();
        let i = if second { None } else { take(1) };
        let x12 = if second { take(2) } else { None };
        let hrod = if fx.eddy { take(1) } else { None };
        let law = if fx.law == Law::JilesAtherton { take(1) } else { None };
        let mslow = if fx.aftereffect { take(1) } else { None };
        let mech = if fx.mech { take(2) } else { None };
        let theta = if fx.thermal { take(1) } else { None };
        let theta_r = if fx.thermal && p.thermal.rod_tau_s > 0.0 { take(1) } else { None };
        let lay = Layout { n, i, x12, hrod, law, mslow, mech, theta, theta_r };
        let ms = match fx.law {
            Law::JilesAtherton => p.ja.ms_a_per_m,
            Law::Preisach => p.preisach.ms_a_per_m,
            Law::Langevin => p.anhysteretic.ms_a_per_m,
            Law::Linear => p.magnetostriction.ms_a_per_m,
        };
        let yscale = 1e6 * 1.5 * p.magnetostriction.lambda_s * p.rod_length_m;
        let mut scale = vec![1.0; n];
        if let Some(k) = x12 {
            let b = p.amp_second_order.as_ref().map(|a| a.b_s2).unwrap_or(1.0);
            scale[k] = 1.0;
            scale[k + 1] = 1.0 / b.sqrt();
        }
        if let Some(k) = hrod {
            scale[k] = p.coil.turns_per_m;
        }
        if let Some(k) = law {
            scale[k] = ms;
        }
        if let Some(k) = mslow {
            scale[k] = ms;
        }
        if let Some(k) = mech {
            scale[k] = yscale;
            scale[k + 1] = yscale * 2.0 * PI * p.mech.natural_frequency_hz;
        }
        let ev = if fx.law == Law::Preisach { Some(Everett::new(&p.preisach)) } else { None };
        let strain_factor = p.magnetostriction.preload.as_ref().map(|pl| pl.factor()).unwrap_or(1.0);
        Plant { fx, p, lay, ev, scale, strain_factor }
    }

    fn hysteretic(&self) -> bool {
        matches!(self.fx.law, Law::JilesAtherton | Law::Preisach)
    }

    fn clamp_i(&self, i: f64) -> f64 {
        let l = self.p.rig.current_limit_a;
        i.clamp(-l, l)
    }

    /// Evaluate everything at (t, y); fill `dy` when given.
    fn eval(&self, sig: &Signal, t: f64, y: &[f64], dy: Option<&mut [f64]>, d: &Disc) -> Obs {
        let p = &self.p;
        let lay = &self.lay;
        let mut tmp = [0.0; 12];
        let dy: &mut [f64] = match dy {
            Some(v) => v,
            None => &mut tmp[..lay.n],
        };
        let (w, wdot) = sig.value_rate(t);
        let (i, di) = if self.fx.amp {
            if let Some(k) = lay.x12 {
                let a2 = p.amp_second_order.as_ref().expect("second order");
                let (x1, x2) = (y[k], y[k + 1]);
                let x2d = (w - x1 - a2.c_s * x2) / a2.b_s2;
                dy[k] = x2;
                dy[k + 1] = x2d;
                let raw = a2.k_u * (x1 + a2.a_s * x2);
                if raw.abs() < p.rig.current_limit_a {
                    (raw, a2.k_u * (x2 + a2.a_s * x2d))
                } else {
                    (self.clamp_i(raw), 0.0)
                }
            } else {
                let k = lay.i.expect("current state");
                let i = y[k];
                let di = (self.clamp_i(p.amp.gain_a_per_v * w) - i) / p.amp.tau_s;
                dy[k] = di;
                (i, di)
            }
        } else if let Some(k) = lay.i.filter(|_| p.rig.current_loop_tau_s > 0.0) {
            let i = y[k];
            let di = (self.clamp_i(w) - i) / p.rig.current_loop_tau_s;
            dy[k] = di;
            (i, di)
        } else {
            if let Some(k) = lay.i {
                dy[k] = 0.0;
            }
            let lim = p.rig.current_limit_a;
            if w.abs() < lim {
                (w, wdot)
            } else {
                (self.clamp_i(w), 0.0)
            }
        };
        let h = p.coil.turns_per_m * i + p.coil.bias_a_per_m;
        let dh = p.coil.turns_per_m * di;
        let (hrod, dhrod) = if let Some(k) = lay.hrod {
            let r = (h - y[k]) / p.eddy_tau_s;
            dy[k] = r;
            (y[k], r)
        } else {
            (h, dh)
        };
        let m_law = match self.fx.law {
            Law::Linear => p.linear.offset_a_per_m + p.linear.susceptibility * hrod,
            Law::Langevin => p.anhysteretic.ms_a_per_m * langevin(hrod / p.anhysteretic.a_a_per_m),
            Law::JilesAtherton => {
                let k = lay.law.expect("ja state");
                let (m, ds) = ja_slope(&p.ja, hrod, y[k], d.delta);
                dy[k] = ds * dhrod;
                m
            }
            Law::Preisach => {
                let ev = self.ev.as_ref().expect("everett");
                let mem = d.mem.as_ref().expect("memory");
                let pp = &p.preisach;
                let up = mem.up(ev, hrod, d.delta);
                let rho = pp.reversible_fraction;
                (1.0 - rho) * pp.ms_a_per_m * (2.0 * up - 1.0)
                    + rho * pp.ms_a_per_m * (hrod / pp.reversible_field()).tanh()
            }
        };
        let m_obs = if let Some(k) = lay.mslow {
            dy[k] = (m_law - y[k]) / p.aftereffect.tau_s;
            let wf = p.aftereffect.fraction;
            (1.0 - wf) * m_law + wf * y[k]
        } else {
            m_law
        };
        let ms = &p.magnetostriction;
        let lambda = 1.5 * ms.lambda_s / (ms.ms_a_per_m * ms.ms_a_per_m)
            * (m_obs * m_obs - ms.bias_m_a_per_m * ms.bias_m_a_per_m)
            * self.strain_factor;
        let mut y_free = lambda * p.rod_length_m;
        let mut theta = 0.0;
        if let Some(k) = lay.theta {
            let th = &p.thermal;
            theta = y[k];
            dy[k] = (th.thermal_resistance_c_per_w * th.coil_resistance_ohm * i * i - theta) / th.tau_s;
            let theta_r = if let Some(kr) = lay.theta_r {
                dy[kr] = (theta - y[kr]) / th.rod_tau_s;
                y[kr]
            } else {
                theta
            };
            y_free += th.expansion_per_c * th.rod_length_m * theta_r;
        }
        let y_free_um = 1e6 * y_free;
        let yout = if let Some(k) = lay.mech {
            let wn = 2.0 * PI * p.mech.natural_frequency_hz;
            let z = p.mech.damping_ratio;
            dy[k] = y[k + 1];
            dy[k + 1] = wn * wn * (y_free_um - y[k]) - 2.0 * z * wn * y[k + 1];
            y[k]
        } else {
            y_free_um
        };
        Obs { u: w, y_free: y_free_um, i, h, hrod, field_rate: dhrod, m_law, m_obs, y: yout, theta }
    }

    /// Steady state at the drive's value at `t` with the given start.
    fn initial(&self, sig: &Signal, t: f64, demag: bool) -> (Vec<f64>, Disc) {
        let p = &self.p;
        let lay = &self.lay;
        let mut y = vec![0.0; lay.n];
        let w = sig.value(t);
        let i = if self.fx.amp {
            if let Some(k) = lay.x12 {
                y[k] = w;
                self.clamp_i(p.amp_second_order.as_ref().expect("2nd").k_u * w)
            } else {
                let i = self.clamp_i(p.amp.gain_a_per_v * w);
                y[lay.i.expect("i")] = i;
                i
            }
        } else {
            let i = self.clamp_i(w);
            if let Some(k) = lay.i {
                y[k] = i;
            }
            i
        };
        let h0 = p.coil.turns_per_m * i + p.coil.bias_a_per_m;
        if let Some(k) = lay.hrod {
            y[k] = h0;
        }
        if let Some(k) = lay.law {
            y[k] = if demag { 0.0 } else { ja_anhysteretic(&p.ja, h0) };
        }
        let mem = self.ev.as_ref().map(|ev| {
            if demag {
                let mut m = Memory::ac_demagnetised(ev, 0.0, PREISACH_DEMAG_REVERSALS);
                m.commit(ev, h0, if h0 >= 0.0 { 1.0 } else { -1.0 });
                m
            } else {
                Memory::ac_demagnetised(ev, h0, PREISACH_DEMAG_REVERSALS)
            }
        });
        let mut d = Disc { delta: 1.0, mem, h_ext: h0 };
        let o = self.eval(sig, t, &y, None, &d);
        if o.field_rate < 0.0 {
            d.delta = -1.0;
        }
        let o = self.eval(sig, t, &y, None, &d);
        if let Some(k) = lay.mslow {
            y[k] = o.m_law;
        }
        let o = self.eval(sig, t, &y, None, &d);
        if let Some(k) = lay.mech {
            // At rest at the free displacement (README, "Start states"): `o.y` is the mechanics'
            // own state here, still 0, which started every `mech` record with a step.
            y[k] = o.y_free;
            y[k + 1] = 0.0;
        }
        (y, d)
    }

    fn commit(&self, d: &mut Disc, hrod: f64) {
        if let (Some(ev), Some(m)) = (self.ev.as_ref(), d.mem.as_mut()) {
            m.commit(ev, hrod, d.delta);
        }
    }
}

/// Integrate one segment [t0, t1] of the plant under `sig` (evaluated at t − sig_t0), calling
/// `out(tag, t, obs)` at each query time (sorted) as the integration passes it.
#[allow(clippy::too_many_arguments)]
fn run_segment(
    plant: &Plant,
    sig: &Signal,
    sig_t0: f64,
    t0: f64,
    t1: f64,
    y: &mut [f64],
    disc: &mut Disc,
    queries: &[(f64, usize)],
    out: &mut dyn FnMut(usize, f64, &Obs),
    opts: &SolverOptions,
    stats: &mut SolverStats,
) -> Result<(), RigError> {
    let n = plant.lay.n;
    let atol: Vec<f64> = plant.scale.iter().map(|s| s * opts.rtol * opts.atol_factor).collect();
    let mut dp = solver::Dopri::new(n);
    let mut rhs_count = 0usize;
    let mut q = 0usize;
    // Queries at (or before) the start.
    while q < queries.len() && queries[q].0 <= t0 {
        let o = plant.eval(sig, t0 - sig_t0, y, None, disc);
        out(queries[q].1, queries[q].0, &o);
        q += 1;
    }
    let mut breaks: Vec<f64> = sig.breaks(t0 - sig_t0, t1 - sig_t0).into_iter().map(|b| b + sig_t0).collect();
    breaks.push(t1);
    let mut bi = 0usize;
    let mut t = t0;
    let mut k1 = vec![0.0; n];
    let eps_h = (10.0 * opts.rtol).max(1e-13)
        * (plant.p.coil.turns_per_m * plant.p.rig.current_limit_a + plant.p.coil.bias_a_per_m.abs());
    // The rate of a field at rest is interpolation noise amplified by the fastest lag in
    // front of the field; a reversed rate above this floor is a reversal at once.
    let pp = &plant.p;
    let mut tau_fast: f64 = 1e-3;
    if plant.fx.amp {
        tau_fast = tau_fast.min(pp.amp.tau_s);
        if let Some(a2) = &pp.amp_second_order {
            tau_fast = tau_fast.min(a2.b_s2.sqrt());
        }
    } else if pp.rig.current_loop_tau_s > 0.0 {
        tau_fast = tau_fast.min(pp.rig.current_loop_tau_s);
    }
    if plant.fx.eddy {
        tau_fast = tau_fast.min(pp.eddy_tau_s);
    }
    let g_noise = eps_h / tau_fast;
    let hyst = plant.hysteretic();
    let mut h = (t1 - t0).min(1e-6);
    let hmax = (t1 - t0).max(1e-12);
    let mut rejected_last = false;
    let mut need_k1 = true;
    let mut dense_y = vec![0.0; n];
    let mut guard = 0u64;
    while t < t1 {
        guard += 1;
        if guard > 2_000_000_000 {
            return Err(RigError::Solver("too many steps".into()));
        }
        if need_k1 {
            let d = &*disc;
            let f = |tt: f64, yy: &[f64], dd: &mut [f64]| {
                plant.eval(sig, tt - sig_t0, yy, Some(dd), d);
            };
            f(t, y, &mut k1);
            rhs_count += 1;
            need_k1 = false;
        }
        while bi < breaks.len() && breaks[bi] <= t {
            bi += 1;
        }
        let stop = breaks[bi.min(breaks.len() - 1)];
        let mut hs = h.min(hmax);
        let mut landing = false;
        if t + hs >= stop - 1e-13 * stop.abs().max(1e-9) || t + 1.01 * hs > stop {
            hs = stop - t;
            landing = true;
        }
        if hs <= 1e-15 * t.abs().max(1e-9) {
            if landing {
                t = stop;
                need_k1 = true;
                continue;
            }
            return Err(RigError::Solver(format!("step size underflow at t = {t}")));
        }
        let err = {
            let d = &*disc;
            let mut f = |tt: f64, yy: &[f64], dd: &mut [f64]| {
                plant.eval(sig, tt - sig_t0, yy, Some(dd), d);
            };
            dp.try_step(&mut f, t, y, &k1, hs, &atol, opts.rtol)
        };
        rhs_count += 6;
        if !(err <= 1.0) {
            stats.rejected += 1;
            h = hs * if err.is_finite() { solver::step_factor(err, true) } else { 0.2 };
            rejected_last = true;
            continue;
        }
        let mut step = dp.dense(t, y, hs);
        let mut event = false;
        if hyst {
            // A reversal: the field has retreated from its running extreme by more than
            // eps_h (far above the dense output's error, so a field at rest, whose computed
            // rate is only interpolation noise, never reverses), or its rate has turned above the
            // noise floor g_noise. The reversal itself is then
            // located as the zero of the field's rate and the step retaken to end there.
            let delta = disc.delta;
            let mut probe = |tt: f64| {
                step.eval(tt, &mut dense_y);
                rhs_count += 1;
                let o = plant.eval(sig, tt - sig_t0, &dense_y, None, disc);
                (o.hrod, o.field_rate * delta)
            };
            let tm = t + 0.5 * hs;
            let (hm_, sm) = probe(tm);
            let (he_, se) = probe(t + hs);
            let ext_m = if delta * (hm_ - disc.h_ext) > 0.0 { hm_ } else { disc.h_ext };
            let bracket = if delta * (hm_ - disc.h_ext) < -eps_h || sm < -g_noise {
                Some(tm)
            } else if delta * (he_ - ext_m) < -eps_h || se < -g_noise {
                Some(t + hs)
            } else {
                None
            };
            if let Some(tr) = bracket {
                let (_, r0) = probe(t);
                let te = if r0 <= 0.0 {
                    t
                } else {
                    let (mut lo, mut hi) = (t, tr);
                    for _ in 0..200 {
                        if hi - lo <= 1e-15 * hi.abs().max(1e-9) {
                            break;
                        }
                        let mid = 0.5 * (lo + hi);
                        if probe(mid).1 < 0.0 {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    hi
                };
                let he = te - t;
                if he <= 1e-14 * t.abs().max(1e-9) {
                    // The reversal is at t itself: switch and retry.
                    let o = plant.eval(sig, t - sig_t0, y, None, disc);
                    plant.commit(disc, o.hrod);
                    disc.delta = -disc.delta;
                    disc.h_ext = o.hrod;
                    stats.events += 1;
                    need_k1 = true;
                    continue;
                }
                let err2 = {
                    let d = &*disc;
                    let mut f = |tt: f64, yy: &[f64], dd: &mut [f64]| {
                        plant.eval(sig, tt - sig_t0, yy, Some(dd), d);
                    };
                    dp.try_step(&mut f, t, y, &k1, he, &atol, opts.rtol)
                };
                rhs_count += 6;
                if !(err2 <= 1.0) {
                    stats.rejected += 1;
                    h = he * 0.5;
                    continue;
                }
                hs = he;
                step = dp.dense(t, y, hs);
                event = true;
                landing = false;
            } else {
                disc.h_ext = if delta * (he_ - ext_m) > 0.0 { he_ } else { ext_m };
            }
        }
        // Accepted step [t, t + hs].
        stats.accepted += 1;
        let tn = if landing { stop } else { t + hs };
        while q < queries.len() && queries[q].0 <= tn {
            let tq = queries[q].0;
            step.eval(tq.min(t + hs), &mut dense_y);
            let o = plant.eval(sig, tq - sig_t0, &dense_y, None, disc);
            out(queries[q].1, tq, &o);
            q += 1;
        }
        y.copy_from_slice(&dp.y1);
        k1.copy_from_slice(&dp.k7);
        if hyst {
            let o = plant.eval(sig, tn - sig_t0, y, None, disc);
            if !o.m_law.is_finite() {
                return Err(RigError::Solver(format!("non-finite magnetization at t = {tn}")));
            }
            plant.commit(disc, o.hrod);
            if event {
                disc.delta = -disc.delta;
                disc.h_ext = o.hrod;
                stats.events += 1;
                need_k1 = true;
            }
        }
        if y.iter().any(|v| !v.is_finite()) {
            return Err(RigError::Solver(format!("non-finite state at t = {tn}")));
        }
        t = tn;
        if landing {
            need_k1 = true;
        }
        h = hs * solver::step_factor(err, rejected_last);
        rejected_last = false;
    }
    stats.rhs_evals += rhs_count;
    Ok(())
}

fn check(ok: bool, what: &str) -> Result<(), RigError> {
    if ok {
        Ok(())
    } else {
        Err(RigError::BadParameter(what.to_string()))
    }
}

/// Range checks of the parameters the structure uses (docs/formats.md "Keys").
pub fn validate(fx: &Effects, p: &Params) -> Result<(), RigError> {
    check(p.dt_s >= 1e-7 && p.dt_s <= 10.0, "dt_s must be in [1e-7, 10] s")?;
    check(p.rod_length_m >= 1e-4 && p.rod_length_m <= 10.0, "rod_length_m must be in [1e-4, 10] m")?;
    check(p.coil.turns_per_m >= 1.0 && p.coil.turns_per_m <= 1e7, "coil.turns_per_m must be in [1, 1e7]")?;
    check(p.coil.bias_a_per_m.abs() <= 1e7, "coil.bias_a_per_m must be within ±1e7")?;
    check(p.rig.current_limit_a > 0.0, "rig.current_limit_a must be > 0")?;
    check(p.rig.current_loop_tau_s >= 0.0, "rig.current_loop_tau_s must be >= 0")?;
    let ms = &p.magnetostriction;
    check(ms.lambda_s >= 1e-9 && ms.lambda_s <= 1.0, "magnetostriction.lambda_s must be in [1e-9, 1]")?;
    check(ms.ms_a_per_m >= 1e3 && ms.ms_a_per_m <= 1e7, "magnetostriction.ms_a_per_m must be in [1e3, 1e7]")?;
    check(ms.bias_m_a_per_m.abs() < ms.ms_a_per_m, "magnetostriction.bias_m_a_per_m: |M_b| < M_s")?;
    if let Some(pl) = &ms.preload {
        check(
            pl.force_n >= 0.0 && pl.optimal_force_n > 0.0 && pl.max_force_n > 0.0,
            "magnetostriction.preload: F >= 0, F_s > 0, F_max > 0",
        )?;
        check(pl.factor() >= 0.01, "magnetostriction.preload: strain factor below 0.01")?;
    }
    if fx.amp {
        if let Some(a) = &p.amp_second_order {
            check(a.k_u > 0.0 && a.k_u <= 1e3, "amp2.k_u must be in (0, 1e3]")?;
            check(a.a_s >= 0.0 && a.b_s2 > 0.0 && a.c_s >= 0.0, "amp2: a_s >= 0, b_s2 > 0, c_s >= 0")?;
        } else {
            check(
                p.amp.gain_a_per_v > 0.0 && p.amp.gain_a_per_v <= 1e3,
                "amp.gain_a_per_v must be in (0, 1e3]",
            )?;
            check(p.amp.tau_s > 0.0, "amp.tau_s must be > 0")?;
        }
    }
    if fx.eddy {
        check(p.eddy_tau_s > 0.0, "eddy_tau_s must be > 0")?;
    }
    match fx.law {
        Law::Linear => check(
            p.linear.susceptibility >= 1e-3
                && p.linear.susceptibility <= 1e5
                && p.linear.offset_a_per_m.abs() <= 1e7,
            "linear: susceptibility in [1e-3, 1e5], |offset| <= 1e7",
        )?,
        Law::Langevin => check(
            p.anhysteretic.ms_a_per_m >= 1e3
                && p.anhysteretic.ms_a_per_m <= 1e7
                && p.anhysteretic.a_a_per_m >= 1.0
                && p.anhysteretic.a_a_per_m <= 1e7,
            "anhysteretic: ms in [1e3, 1e7], a in [1, 1e7]",
        )?,
        Law::JilesAtherton => {
            let j = &p.ja;
            check(j.ms_a_per_m >= 1e3 && j.ms_a_per_m <= 1e7, "ja.ms_a_per_m must be in [1e3, 1e7]")?;
            check(j.a_a_per_m >= 1.0 && j.a_a_per_m <= 1e7, "ja.a_a_per_m must be in [1, 1e7]")?;
            check(j.k_a_per_m >= 1.0 && j.k_a_per_m <= 1e7, "ja.k_a_per_m must be in [1, 1e7]")?;
            check(j.alpha > -1.0 && j.alpha < 1.0, "ja.alpha must be in (-1, 1)")?;
            check(j.c >= 0.0 && j.c < 1.0, "ja.c must be in [0, 1)")?;
            check(j.alpha * j.ms_a_per_m / (3.0 * j.a_a_per_m) < 1.0, "ja: alpha*M_s/(3a) must be < 1")?;
        }
        Law::Preisach => {
            let q = &p.preisach;
            check(q.ms_a_per_m >= 1e3 && q.ms_a_per_m <= 1e7, "preisach.ms_a_per_m must be in [1e3, 1e7]")?;
            check(
                q.coercive_a_per_m >= 1.0 && q.coercive_a_per_m < q.h_max_a_per_m,
                "preisach.coercive_a_per_m must be in [1, h_max)",
            )?;
            check(
                q.spread_a_per_m >= 1.0 && q.spread_a_per_m <= 1e7,
                "preisach.spread_a_per_m must be in [1, 1e7]",
            )?;
            check(
                q.interaction_spread_a_per_m.is_none_or(|v| (1.0..=1e7).contains(&v)),
                "preisach.interaction_spread_a_per_m must be in [1, 1e7]",
            )?;
            check(
                q.reversible_fraction >= 0.0 && q.reversible_fraction < 0.95,
                "preisach.reversible_fraction must be in [0, 0.95)",
            )?;
            check(q.reversible_field() >= 1.0, "preisach.reversible_field_a_per_m must be >= 1")?;
            check(
                q.h_max_a_per_m >= 1.0 && q.h_max_a_per_m <= 1e7,
                "preisach.h_max_a_per_m must be in [1, 1e7]",
            )?;
        }
    }
    if fx.aftereffect {
        check(
            p.aftereffect.fraction >= 0.0 && p.aftereffect.fraction < 1.0,
            "aftereffect.fraction must be in [0, 1)",
        )?;
        check(p.aftereffect.tau_s > 0.0, "aftereffect.tau_s must be > 0")?;
    }
    if fx.mech {
        check(
            p.mech.natural_frequency_hz >= 1e-6 && p.mech.natural_frequency_hz <= 1e9,
            "mech.natural_frequency_hz must be in [1e-6, 1e9]",
        )?;
        check(
            p.mech.damping_ratio >= 1e-3 && p.mech.damping_ratio <= 1e3,
            "mech.damping_ratio must be in [1e-3, 1e3]",
        )?;
    }
    if fx.thermal {
        let t = &p.thermal;
        check(
            t.coil_resistance_ohm >= 0.0 && t.thermal_resistance_c_per_w >= 0.0,
            "thermal: resistances >= 0",
        )?;
        check(t.tau_s > 0.0 && t.rod_tau_s >= 0.0, "thermal: tau_s > 0, rod_tau_s >= 0")?;
        check(
            t.rod_length_m >= 1e-4 && t.expansion_per_c >= 0.0 && t.expansion_per_c <= 1e-3,
            "thermal: rod_length_m >= 1e-4, expansion_per_c in [0, 1e-3]",
        )?;
    }
    if fx.delay {
        check(p.delay_samples >= 0.0 && p.delay_samples < 64.0, "delay_samples must be in [0, 64)")?;
    }
    Ok(())
}

/// Simulate an experiment with the default solver settings (rtol 1e-9).
pub fn simulate(e: &Experiment) -> Result<Recording, RigError> {
    simulate_with(e, &SolverOptions::default())
}

/// Simulate an experiment with the given solver settings.
pub fn simulate_with(e: &Experiment, opts: &SolverOptions) -> Result<Recording, RigError> {
    let clock = std::time::Instant::now();
    let fx = Effects::parse(&e.structure)?;
    validate(&fx, &e.params)?;
    check(e.rate_hz > 0.0 && e.rate_hz.is_finite(), "rate_hz must be > 0")?;
    check(e.duration_s > 0.0 && e.duration_s.is_finite(), "duration_s must be > 0")?;
    check(opts.rtol > 0.0 && opts.atol_factor > 0.0, "solver tolerances must be > 0")?;
    let ns = (e.duration_s * e.rate_hz).round() as usize;
    check(ns >= 3, "the recording needs at least 3 samples")?;
    for (v, what) in [
        (e.noise.current_lsb_rms, "noise.current_lsb_rms"),
        (e.noise.displacement_um_rms, "noise.displacement_um_rms"),
        (e.noise.flux_t_rms, "noise.flux_t_rms"),
        (e.noise.temperature_c_rms, "noise.temperature_c_rms"),
    ] {
        check(v >= 0.0 && v.is_finite(), &format!("{what} must be >= 0"))?;
    }
    let plant = Plant::new(fx.clone(), e.params.clone());
    let sig = Signal::new(&e.drive, e.duration_s, e.seed)?;
    let delay_s = if fx.delay { e.params.delay_samples * e.params.dt_s } else { 0.0 };
    let times: Vec<f64> = (0..ns).map(|k| k as f64 / e.rate_hz).collect();
    let mut stats = SolverStats::default();
    let mut obs = vec![Obs::default(); ns];
    let mut ydel = vec![f64::NAN; ns];
    // Delayed queries before t = 0.
    let neg: Vec<(f64, usize)> = times
        .iter()
        .enumerate()
        .filter(|(_, t)| delay_s > 0.0 && **t - delay_s < 0.0)
        .map(|(k, t)| (*t - delay_s, k))
        .collect();
    let (mut y, mut disc) = match &e.start {
        Start::Demagnetised | Start::Anhysteretic => {
            let (y, d) = plant.initial(&sig, 0.0, e.start == Start::Demagnetised);
            let y0 = plant.eval(&sig, 0.0, &y, None, &d).y;
            for (_, k) in &neg {
                ydel[*k] = y0;
            }
            (y, d)
        }
        Start::History { drive, duration_s } => {
            check(*duration_s > 0.0 && duration_s.is_finite(), "history duration must be > 0")?;
            let hsig = Signal::new(drive, *duration_s, e.seed)?;
            let th = *duration_s;
            let (mut y, mut d) = plant.initial(&hsig, 0.0, true);
            let mut qs: Vec<(f64, usize)> = neg.iter().filter(|(t, _)| *t >= -th).cloned().collect();
            let y_early = plant.eval(&hsig, 0.0, &y, None, &d).y;
            for (t, k) in &neg {
                if *t < -th {
                    ydel[*k] = y_early;
                }
            }
            qs.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut sink = |k: usize, _t: f64, o: &Obs| ydel[k] = o.y;
            run_segment(&plant, &hsig, -th, -th, 0.0, &mut y, &mut d, &qs, &mut sink, opts, &mut stats)?;
            // The direction of the field under the new drive.
            let o = plant.eval(&sig, 0.0, &y, None, &d);
            let nd = if o.field_rate > 1e-9 * e.params.coil.turns_per_m {
                1.0
            } else if o.field_rate < -1e-9 * e.params.coil.turns_per_m {
                -1.0
            } else {
                d.delta
            };
            if nd != d.delta {
                plant.commit(&mut d, o.hrod);
                d.delta = nd;
                d.h_ext = o.hrod;
            }
            (y, d)
        }
    };
    // Queries of the logged segment: tag k = sample k, tag ns + k = delayed sample k.
    let mut qs: Vec<(f64, usize)> = times.iter().enumerate().map(|(k, t)| (*t, k)).collect();
    if delay_s > 0.0 {
        qs.extend(
            times
                .iter()
                .enumerate()
                .filter(|(_, t)| **t - delay_s >= 0.0)
                .map(|(k, t)| (*t - delay_s, ns + k)),
        );
    }
    qs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let t_end = times[ns - 1];
    {
        let mut sink = |tag: usize, _t: f64, o: &Obs| {
            if tag < ns {
                obs[tag] = *o;
            } else {
                ydel[tag - ns] = o.y;
            }
        };
        run_segment(&plant, &sig, 0.0, 0.0, t_end, &mut y, &mut disc, &qs, &mut sink, opts, &mut stats)?;
    }
    let y_meas: Vec<f64> = if delay_s > 0.0 { ydel.clone() } else { obs.iter().map(|o| o.y).collect() };
    let truth = Truth {
        current_a: obs.iter().map(|o| o.i).collect(),
        displacement_um: y_meas.clone(),
        field_a_per_m: obs.iter().map(|o| o.hrod).collect(),
        magnetization_a_per_m: obs.iter().map(|o| o.m_obs).collect(),
        coil_field_a_per_m: obs.iter().map(|o| o.h).collect(),
        law_magnetization_a_per_m: obs.iter().map(|o| o.m_law).collect(),
        undelayed_displacement_um: obs.iter().map(|o| o.y).collect(),
        flux_density_t: obs.iter().map(|o| MU0 * (o.hrod + o.m_obs)).collect(),
        temperature_c: obs.iter().map(|o| e.params.rig.ambient_c + o.theta).collect(),
    };
    // Noise: one ChaCha20 stream per channel, so a channel's noise does not depend on which
    // other channels are logged.
    let noisy = |x: &[f64], sd: f64, stream: u64| -> Vec<f64> {
        let mut rng = ChaCha20Rng::seed_from_u64(e.seed);
        rng.set_stream(stream);
        if sd > 0.0 {
            let nd = Normal::new(0.0, sd).expect("sd > 0");
            x.iter().map(|v| v + nd.sample(&mut rng)).collect()
        } else {
            x.to_vec()
        }
    };
    let mut current = noisy(&truth.current_a, e.noise.current_lsb_rms * CURRENT_LSB_A, 1);
    if e.noise.quantise_current {
        for c in current.iter_mut() {
            let code = (*c / CURRENT_LSB_A).round().clamp(-2048.0, 2047.0);
            *c = code * CURRENT_LSB_A;
        }
    }
    let displacement = noisy(&truth.displacement_um, e.noise.displacement_um_rms, 2);
    let flux = e.log_flux.then(|| noisy(&truth.flux_density_t, e.noise.flux_t_rms, 3));
    let temperature = e.log_temperature.then(|| noisy(&truth.temperature_c, e.noise.temperature_c_rms, 4));
    let command = fx.amp.then(|| obs.iter().map(|o| o.u).collect());
    stats.seconds = clock.elapsed().as_secs_f64();
    Ok(Recording {
        time_s: times,
        command_v: command,
        current_a: current,
        displacement_um: displacement,
        flux_density_t: flux,
        temperature_c: temperature,
        truth,
        stats,
    })
}
