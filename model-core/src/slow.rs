//! Slow effects on top of the fast chain: magnetic aftereffect (creep), coil heating → thermal
//! expansion of the rod, and the displacement sensor's transport delay.

use crate::error::{check, ParamError};
use crate::field::{FirstOrderLag, LagState};

/// Magnetic aftereffect: a fraction w of every magnetization change arrives with a slow time
/// constant τ_a (magnetic viscosity): M_out = (1 − w) M + w M_slow, M_slow' = (M − M_slow)/τ_a.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct AftereffectParams {
    /// Slow fraction w, 0 ≤ w < 1.
    pub fraction: f32,
    /// Creep time constant τ_a [s].
    pub tau_s: f32,
}

/// Validated aftereffect; state is the slow magnetization M_slow [A/m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aftereffect {
    lag: FirstOrderLag,
    fraction: f32,
}

impl Aftereffect {
    /// Validates and discretises at `dt_s`.
    pub fn new(p: AftereffectParams, dt_s: f32) -> Result<Self, ParamError> {
        check("aftereffect.fraction", p.fraction, |w| (0.0..1.0).contains(&w), "in [0, 1)")?;
        Ok(Self { lag: FirstOrderLag::new("aftereffect.tau_s", p.tau_s, 1.0, dt_s)?, fraction: p.fraction })
    }

    /// One sample: returns the observed magnetization.
    #[inline]
    pub fn step(&self, m_slow: &mut LagState, m: f32) -> f32 {
        let slow = self.lag.step(m_slow, m);
        (1.0 - self.fraction) * m + self.fraction * slow
    }

    /// Its lag's ramp factor ([`FirstOrderLag::ramp_factor`]).
    pub fn ramp_factor(&self, dt_s: f32) -> f32 {
        self.lag.ramp_factor(dt_s)
    }

    /// One sample under a magnetization running linearly from `m0` to `m1`: returns the
    /// observed magnetization at its end.
    #[inline]
    pub fn step_ramp(&self, m_slow: &mut LagState, m0: f32, m1: f32, ramp: f32) -> f32 {
        let slow = self.lag.step_ramp(m_slow, m0, m1, ramp);
        (1.0 - self.fraction) * m1 + self.fraction * slow
    }

    /// The instantaneous magnetization that makes the observed one equal `m_out` this sample.
    #[inline]
    pub fn magnetization_for(&self, m_slow: &LagState, m_out: f32) -> f32 {
        // m_out = (1 − w) m + w (s + f (m − s)) = s + ((1 − w) + w f)(m − s): of a change of M,
        // the share (1 − w) + w f ≥ 1 − w > 0 shows in the same sample.
        let f = self.lag.fraction_per_sample();
        let s = m_slow.value();
        s + (m_out - s) / ((1.0 - self.fraction) + self.fraction * f)
    }
}

/// Coil heating → rod thermal expansion: the coil's temperature rise θ' = (R_th R i² − θ)/τ_th
/// (what a thermometer on the winding reads, above its surroundings), the rod's rise behind it
/// θ_r' = (θ − θ_r)/τ_r (heat crosses the gap between winding and rod; τ_r = 0: the rod follows
/// the coil at once), expansion Δy = α_T L θ_r (α_T = 12.9e-6 /°C for Terfenol-D, 002 §VII).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ThermalParams {
    /// Coil resistance R [Ω].
    pub coil_resistance_ohm: f32,
    /// Thermal resistance R_th of the coil to its surroundings [°C/W] (τ_th = R_th × its heat
    /// capacity).
    pub thermal_resistance_c_per_w: f32,
    /// Thermal time constant τ_th [s].
    pub tau_s: f32,
    /// Rod length L [m], in [1e-4, 10] (as the chain's).
    pub rod_length_m: f32,
    /// Expansion coefficient α_T [1/°C].
    pub expansion_per_c: f32,
    /// Time constant τ_r [s] of the rod's temperature behind the coil's; 0 (the default, and
    /// every parameter file before 2026-11-26): the rod follows the coil at once. A fit
    /// identifies it only from recordings that log the coil's temperature, which pins the coil's
    /// own lag: from the displacement alone the two lags trade.
    #[cfg_attr(feature = "serde", serde(default))]
    pub rod_tau_s: f32,
}

impl ThermalParams {
    /// Terfenol-D's thermal expansion coefficient (002 §VII).
    pub const TERFENOL_EXPANSION_PER_C: f32 = 12.9e-6;
}

/// Validated thermal drift; state is the coil's and the rod's temperature rise θ, θ_r [°C].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalDrift {
    lag: FirstOrderLag,
    /// The rod behind the coil (None: τ_r = 0, the rod at the coil's temperature).
    rod_lag: Option<FirstOrderLag>,
    metres_per_c: f32,
}

impl ThermalDrift {
    /// Validates and discretises at `dt_s`.
    pub fn new(p: ThermalParams, dt_s: f32) -> Result<Self, ParamError> {
        check(
            "thermal.coil_resistance_ohm",
            p.coil_resistance_ohm,
            |r| (0.0..=1e4).contains(&r),
            "in [0, 1e4] Ω",
        )?;
        check(
            "thermal.thermal_resistance_c_per_w",
            p.thermal_resistance_c_per_w,
            |r| (0.0..=1e4).contains(&r),
            "in [0, 1e4] °C/W",
        )?;
        let l =
            check("thermal.rod_length_m", p.rod_length_m, |l| (1e-4..=10.0).contains(&l), "in [1e-4, 10] m")?;
        let a = check(
            "thermal.expansion_per_c",
            p.expansion_per_c,
            |a| (0.0..=1e-3).contains(&a),
            "in [0, 1e-3] 1/°C",
        )?;
        let rod_tau = check("thermal.rod_tau_s", p.rod_tau_s, |t| (0.0..=1e5).contains(&t), "in [0, 1e5] s")?;
        let rod_lag = if rod_tau > 0.0 {
            Some(FirstOrderLag::new("thermal.rod_tau_s", rod_tau, 1.0, dt_s)?)
        } else {
            None
        };
        let gain = p.coil_resistance_ohm * p.thermal_resistance_c_per_w;
        Ok(Self {
            lag: FirstOrderLag::new("thermal.tau_s", p.tau_s, gain, dt_s)?,
            rod_lag,
            metres_per_c: a * l,
        })
    }

    /// One sample at coil current `i`: advances the coil's rise θ and the rod's θ_r, returns
    /// the thermal elongation [m].
    #[inline]
    pub fn step(&self, theta_c: &mut LagState, rod_theta_c: &mut LagState, current_a: f32) -> f32 {
        let coil = self.lag.step(theta_c, current_a * current_a);
        let rod = match &self.rod_lag {
            Some(lag) => lag.step(rod_theta_c, coil),
            None => {
                *rod_theta_c = *theta_c;
                coil
            }
        };
        rod * self.metres_per_c
    }

    /// The ramp factors of the coil's and the rod's lags ([`FirstOrderLag::ramp_factor`]; 0 for a
    /// rod that follows the coil at once).
    pub fn ramp_factors(&self, dt_s: f32) -> (f32, f32) {
        (self.lag.ramp_factor(dt_s), self.rod_lag.as_ref().map_or(0.0, |l| l.ramp_factor(dt_s)))
    }

    /// One sample under a current running linearly from `i0` to `i1` (its square taken as
    /// running linearly too), with `ramps` = [`ThermalDrift::ramp_factors`]: returns the
    /// thermal elongation [m] at its end.
    #[inline]
    pub fn step_ramp(
        &self,
        theta_c: &mut LagState,
        rod_theta_c: &mut LagState,
        i0: f32,
        i1: f32,
        ramps: (f32, f32),
    ) -> f32 {
        let coil_before = theta_c.value();
        let coil = self.lag.step_ramp(theta_c, i0 * i0, i1 * i1, ramps.0);
        let rod = match &self.rod_lag {
            Some(lag) => lag.step_ramp(rod_theta_c, coil_before, coil, ramps.1),
            None => {
                *rod_theta_c = *theta_c;
                coil
            }
        };
        rod * self.metres_per_c
    }

    /// Elongation [m] for a rod temperature rise θ_r.
    #[inline]
    pub fn elongation_m(&self, rod_theta_c: f32) -> f32 {
        rod_theta_c * self.metres_per_c
    }
}

/// Transport delay of `delay` samples, at most `N` (fixed-size ring buffer). A fractional
/// delay interpolates linearly between the two samples around it: exact at whole samples,
/// continuous in `delay` (a fit can move it smoothly), and at half a sample a mild low-pass
/// (|H| = cos(ω/2): −0.1 dB at a twentieth of the sample rate, −1.8 dB at a fifth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayLine<const N: usize> {
    buf: [f32; N],
    head: usize,
    whole: usize,
    fraction: f32,
}

impl<const N: usize> DelayLine<N> {
    /// A delay of `delay` samples (0 ≤ delay ≤ N), initially filled with `initial`.
    pub fn new(delay: f32, initial: f32) -> Result<Self, ParamError> {
        if !(delay.is_finite() && (0.0..=N as f32).contains(&delay)) {
            return Err(ParamError::OutOfRange("delay.samples", "0 to the delay line's capacity"));
        }
        Ok(Self::clamped(delay, initial))
    }

    /// A delay of `delay` samples clamped to [0, N] (0 when not finite), initially filled with
    /// `initial`.
    pub fn clamped(delay: f32, initial: f32) -> Self {
        let d = if delay.is_finite() { delay.clamp(0.0, N as f32) } else { 0.0 };
        let whole = (d as usize).min(N);
        Self { buf: [initial; N], head: 0, whole, fraction: d - whole as f32 }
    }

    /// Pushes `x`, returns the value from `delay` samples ago.
    #[inline]
    pub fn step(&mut self, x: f32) -> f32 {
        if N == 0 {
            return x;
        }
        // The slot written k samples ago is k positions behind head (k = 0: the input itself;
        // k = N: the slot about to be overwritten).
        let ago = |k: usize| if k == 0 { x } else { self.buf[(self.head + N - k) % N] };
        let near = ago(self.whole);
        let out =
            if self.fraction > 0.0 { near + self.fraction * (ago(self.whole + 1) - near) } else { near };
        self.buf[self.head] = x;
        self.head = (self.head + 1) % N;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delay_line_delays_exactly() {
        let mut d = DelayLine::<8>::new(3.0, 0.0).unwrap();
        let out: Vec<f32> = (1..=6).map(|x| d.step(x as f32)).collect();
        assert_eq!(out, [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        let mut full = DelayLine::<4>::new(4.0, -1.0).unwrap();
        let out: Vec<f32> = (1..=6).map(|x| full.step(x as f32)).collect();
        assert_eq!(out, [-1.0, -1.0, -1.0, -1.0, 1.0, 2.0]);
        assert!(DelayLine::<4>::new(5.0, 0.0).is_err());
        assert!(DelayLine::<4>::new(f32::NAN, 0.0).is_err());
    }

    /// A fractional delay shifts a sine by δ samples (at 200 Hz, 10 kHz, the interpolation's
    /// low-pass takes δ(1 − δ)ω²/2 ≤ 0.2 % of the amplitude), is continuous across whole samples,
    /// and its step response settles to the step.
    #[test]
    fn a_fractional_delay_shifts_a_sine_by_its_fraction() {
        let (f, fs) = (200.0_f64, 10_000.0_f64);
        let w = 2.0 * core::f64::consts::PI * f / fs;
        for delay in [0.25_f32, 1.5, 3.7, 7.5] {
            let mut d = DelayLine::<8>::new(delay, 0.0).unwrap();
            let err = (0..2000)
                .map(|k| (d.step((w * k as f64).sin() as f32) as f64, k as f64))
                .filter(|&(_, k)| k > 16.0)
                .map(|(y, k)| (y - (w * (k - delay as f64)).sin()).abs())
                .fold(0.0, f64::max);
            assert!(err < 2e-3, "delay {delay}: {err} from the sine shifted by {delay} samples");
            let mut s = DelayLine::<8>::new(delay, 0.0).unwrap();
            let last = (0..20).map(|_| s.step(1.0)).last().unwrap();
            assert_eq!(last, 1.0, "delay {delay}: the step settles");
        }
        // Continuous at a whole sample: 3 − ε and 3 give nearly the same output.
        let ramp = |delay: f32| {
            let mut d = DelayLine::<8>::new(delay, 0.0).unwrap();
            (0..12).map(|k| d.step(k as f32)).last().unwrap()
        };
        assert!((ramp(2.999) - ramp(3.0)).abs() < 2e-3 && ramp(3.0) == 8.0);
    }

    #[test]
    fn aftereffect_creeps_and_inverts() {
        let ae = Aftereffect::new(AftereffectParams { fraction: 0.2, tau_s: 0.05 }, 1e-4).unwrap();
        let mut slow = LagState::default();
        let first = ae.step(&mut slow, 1000.0);
        assert!((first - 800.0).abs() < 1.0, "{first}");
        for _ in 0..20_000 {
            ae.step(&mut slow, 1000.0);
        }
        assert!((ae.step(&mut slow, 1000.0) - 1000.0).abs() < 0.1);
        let m = ae.magnetization_for(&slow, 1200.0);
        assert!((ae.step(&mut slow, m) - 1200.0).abs() < 0.05);
    }

    /// 002 §VII scale: a 20 W coil heating a 100 mm rod by ~2 °C in 20 s gives ≈ 2 µm.
    #[test]
    fn thermal_drift_has_the_papers_scale() {
        let th = ThermalDrift::new(
            ThermalParams {
                coil_resistance_ohm: 5.0,
                thermal_resistance_c_per_w: 0.5,
                tau_s: 60.0,
                rod_length_m: 0.1,
                expansion_per_c: ThermalParams::TERFENOL_EXPANSION_PER_C,
                rod_tau_s: 0.0,
            },
            1e-3,
        )
        .unwrap();
        let (mut theta, mut rod) = (LagState::default(), LagState::default());
        let mut y = 0.0;
        for _ in 0..20_000 {
            y = th.step(&mut theta, &mut rod, 2.0);
        }
        let theta = theta.value();
        // θ(20 s) = 10 °C·(1 − e^{−1/3}) = 2.835 °C → 3.66 µm.
        assert!((theta - 2.835).abs() < 0.01 && (y * 1e6 - 3.657).abs() < 0.01, "{theta} °C, {} µm", y * 1e6);
    }

    /// The rod's rise follows the coil's through its own lag: for a heating step the two-node
    /// response θ_r(t) = G(1 − (τ e^{−t/τ} − τ_r e^{−t/τ_r})/(τ − τ_r)) (G = R_th R i²), and the
    /// elongation is the rod's, not the coil's.
    #[test]
    fn the_rod_lags_the_coil() {
        let (tau, tau_r, dt) = (60.0_f64, 15.0_f64, 1e-2_f32);
        let p = ThermalParams {
            coil_resistance_ohm: 5.0,
            thermal_resistance_c_per_w: 0.5,
            tau_s: tau as f32,
            rod_length_m: 0.1,
            expansion_per_c: ThermalParams::TERFENOL_EXPANSION_PER_C,
            rod_tau_s: tau_r as f32,
        };
        let th = ThermalDrift::new(p, dt).unwrap();
        let (mut coil, mut rod, mut y) = (LagState::default(), LagState::default(), 0.0);
        let steps = 2_000; // 20 s
        for _ in 0..steps {
            y = th.step(&mut coil, &mut rod, 2.0);
        }
        let (coil, rod) = (coil.value(), rod.value());
        let t = steps as f64 * dt as f64;
        let g = 10.0;
        let exact_coil = g * (1.0 - (-t / tau).exp());
        let exact_rod = g * (1.0 - (tau * (-t / tau).exp() - tau_r * (-t / tau_r).exp()) / (tau - tau_r));
        assert!((coil as f64 - exact_coil).abs() < 2e-3, "coil {coil} °C, exact {exact_coil}");
        assert!((rod as f64 - exact_rod).abs() < 2e-3, "rod {rod} °C, exact {exact_rod}");
        assert!(rod < 0.7 * coil, "the rod behind the coil: {rod} against {coil} °C");
        assert_eq!(y, th.elongation_m(rod));
        let bad = ThermalParams { rod_tau_s: -1.0, ..p };
        assert!(ThermalDrift::new(bad, dt).is_err());
        assert!(ThermalDrift::new(ThermalParams { rod_tau_s: f32::NAN, ..p }, dt).is_err());
        // 1e5 s is a rod's lag at 10 kHz, not at 10 MHz (1e12 samples: it would not move in f32).
        assert!(ThermalDrift::new(ThermalParams { rod_tau_s: 1e5, ..p }, 1e-4).is_ok());
        assert!(matches!(
            ThermalDrift::new(ThermalParams { rod_tau_s: 1e5, ..p }, 1e-7),
            Err(ParamError::OutOfRange("thermal.rod_tau_s", _))
        ));
    }
}
