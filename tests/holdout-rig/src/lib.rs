//! `holdout`: a held-out simulated Terfenol-D actuator rig (SIMULATED data).
//!
//! Written from textbooks and papers only, without reading the workbench's model code, so that a
//! fit by `gma` on its recordings tests the workbench and not a simulator agreeing with itself.
//! It is deliberately unlike the project's models and unlike `tests/reference-rig`: see README.md
//! for the equations, their sources and the differences.
//!
//! Chain: command u [V] → voltage amplifier (lag, rail) → coil L di/dt = v − R(T) i (current
//! limit) → surface field H_s = n i + H_bias → two-branch eddy ladder → rod field H →
//! magnetization law (Coleman–Hodgdon with a tanh anhysteretic, or Preisach with a Lorentzian
//! relay density) → logarithmic aftereffect → quartic magnetostriction + thermal expansion →
//! rod with a tip load (first two longitudinal modes) → sensor (delay, noise, quantisation,
//! offset).

use std::f64::consts::PI;
use std::io::{self, Write};

/// Temperature coefficient of copper's resistance near 20 °C.
const COPPER_TEMPERATURE_COEFFICIENT_PER_C: f64 = 0.0039;
/// Integration substeps per recorded sample (fixed-step RK4 on each stage).
const SUBSTEPS: usize = 8;
/// Relaxation times of the aftereffect, log-uniform over this range [s] (a flat spectrum in
/// ln τ gives creep ∝ ln t between its ends).
const CREEP_TAU_RANGE_S: (f64, f64) = (2e-3, 2.0);
const CREEP_TERMS: usize = 6;

/// The magnetization law of the rod.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// Coleman–Hodgdon (Duhem) law with anhysteretic M_s tanh(H/a).
    ColemanHodgdon,
    /// Preisach relays with a factorised Lorentzian density, plus a reversible arctan part.
    LorentzPreisach,
}

impl Law {
    /// Short name used in file names and tables.
    pub fn name(self) -> &'static str {
        match self {
            Law::ColemanHodgdon => "coleman-hodgdon",
            Law::LorentzPreisach => "lorentz-preisach",
        }
    }
}

/// One switch per effect, so a suite can hide one effect at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    /// Saturating law; off: the law's tangent at the bias (a linear rod).
    pub saturation: bool,
    /// Hysteresis; off: the law's own anhysteretic curve.
    pub hysteresis: bool,
    /// Two-branch eddy ladder; off: the rod sees the surface field at once.
    pub eddy_current: bool,
    /// Rod modes and load; off: displacement = free strain × length.
    pub mechanical_dynamics: bool,
    /// Voltage amplifier + RL coil + current limit; off: ideal current source i = g·u.
    pub amplifier_dynamics: bool,
    /// Logarithmic magnetic aftereffect.
    pub magnetic_aftereffect: bool,
    /// Coil heating R(T) i², rod temperature, thermal expansion (and R(T) in the coil).
    pub thermal_drift: bool,
    /// Transport delay of the displacement sensor.
    pub sensor_delay: bool,
    /// Sensor noise, quantisation and offsets.
    pub sensor_noise: bool,
    /// Start from a remanent state after a field pre-history (off: demagnetised at the bias).
    pub premagnetised: bool,
}

impl Effects {
    /// Every effect on.
    pub const ALL: Effects = Effects {
        saturation: true,
        hysteresis: true,
        eddy_current: true,
        mechanical_dynamics: true,
        amplifier_dynamics: true,
        magnetic_aftereffect: true,
        thermal_drift: true,
        sensor_delay: true,
        sensor_noise: true,
        premagnetised: true,
    };
    /// Every effect off (a static, linear, noise-free rod driven by an ideal current source).
    pub const NONE: Effects = Effects {
        saturation: false,
        hysteresis: false,
        eddy_current: false,
        mechanical_dynamics: false,
        amplifier_dynamics: false,
        magnetic_aftereffect: false,
        thermal_drift: false,
        sensor_delay: false,
        sensor_noise: false,
        premagnetised: false,
    };
}

/// Command waveform (the amplifier input, volts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Waveform {
    /// offset + amplitude·sin 2πft.
    Sine,
    /// Symmetric triangle.
    Triangle,
    /// Square wave (the amplifier and coil shape its edges).
    Square,
    /// Linear chirp from `freq_hz` to `f_end_hz`.
    Chirp,
    /// Tones at `freq_hz`·k for k = 1…n up to `f_end_hz`, Schroeder phases, peak scaled to amplitude.
    Multisine,
    /// Sine at `freq_hz` with its amplitude ramped from 0 (nested minor loops).
    Sweep,
}

/// The drive of one recording.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// Waveform of the command.
    pub waveform: Waveform,
    /// Amplitude [V].
    pub amplitude_v: f64,
    /// DC offset of the command [V].
    pub offset_v: f64,
    /// Frequency [Hz] (start of a chirp, fundamental of a multisine).
    pub freq_hz: f64,
    /// End frequency of a chirp, top of a multisine [Hz].
    pub f_end_hz: f64,
    /// Duration [s].
    pub duration_s: f64,
}

impl Drive {
    /// A sine drive.
    pub fn sine(amplitude_v: f64, freq_hz: f64, duration_s: f64) -> Drive {
        Drive { waveform: Waveform::Sine, amplitude_v, offset_v: 0.0, freq_hz, f_end_hz: freq_hz, duration_s }
    }

    /// Command at time t [V].
    pub fn command_v(&self, t: f64) -> f64 {
        let f = self.freq_hz;
        let a = self.amplitude_v;
        let wave = match self.waveform {
            Waveform::Sine => (2.0 * PI * f * t).sin(),
            Waveform::Triangle => {
                let phase = (f * t + 0.25).rem_euclid(1.0);
                if phase < 0.5 {
                    4.0 * phase - 1.0
                } else {
                    3.0 - 4.0 * phase
                }
            }
            Waveform::Square => {
                if (f * t).rem_euclid(1.0) < 0.5 {
                    1.0
                } else {
                    -1.0
                }
            }
            Waveform::Chirp => {
                let rate = (self.f_end_hz - f) / self.duration_s;
                (2.0 * PI * (f * t + 0.5 * rate * t * t)).sin()
            }
            Waveform::Multisine => {
                let tones = self.multisine_tones();
                let n = tones as f64;
                let mut sum = 0.0;
                for k in 1..=tones {
                    let kf = k as f64;
                    // Schroeder phases keep the crest factor low.
                    sum += (2.0 * PI * f * kf * t - PI * kf * (kf - 1.0) / n).sin();
                }
                // A Schroeder multisine of n equal tones peaks near 1.5·√(n/2); scaled to ≈ 1.
                sum / (1.5 * (n / 2.0).sqrt()).max(1.0)
            }
            Waveform::Sweep => (t / self.duration_s).min(1.0) * (2.0 * PI * f * t).sin(),
        };
        self.offset_v + a * wave
    }

    fn multisine_tones(&self) -> usize {
        ((self.f_end_hz / self.freq_hz).floor() as usize).clamp(1, 64)
    }
}

/// Every parameter of the rig. `Rig::default()` is the documented set (README.md).
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// Magnetization law.
    pub law: Law,
    /// Effect switches.
    pub effects: Effects,
    /// Sample rate of the recording [Hz].
    pub sample_rate_hz: f64,
    /// Noise seed.
    pub seed: u64,
    /// Amplifier voltage gain [V/V].
    pub amp_gain_v_per_v: f64,
    /// Amplifier output lag [s].
    pub amp_tau_s: f64,
    /// Amplifier output rail [V].
    pub amp_rail_v: f64,
    /// Amplifier current limit [A].
    pub current_limit_a: f64,
    /// Ideal current-source gain when the amplifier dynamics are off [A/V].
    pub ideal_gain_a_per_v: f64,
    /// Coil inductance [H].
    pub coil_inductance_h: f64,
    /// Coil resistance at the ambient temperature [Ω].
    pub coil_resistance_ohm: f64,
    /// Coil field per ampere [1/m].
    pub turns_per_m: f64,
    /// Bias field of the permanent magnet [A/m].
    pub bias_a_per_m: f64,
    /// Eddy ladder: surface → outer shell time constant [s].
    pub eddy_outer_tau_s: f64,
    /// Eddy ladder: outer shell → core time constant [s].
    pub eddy_core_tau_s: f64,
    /// Saturation magnetization [A/m].
    pub ms_a_per_m: f64,
    /// Coleman–Hodgdon anhysteretic width a in M_s tanh(H/a) [A/m].
    pub ch_a_a_per_m: f64,
    /// Coleman–Hodgdon α [m/A]: rate at which a branch approaches the anhysteretic.
    pub ch_alpha_per_a_per_m: f64,
    /// Coleman–Hodgdon reversible share β of the anhysteretic slope.
    pub ch_beta: f64,
    /// Preisach: centre ±h_c of the Lorentzian switching fields [A/m].
    pub preisach_coercive_a_per_m: f64,
    /// Preisach: half width of the Lorentzian switching fields [A/m].
    pub preisach_width_a_per_m: f64,
    /// Preisach: relay plane ±H_max [A/m].
    pub preisach_h_max_a_per_m: f64,
    /// Preisach: reversible share ρ.
    pub preisach_reversible_share: f64,
    /// Preisach: reversible part width [A/m].
    pub preisach_reversible_width_a_per_m: f64,
    /// Aftereffect: share w of every change of M that arrives late.
    pub creep_share: f64,
    /// Saturation magnetostriction λ_s.
    pub lambda_s: f64,
    /// Quartic share κ of the magnetostriction curve.
    pub lambda_quartic_share: f64,
    /// Rod length [m].
    pub rod_length_m: f64,
    /// Rod radius [m].
    pub rod_radius_m: f64,
    /// Rod Young's modulus at constant field [Pa].
    pub rod_young_pa: f64,
    /// Rod density [kg/m³].
    pub rod_density_kg_per_m3: f64,
    /// Tip load mass [kg].
    pub load_mass_kg: f64,
    /// Damping ratio of the first and second longitudinal modes.
    pub mode_damping: [f64; 2],
    /// Ambient (and initial) temperature [°C].
    pub ambient_c: f64,
    /// Coil heat capacity [J/°C].
    pub coil_heat_capacity_j_per_c: f64,
    /// Coil-to-ambient thermal resistance [°C/W].
    pub coil_thermal_resistance_c_per_w: f64,
    /// Rod temperature lag behind the coil [s].
    pub rod_thermal_tau_s: f64,
    /// Rod thermal expansion [1/°C].
    pub expansion_per_c: f64,
    /// Displacement sensor delay [samples].
    pub delay_samples: usize,
    /// Displacement noise, standard deviation [µm].
    pub noise_um: f64,
    /// Displacement quantisation step [µm].
    pub quantum_um: f64,
    /// Displacement sensor offset [µm].
    pub offset_um: f64,
    /// Current noise, standard deviation [A].
    pub current_noise_a: f64,
    /// Current quantisation step [A].
    pub current_quantum_a: f64,
}

impl Default for Rig {
    fn default() -> Rig {
        Rig {
            law: Law::ColemanHodgdon,
            effects: Effects::ALL,
            sample_rate_hz: 10_000.0,
            seed: 1,
            amp_gain_v_per_v: 6.0,
            amp_tau_s: 60e-6,
            amp_rail_v: 30.0,
            current_limit_a: 2.5,
            ideal_gain_a_per_v: 1.2,
            coil_inductance_h: 2e-3,
            coil_resistance_ohm: 5.0,
            turns_per_m: 10_000.0,
            bias_a_per_m: 18_000.0,
            eddy_outer_tau_s: 80e-6,
            eddy_core_tau_s: 250e-6,
            ms_a_per_m: 7.65e5,
            ch_a_a_per_m: 25_000.0,
            ch_alpha_per_a_per_m: 2.5e-4,
            ch_beta: 0.35,
            preisach_coercive_a_per_m: 5_000.0,
            preisach_width_a_per_m: 9_000.0,
            preisach_h_max_a_per_m: 150_000.0,
            preisach_reversible_share: 0.2,
            preisach_reversible_width_a_per_m: 30_000.0,
            creep_share: 0.08,
            lambda_s: 1.0e-3,
            lambda_quartic_share: 0.3,
            rod_length_m: 0.06,
            rod_radius_m: 5e-3,
            rod_young_pa: 30e9,
            rod_density_kg_per_m3: 9250.0,
            load_mass_kg: 0.6,
            mode_damping: [0.06, 0.02],
            ambient_c: 22.0,
            coil_heat_capacity_j_per_c: 0.5,
            coil_thermal_resistance_c_per_w: 4.0,
            rod_thermal_tau_s: 0.3,
            expansion_per_c: 12e-6,
            delay_samples: 2,
            noise_um: 0.01,
            quantum_um: 0.005,
            offset_um: 15.0,
            current_noise_a: 1e-3,
            current_quantum_a: 5e-4,
        }
    }
}

/// One recording: the measured channels (what the CSV holds) and the true ones.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recording {
    /// Sample times [s].
    pub time_s: Vec<f64>,
    /// Amplifier command [V].
    pub command_v: Vec<f64>,
    /// Measured coil current [A].
    pub current_a: Vec<f64>,
    /// Measured displacement [µm].
    pub displacement_um: Vec<f64>,
    /// Measured coil temperature [°C].
    pub temperature_c: Vec<f64>,
    /// True coil current [A].
    pub true_current_a: Vec<f64>,
    /// True mean rod field [A/m].
    pub rod_field_a_per_m: Vec<f64>,
    /// True rod magnetization (before the aftereffect) [A/m].
    pub magnetization_a_per_m: Vec<f64>,
    /// True tip displacement [µm].
    pub true_displacement_um: Vec<f64>,
}

impl Recording {
    /// Writes the measurement CSV of docs/formats.md.
    pub fn write_csv<W: Write>(&self, mut w: W) -> io::Result<()> {
        writeln!(w, "time_s,command_V,current_A,displacement_um,temperature_C")?;
        for k in 0..self.time_s.len() {
            writeln!(
                w,
                "{:.7},{},{},{},{}",
                self.time_s[k],
                self.command_v[k] as f32,
                self.current_a[k] as f32,
                self.displacement_um[k] as f32,
                self.temperature_c[k] as f32
            )?;
        }
        Ok(())
    }
}

/// Lorentzian density (1/π) w/((x − c)² + w²) and its antiderivative (1/π) atan((x − c)/w).
fn lorentz_cdf(x: f64, centre: f64, width: f64) -> f64 {
    ((x - centre) / width).atan() / PI
}

/// Preisach model with the factorised density μ(α, β) = g(α) g(−β) on α ≥ β, g a Lorentzian
/// centred at h_c (the density of up-switching fields; down-switching at −h_c), after
/// Mayergoyz (1991) and the Lorentzian distribution of Bertotti (1998, ch. 9).
#[derive(Clone, Debug)]
pub struct LorentzPreisach {
    hc: f64,
    width: f64,
    h_max: f64,
    /// I(x) = ∫_{−H_max}^{x} K(b) G(b) db on a uniform grid, for the Everett function.
    integral_table: Vec<f64>,
    total: f64,
    /// Alternating dominant extrema [M1, m1, M2, …, current input]; empty: negative saturation.
    extrema: Vec<f64>,
}

const EVERETT_TABLE_INTERVALS: usize = 8000;

impl LorentzPreisach {
    /// A relay plane over ±h_max, starting at negative saturation.
    pub fn new(hc: f64, width: f64, h_max: f64) -> LorentzPreisach {
        let n = EVERETT_TABLE_INTERVALS;
        let dx = 2.0 * h_max / n as f64;
        let integrand = |b: f64| {
            let k = (width / PI) / ((b + hc).powi(2) + width * width);
            k * lorentz_cdf(b, hc, width)
        };
        let mut table = Vec::with_capacity(n + 1);
        table.push(0.0);
        let mut acc = 0.0;
        for j in 0..n {
            let a = -h_max + j as f64 * dx;
            // Simpson on each interval: the table is exact to O(dx⁴).
            acc += dx / 6.0 * (integrand(a) + 4.0 * integrand(a + 0.5 * dx) + integrand(a + dx));
            table.push(acc);
        }
        let mut p =
            LorentzPreisach { hc, width, h_max, integral_table: table, total: 1.0, extrema: Vec::new() };
        p.total = p.everett(h_max, -h_max);
        p
    }

    fn integral(&self, x: f64) -> f64 {
        let n = EVERETT_TABLE_INTERVALS;
        let pos = ((x + self.h_max) / (2.0 * self.h_max) * n as f64).clamp(0.0, n as f64);
        let j = (pos.floor() as usize).min(n - 1);
        let frac = pos - j as f64;
        self.integral_table[j] * (1.0 - frac) + self.integral_table[j + 1] * frac
    }

    /// Everett function E(α, β): the relay weight in the triangle β ≤ b ≤ a ≤ α,
    /// E = G(α)(K(α) − K(β)) − (I(α) − I(β)) with G, K the Lorentzian CDFs of α and β.
    pub fn everett(&self, alpha: f64, beta: f64) -> f64 {
        if alpha <= beta {
            return 0.0;
        }
        let g_alpha = lorentz_cdf(alpha, self.hc, self.width);
        let k_cdf = |b: f64| lorentz_cdf(b, -self.hc, self.width);
        g_alpha * (k_cdf(alpha) - k_cdf(beta)) - (self.integral(alpha) - self.integral(beta))
    }

    /// Applies the input h (wiping-out rule) and returns the relay output y ∈ [−1, 1].
    pub fn apply(&mut self, h: f64) -> f64 {
        let u = h.clamp(-self.h_max, self.h_max);
        if u <= -self.h_max {
            self.extrema.clear();
        } else if self.extrema.is_empty() {
            self.extrema.push(u);
        } else {
            let n = self.extrema.len();
            let last_is_max = n % 2 == 1;
            let extends = if last_is_max { u >= self.extrema[n - 1] } else { u <= self.extrema[n - 1] };
            if extends {
                self.extrema[n - 1] = u;
            } else {
                self.extrema.push(u);
            }
            // Wiping out: the input passing an earlier extremum of its kind erases that pair.
            while self.extrema.len() >= 3 {
                let n = self.extrema.len();
                let current_is_max = n % 2 == 1;
                let previous = self.extrema[n - 3];
                let wipes = if current_is_max { u >= previous } else { u <= previous };
                if !wipes {
                    break;
                }
                self.extrema.drain(n - 3..n - 1);
            }
        }
        self.output()
    }

    /// Relay output y = 2P/P_total − 1 of the present memory.
    pub fn output(&self) -> f64 {
        let mut up = 0.0;
        let mut previous_min = -self.h_max;
        let mut current_max = -self.h_max;
        for (j, &x) in self.extrema.iter().enumerate() {
            if j % 2 == 0 {
                up += self.everett(x, previous_min);
                current_max = x;
            } else {
                up -= self.everett(current_max, x);
                previous_min = x;
            }
        }
        2.0 * up / self.total - 1.0
    }

    /// Mean of the ascending and descending major branches' shape, used as the law's
    /// anhysteretic: (2/π) atan(H/(h_c + w)).
    pub fn anhysteretic(&self, h: f64) -> f64 {
        2.0 / PI * (h / (self.hc + self.width)).atan()
    }
}

/// The magnetization stage: law + its memory.
#[derive(Clone, Debug)]
enum MagnetizationState {
    ColemanHodgdon { m: f64 },
    Preisach(Box<LorentzPreisach>),
}

struct Magnetization {
    effects: Effects,
    ms: f64,
    ch_a: f64,
    ch_alpha: f64,
    ch_beta: f64,
    rev_share: f64,
    rev_width: f64,
    bias: f64,
    state: MagnetizationState,
}

impl Magnetization {
    fn new(rig: &Rig) -> Magnetization {
        let state = match rig.law {
            Law::ColemanHodgdon => MagnetizationState::ColemanHodgdon { m: 0.0 },
            Law::LorentzPreisach => MagnetizationState::Preisach(Box::new(LorentzPreisach::new(
                rig.preisach_coercive_a_per_m,
                rig.preisach_width_a_per_m,
                rig.preisach_h_max_a_per_m,
            ))),
        };
        Magnetization {
            effects: rig.effects,
            ms: rig.ms_a_per_m,
            ch_a: rig.ch_a_a_per_m,
            ch_alpha: rig.ch_alpha_per_a_per_m,
            ch_beta: rig.ch_beta,
            rev_share: rig.preisach_reversible_share,
            rev_width: rig.preisach_reversible_width_a_per_m,
            bias: rig.bias_a_per_m,
            state,
        }
    }

    /// The law's anhysteretic M(H) [A/m].
    fn anhysteretic(&self, h: f64) -> f64 {
        match &self.state {
            MagnetizationState::ColemanHodgdon { .. } => self.ms * (h / self.ch_a).tanh(),
            MagnetizationState::Preisach(p) => {
                self.ms
                    * ((1.0 - self.rev_share) * p.anhysteretic(h)
                        + self.rev_share * 2.0 / PI * (h / self.rev_width).atan())
            }
        }
    }

    fn anhysteretic_slope(&self, h: f64) -> f64 {
        let dh = 1.0;
        (self.anhysteretic(h + dh) - self.anhysteretic(h - dh)) / (2.0 * dh)
    }

    /// Moves the rod field from h_old to h_new and returns M [A/m].
    fn step(&mut self, h_old: f64, h_new: f64) -> f64 {
        if !self.effects.saturation {
            // Linear rod: the law's tangent at the bias.
            return self.anhysteretic(self.bias) + self.anhysteretic_slope(self.bias) * (h_new - self.bias);
        }
        if !self.effects.hysteresis {
            return self.anhysteretic(h_new);
        }
        let (ms, a, alpha, beta) = (self.ms, self.ch_a, self.ch_alpha, self.ch_beta);
        let rev_share = self.rev_share;
        let rev_width = self.rev_width;
        match &mut self.state {
            MagnetizationState::ColemanHodgdon { m } => {
                // Rate-independent Duhem law: dM/dH = α sgn(dH)(f(H) − M) + β f'(H), integrated
                // along the field path with RK4 (exact in form for any rate).
                let dh = h_new - h_old;
                let sign = dh.signum();
                let f = |h: f64| ms * (h / a).tanh();
                let fp = |h: f64| ms / a / (h / a).cosh().powi(2);
                let slope = |h: f64, mm: f64| alpha * sign * (f(h) - mm) + beta * fp(h);
                let k1 = slope(h_old, *m);
                let k2 = slope(h_old + 0.5 * dh, *m + 0.5 * dh * k1);
                let k3 = slope(h_old + 0.5 * dh, *m + 0.5 * dh * k2);
                let k4 = slope(h_new, *m + dh * k3);
                *m += dh / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
                *m
            }
            MagnetizationState::Preisach(p) => {
                let y = p.apply(h_new);
                ms * ((1.0 - rev_share) * y + rev_share * 2.0 / PI * (h_new / rev_width).atan())
            }
        }
    }

    /// Field pre-history from the demagnetised state (H = 0, M = 0) through `path`.
    fn premagnetise(&mut self, path: &[f64]) {
        if let MagnetizationState::Preisach(p) = &mut self.state {
            // Demagnetised Preisach state: a decaying alternating sequence to 0.
            let mut amp = p.h_max;
            while amp > 10.0 {
                p.apply(amp);
                p.apply(-0.9 * amp);
                amp *= 0.81;
            }
            p.apply(0.0);
        }
        let mut h = 0.0;
        for &target in path {
            let steps = ((target - h).abs() / 100.0).ceil().max(1.0) as usize;
            let dh = (target - h) / steps as f64;
            for _ in 0..steps {
                self.step(h, h + dh);
                h += dh;
            }
        }
    }
}

/// First two longitudinal modes of a fixed–free rod with a tip mass: frequencies [rad/s] and
/// each mode's share of the static tip compliance (Σ over all modes = 1).
pub fn rod_modes(rig: &Rig, count: usize) -> Vec<(f64, f64)> {
    let area = PI * rig.rod_radius_m.powi(2);
    let l = rig.rod_length_m;
    let rod_mass = rig.rod_density_kg_per_m3 * area * l;
    let mu = rod_mass / rig.load_mass_kg;
    let c = (rig.rod_young_pa / rig.rod_density_kg_per_m3).sqrt();
    let k_static = rig.rod_young_pa * area / l;
    let mut modes = Vec::with_capacity(count);
    for n in 0..count {
        // Root of x tan x = μ in (nπ, nπ + π/2) by bisection.
        let (mut lo, mut hi) = (n as f64 * PI + 1e-12, n as f64 * PI + 0.5 * PI - 1e-12);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid * mid.tan() < mu {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let x = 0.5 * (lo + hi);
        let beta = x / l;
        let omega = beta * c;
        // Mode shape φ = sin βx; modal mass ρA∫φ² + M_t φ(L)².
        let modal_mass = rig.rod_density_kg_per_m3 * area * (l / 2.0 - (2.0 * x).sin() / (4.0 * beta))
            + rig.load_mass_kg * x.sin().powi(2);
        let compliance = x.sin().powi(2) / (modal_mass * omega * omega);
        modes.push((omega, compliance * k_static));
    }
    modes
}

/// splitmix64 + Box–Muller: a small deterministic Gaussian source.
struct Noise {
    state: u64,
}

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn gaussian(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

fn quantise(x: f64, step: f64) -> f64 {
    if step > 0.0 {
        (x / step).round() * step
    } else {
        x
    }
}

/// State of the electrical, thermal and eddy stages: [v_amp, i, T_coil, T_rod, H_outer, H_core].
type FastState = [f64; 6];

impl Rig {
    fn coil_resistance(&self, coil_c: f64) -> f64 {
        let rise = if self.effects.thermal_drift { coil_c - self.ambient_c } else { 0.0 };
        self.coil_resistance_ohm * (1.0 + COPPER_TEMPERATURE_COEFFICIENT_PER_C * rise)
    }

    fn current(&self, y: &FastState, u: f64) -> f64 {
        if self.effects.amplifier_dynamics {
            y[1]
        } else {
            self.ideal_gain_a_per_v * u
        }
    }

    fn surface_field(&self, i: f64) -> f64 {
        self.turns_per_m * i + self.bias_a_per_m
    }

    /// Mean rod field of the ladder: outer shell 3/4 of the section, core 1/4.
    fn rod_field(&self, y: &FastState, i: f64) -> f64 {
        if self.effects.eddy_current {
            0.75 * y[4] + 0.25 * y[5]
        } else {
            self.surface_field(i)
        }
    }

    fn fast_derivative(&self, y: &FastState, u: f64) -> FastState {
        let mut d = [0.0; 6];
        let i = self.current(y, u);
        if self.effects.amplifier_dynamics {
            d[0] = (self.amp_gain_v_per_v * u - y[0]) / self.amp_tau_s;
            let v = y[0].clamp(-self.amp_rail_v, self.amp_rail_v);
            let di = (v - self.coil_resistance(y[2]) * i) / self.coil_inductance_h;
            // Current limit: the amplifier folds back instead of driving further.
            d[1] = if i.abs() >= self.current_limit_a && di * i > 0.0 { 0.0 } else { di };
        }
        if self.effects.thermal_drift {
            let heat = self.coil_resistance(y[2]) * i * i;
            d[2] = (heat - (y[2] - self.ambient_c) / self.coil_thermal_resistance_c_per_w)
                / self.coil_heat_capacity_j_per_c;
            d[3] = (y[2] - y[3]) / self.rod_thermal_tau_s;
        }
        if self.effects.eddy_current {
            // Two-branch Cauer ladder: the core draws on the outer shell in proportion to its
            // area (1/3 of the outer shell's), so flux is conserved between the branches.
            let hs = self.surface_field(i);
            d[4] = (hs - y[4]) / self.eddy_outer_tau_s - (y[4] - y[5]) / (3.0 * self.eddy_core_tau_s);
            d[5] = (y[4] - y[5]) / self.eddy_core_tau_s;
        }
        d
    }

    fn free_strain_um(&self, m_obs: f64, rod_c: f64) -> f64 {
        let r = m_obs / self.ms_a_per_m;
        let kappa = self.lambda_quartic_share;
        let lambda = 1.5 * self.lambda_s * ((1.0 - kappa) * r * r + kappa * r.powi(4));
        let thermal =
            if self.effects.thermal_drift { self.expansion_per_c * (rod_c - self.ambient_c) } else { 0.0 };
        1e6 * self.rod_length_m * (lambda + thermal)
    }

    /// Runs the rig on one drive.
    pub fn simulate(&self, drive: &Drive) -> Recording {
        let dt = 1.0 / self.sample_rate_hz;
        let samples = (drive.duration_s * self.sample_rate_hz).round().max(3.0) as usize;
        let h = dt / SUBSTEPS as f64;
        let fx = self.effects;

        // Initial electrical state: steady current for the command at t = 0.
        let u0 = drive.command_v(0.0);
        let i0 = if fx.amplifier_dynamics {
            (self.amp_gain_v_per_v * u0 / self.coil_resistance_ohm)
                .clamp(-self.current_limit_a, self.current_limit_a)
        } else {
            self.ideal_gain_a_per_v * u0
        };
        let hs0 = self.surface_field(i0);
        let mut y: FastState = [self.amp_gain_v_per_v * u0, i0, self.ambient_c, self.ambient_c, hs0, hs0];

        let mut law = Magnetization::new(self);
        let b = self.bias_a_per_m;
        let prehistory: Vec<f64> =
            if fx.premagnetised { vec![b + 60_000.0, b - 30_000.0, b + 15_000.0, hs0] } else { vec![b, hs0] };
        law.premagnetise(&prehistory);
        let mut h_rod = hs0;
        let mut m = law.step(h_rod, h_rod);

        // Aftereffect: log-uniform relaxation times.
        let (t_lo, t_hi) = CREEP_TAU_RANGE_S;
        let creep_decay: Vec<f64> = (0..CREEP_TERMS)
            .map(|k| {
                let tau = t_lo * (t_hi / t_lo).powf(k as f64 / (CREEP_TERMS - 1) as f64);
                (-h / tau).exp()
            })
            .collect();
        let mut creep = vec![m; CREEP_TERMS];
        let observed = |m: f64, creep: &[f64]| {
            if fx.magnetic_aftereffect {
                (1.0 - self.creep_share) * m
                    + self.creep_share * creep.iter().sum::<f64>() / CREEP_TERMS as f64
            } else {
                m
            }
        };

        let modes = rod_modes(self, 2);
        let mut x_free = self.free_strain_um(observed(m, &creep), y[3]);
        // Modal coordinates [q1, q1', q2, q2'] at static equilibrium.
        let mut q = [modes[0].1 * x_free, 0.0, modes[1].1 * x_free, 0.0];
        let share_total = modes[0].1 + modes[1].1;

        let mut noise = Noise { state: self.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5EED };
        let mut rec = Recording::default();
        let mut tip_history: Vec<f64> = Vec::with_capacity(samples);

        for k in 0..samples {
            let t_sample = k as f64 * dt;
            if k > 0 {
                for s in 0..SUBSTEPS {
                    let t = t_sample - dt + s as f64 * h;
                    let u_at = |tt: f64| drive.command_v(tt);
                    let k1 = self.fast_derivative(&y, u_at(t));
                    let y2 = add(&y, &k1, 0.5 * h);
                    let k2 = self.fast_derivative(&y2, u_at(t + 0.5 * h));
                    let y3 = add(&y, &k2, 0.5 * h);
                    let k3 = self.fast_derivative(&y3, u_at(t + 0.5 * h));
                    let y4 = add(&y, &k3, h);
                    let k4 = self.fast_derivative(&y4, u_at(t + h));
                    for j in 0..6 {
                        y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                    }
                    y[0] = y[0].clamp(-self.amp_rail_v, self.amp_rail_v);
                    y[1] = y[1].clamp(-self.current_limit_a, self.current_limit_a);
                    let i = self.current(&y, u_at(t + h));
                    let h_new = self.rod_field(&y, i);
                    let m_new = law.step(h_rod, h_new);
                    h_rod = h_new;
                    // Exact relaxation of each creep term towards M (M linear over the substep).
                    let m_mid = 0.5 * (m + m_new);
                    for (c, decay) in creep.iter_mut().zip(&creep_decay) {
                        *c = m_mid + (*c - m_mid) * decay;
                    }
                    m = m_new;
                    let x_new = self.free_strain_um(observed(m, &creep), y[3]);
                    if fx.mechanical_dynamics {
                        q = modal_rk4(&q, &modes, self.mode_damping, x_free, x_new, h);
                    }
                    x_free = x_new;
                }
            }
            let i_true = self.current(&y, drive.command_v(t_sample));
            let tip = if fx.mechanical_dynamics { (q[0] + q[2]) / share_total } else { x_free };
            tip_history.push(tip);
            let delayed =
                if fx.sensor_delay { tip_history[k.saturating_sub(self.delay_samples)] } else { tip };
            let (meas_x, meas_i, meas_t) = if fx.sensor_noise {
                (
                    quantise(delayed + self.offset_um + self.noise_um * noise.gaussian(), self.quantum_um),
                    quantise(i_true + self.current_noise_a * noise.gaussian(), self.current_quantum_a),
                    y[2] + 0.02 * noise.gaussian(),
                )
            } else {
                (delayed, i_true, y[2])
            };
            rec.time_s.push(t_sample);
            rec.command_v.push(drive.command_v(t_sample));
            rec.current_a.push(meas_i);
            rec.displacement_um.push(meas_x);
            rec.temperature_c.push(meas_t);
            rec.true_current_a.push(i_true);
            rec.rod_field_a_per_m.push(h_rod);
            rec.magnetization_a_per_m.push(m);
            rec.true_displacement_um.push(tip);
        }
        rec
    }
}

fn add(y: &FastState, d: &FastState, h: f64) -> FastState {
    let mut out = *y;
    for j in 0..6 {
        out[j] += h * d[j];
    }
    out
}

/// RK4 of the two modal oscillators q̈ + 2ζω q̇ + ω² q = ω² s x_free, x_free linear over the step.
/// The shares are renormalised by the caller (two modes carry ≈ 99 % of the static compliance).
fn modal_rk4(q: &[f64; 4], modes: &[(f64, f64)], zeta: [f64; 2], x0: f64, x1: f64, h: f64) -> [f64; 4] {
    let deriv = |s: &[f64; 4], frac: f64| {
        let x = x0 + (x1 - x0) * frac;
        let mut d = [0.0; 4];
        for j in 0..2 {
            let (w, share) = modes[j];
            d[2 * j] = s[2 * j + 1];
            d[2 * j + 1] = w * w * (share * x - s[2 * j]) - 2.0 * zeta[j] * w * s[2 * j + 1];
        }
        d
    };
    let step = |s: &[f64; 4], d: &[f64; 4], c: f64| {
        let mut o = *s;
        for j in 0..4 {
            o[j] += c * d[j];
        }
        o
    };
    let k1 = deriv(q, 0.0);
    let k2 = deriv(&step(q, &k1, 0.5 * h), 0.5);
    let k3 = deriv(&step(q, &k2, 0.5 * h), 0.5);
    let k4 = deriv(&step(q, &k3, h), 1.0);
    let mut out = *q;
    for j in 0..4 {
        out[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
    out
}

#[cfg(test)]
mod tests;
