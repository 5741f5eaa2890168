//! The field path: coil current → applied field (000 eq. 1), and the lumped eddy-current lag in
//! the rod (002 eq. 2). The exact discrete first-order lag here is shared by every first-order
//! stage (amplifier, eddy currents, aftereffect, thermal).

use crate::error::{check, positive, ParamError};

/// μ0 [H/m].
pub const MU0: f64 = 4.0e-7 * core::f64::consts::PI;

/// Coil field H = N i / (k_f L) + H_bias (000 eq. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct CoilField {
    /// Field per ampere N/(k_f L) [A/m per A] = [1/m], in [1, 1e7]: one turn per metre is no
    /// actuator's coil (000's: 13 500), and the inverse divides by it.
    pub turns_per_m: f32,
    /// Bias field from a permanent magnet or DC bias current [A/m].
    pub bias_a_per_m: f32,
}

impl CoilField {
    /// From the winding: N turns, coil length L [m], field non-uniformity factor k_f (000 Table 1: 1.2).
    pub fn from_winding(turns: f32, length_m: f32, k_f: f32, bias_a_per_m: f32) -> Result<Self, ParamError> {
        positive("coil.turns", turns)?;
        positive("coil.length_m", length_m)?;
        positive("coil.k_f", k_f)?;
        Self::new(turns / (k_f * length_m), bias_a_per_m)
    }

    /// Validates the field gain (in [1, 1e7] 1/m) and the bias (within ±1e7 A/m).
    pub fn new(turns_per_m: f32, bias_a_per_m: f32) -> Result<Self, ParamError> {
        check("coil.turns_per_m", turns_per_m, |n| (1.0..=1e7).contains(&n), "in [1, 1e7] 1/m")?;
        check("coil.bias_a_per_m", bias_a_per_m, |b| b.abs() <= 1e7, "within ±1e7 A/m")?;
        Ok(Self { turns_per_m, bias_a_per_m })
    }

    /// H(i).
    #[inline]
    pub fn field(&self, current_a: f32) -> f32 {
        self.turns_per_m * current_a + self.bias_a_per_m
    }

    /// i(H).
    #[inline]
    pub fn current_for(&self, h: f32) -> f32 {
        (h - self.bias_a_per_m) / self.turns_per_m
    }
}

/// Eddy-current time constant of a rod or tube, τ = μ0 μ_G (d_o² − d_i²) / (16 k_J ρ_G) (002 eq. 2).
///
/// `mu_r` relative permeability, diameters in metres, `resistivity_ohm_m` ρ_G, `k_j` the
/// laminations/slits correction (1 for a solid rod).
pub fn eddy_time_constant_s(
    mu_r: f32,
    outer_diameter_m: f32,
    inner_diameter_m: f32,
    resistivity_ohm_m: f32,
    k_j: f32,
) -> Result<f32, ParamError> {
    positive("eddy.mu_r", mu_r)?;
    let d_o = positive("eddy.outer_diameter_m", outer_diameter_m)?;
    let d_i =
        check("eddy.inner_diameter_m", inner_diameter_m, |d| d >= 0.0 && d < d_o, "in [0, outer diameter)")?;
    positive("eddy.resistivity_ohm_m", resistivity_ohm_m)?;
    positive("eddy.k_j", k_j)?;
    let (d_o, d_i) = (d_o as f64, d_i as f64);
    let tau = MU0 * mu_r as f64 * (d_o * d_o - d_i * d_i) / (16.0 * k_j as f64 * resistivity_ohm_m as f64);
    Ok(tau as f32)
}

/// Longest time constant a [`FirstOrderLag`] accepts, in sample periods. Its state's two f32
/// (see [`LagState`]) resolve an increment down to about 2⁻⁴⁸ of the output, so with τ ≤ 1e9 T
/// the lag settles to within 4e-6 of its target; a slower one would stop short of it (and its
/// one-step inverse amplify by more than 1e9). At 10 kHz: τ up to 1e5 s.
pub const MAX_TAU_IN_SAMPLES: f32 = 1e9;

/// First-order lag y' = (g u − y)/τ, discretised exactly for a held input:
/// y[n+1] = y[n] + f (g u[n] − y[n]), f = 1 − e^{−T/τ} (the share of the distance to g u
/// covered per sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirstOrderLag {
    /// f, formed as −expm1(−T/τ): exact to f32 rounding however small T/τ (1 − e^{−T/τ} rounded
    /// to f32 is a multiple of 2⁻²⁴: at T/τ = 1e-7 the time constant came out 18 % short).
    fraction: f32,
    gain: f32,
    tau_s: f32,
}

/// State of a [`FirstOrderLag`]: its output, and what the last additions to it rounded off
/// (Kahan summation). A slow lag's increment per sample falls below half an ulp of the output
/// long before it settles (τ = 30 s at 10 kHz: a coil heating to 36 °C stopped at 34.86 °C);
/// carried over, the increments add up.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LagState {
    value: f32,
    carry: f32,
}

impl LagState {
    /// A lag resting at `value`.
    pub const fn at(value: f32) -> Self {
        Self { value, carry: 0.0 }
    }

    /// The output.
    #[inline]
    pub fn value(&self) -> f32 {
        self.value
    }
}

impl FirstOrderLag {
    /// τ in (0, [`MAX_TAU_IN_SAMPLES`] T] (named `name` in errors), any finite gain, sample
    /// period `dt_s`.
    pub fn new(name: &'static str, tau_s: f32, gain: f32, dt_s: f32) -> Result<Self, ParamError> {
        positive(name, tau_s)?;
        check(name, gain, |_| true, "finite gain")?;
        positive("dt_s", dt_s)?;
        if tau_s > MAX_TAU_IN_SAMPLES * dt_s {
            return Err(ParamError::OutOfRange(
                name,
                "at most 1e9 sample periods (dt_s / tau >= 1e-9): a longer lag does not settle in f32",
            ));
        }
        let fraction = -libm::expm1(-(dt_s as f64) / tau_s as f64) as f32;
        Ok(Self { fraction, gain, tau_s })
    }

    /// The time constant τ [s].
    pub fn tau_s(&self) -> f32 {
        self.tau_s
    }

    /// f = 1 − e^{−T/τ}: the share of the distance to its target the lag covers per sample.
    pub fn fraction_per_sample(&self) -> f32 {
        self.fraction
    }

    /// The static gain.
    pub fn gain(&self) -> f32 {
        self.gain
    }

    /// One sample: advances `s` towards g u and returns the output.
    #[inline]
    pub fn step(&self, s: &mut LagState, u: f32) -> f32 {
        // The increment from the carried value (output + carry), plus the carry itself.
        let increment = self.fraction * (self.gain * u - s.value - s.carry) + s.carry;
        let value = s.value + increment;
        s.carry = increment - (value - s.value);
        s.value = value;
        value
    }

    /// The ramp factor r = 1 − (1 − e^{−T/τ})/(T/τ) at sample period `dt_s`: the output's share,
    /// at the end of a sample, of a rise of the input that runs linearly across it (exact for a
    /// first-order hold, [`FirstOrderLag::step_ramp`]). Formed in f64 (a series for tiny T/τ).
    pub fn ramp_factor(&self, dt_s: f32) -> f32 {
        let x = dt_s as f64 / self.tau_s as f64;
        (if x < 1e-4 { x / 2.0 - x * x / 6.0 + x * x * x / 24.0 } else { 1.0 + libm::expm1(-x) / x }) as f32
    }

    /// One sample under an input that runs linearly from `u0` (this sample's) to `u1` (the
    /// next's): exact for that ramp, with `ramp` = [`FirstOrderLag::ramp_factor`].
    #[inline]
    pub fn step_ramp(&self, s: &mut LagState, u0: f32, u1: f32, ramp: f32) -> f32 {
        let increment =
            self.fraction * (self.gain * u0 - s.value - s.carry) + ramp * self.gain * (u1 - u0) + s.carry;
        let value = s.value + increment;
        s.carry = increment - (value - s.value);
        s.value = value;
        value
    }

    /// The input that takes the lag from `s` to `target` in one sample (its exact one-step
    /// inverse). Finite for a non-zero gain and a finite target that is not absurdly far
    /// (f ≥ 1e-9: no 0/0, as f = 0 gave); beyond, ±∞, which callers clamp.
    #[inline]
    pub fn input_for(&self, s: &LagState, target: f32) -> f32 {
        (s.value + (target - s.value - s.carry) / self.fraction + s.carry) / self.gain
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lag_matches_the_exponential() {
        let lag = FirstOrderLag::new("t", 2e-4, 2.0, 1e-4).unwrap();
        let mut y = LagState::default();
        for n in 1..=10 {
            lag.step(&mut y, 1.0);
            let exact = 2.0 * (1.0 - (-(n as f64) * 0.5).exp());
            assert!((y.value() as f64 - exact).abs() < 1e-6);
        }
        let u = lag.input_for(&y, 0.3);
        lag.step(&mut y, u);
        assert!((y.value() - 0.3).abs() < 1e-5);
    }

    /// The ramp step is exact for an input running linearly across each sample: a ramp
    /// u(t) = t from rest has y(t) = t − τ (1 − e^{−t/τ}); for T/τ from 1e-6 to 20.
    #[test]
    fn ramp_step_is_exact_for_a_ramp() {
        for (tau, dt) in [(2e-4, 1e-4), (1e-4, 1e-4), (5e-6, 1e-4), (100.0, 1e-4)] {
            let lag = FirstOrderLag::new("t", tau as f32, 1.0, dt as f32).unwrap();
            let r = lag.ramp_factor(dt as f32);
            let mut y = LagState::default();
            for n in 0..50 {
                let (u0, u1) = (n as f64 * dt, (n + 1) as f64 * dt);
                lag.step_ramp(&mut y, u0 as f32, u1 as f32, r);
                let t = u1;
                let exact = t + tau * libm::expm1(-t / tau);
                assert!(
                    (y.value() as f64 - exact).abs() <= 1e-5 * t + 1e-12,
                    "τ = {tau}, sample {n}: {} vs {exact}",
                    y.value()
                );
            }
        }
    }

    /// Runs `lag` for `steps` samples at input `u` from rest; its output against the exact
    /// g u (1 − e^{−steps·T/τ}), relative to g u.
    fn relative_error_after(lag: &FirstOrderLag, dt_s: f64, steps: u32, u: f32) -> f64 {
        let mut y = LagState::default();
        for _ in 0..steps {
            lag.step(&mut y, u);
        }
        let target = lag.gain() as f64 * u as f64;
        let exact = target * -(-(steps as f64) * dt_s / lag.tau_s() as f64).exp_m1();
        (y.value() as f64 - exact).abs() / target
    }

    /// A slow lag settles on its target: 36 °C through τ = 30 s at 10 kHz (each sample's increment
    /// is below half an ulp of the output from 34.86 °C on, where the plain f32 update stopped).
    #[test]
    fn a_slow_lag_settles_on_its_target() {
        let lag = FirstOrderLag::new("thermal.tau_s", 30.0, 36.0, 1e-4).unwrap();
        let err = relative_error_after(&lag, 1e-4, 6_000_000, 1.0); // 20 τ
        assert!(err < 1e-6, "after 20 τ: {:.2e} of the target off", err);
    }

    /// The time constant holds however small dt/τ: 1 − e^{−dt/τ} rounded to f32 was a multiple
    /// of 2⁻²⁴ (τ = 1000 s at 10 kHz: 18 % off after 100 s) and 1.0 below dt/τ ≈ 3e-8 (the lag
    /// never moved: τ = 1 h at 10 kHz, or the demo's 30 s at the shortest dt, 1e-7 s).
    #[test]
    fn the_time_constant_holds_for_tiny_dt_per_tau() {
        for (tau, dt, steps) in [(1000.0, 1e-4, 1_000_000), (3600.0, 1e-4, 100_000), (30.0, 1e-7, 1_000_000)]
        {
            let lag = FirstOrderLag::new("thermal.tau_s", tau, 36.0, dt as f32).unwrap();
            let err = relative_error_after(&lag, dt as f32 as f64, steps, 1.0);
            assert!(
                err < 1e-5,
                "τ = {tau} s, dt = {dt} s: {err:.2e} of the target off after {steps} samples"
            );
        }
    }

    /// A lag longer than 1e9 sample periods is refused by its name (a time constant typed in
    /// the wrong unit, or a file at too high a rate); at the bound it still moves and inverts.
    #[test]
    fn a_lag_too_slow_for_its_sample_period_is_refused_by_name() {
        assert!(matches!(
            FirstOrderLag::new("eddy_tau_s", 1e6, 1.0, 1e-4),
            Err(ParamError::OutOfRange("eddy_tau_s", _))
        ));
        let lag = FirstOrderLag::new("eddy_tau_s", 1e5, 1.0, 1e-4).unwrap();
        assert!(lag.fraction_per_sample() > 0.0);
        let mut y = LagState::at(2e4);
        let u = lag.input_for(&y, 2.1e4);
        assert!(u.is_finite() && (lag.step(&mut y, u) - 2.1e4).abs() < 1.0, "{u} gave {y:?}");
    }

    /// A subnormal field gain (1e-45) made the inverse's current infinite; below one turn per
    /// metre it is refused by name.
    #[test]
    fn a_coil_without_turns_is_refused_by_name() {
        for bad in [1e-45, 0.5, 2e7] {
            assert!(matches!(CoilField::new(bad, 0.0), Err(ParamError::OutOfRange("coil.turns_per_m", _))));
        }
        let weakest = CoilField::new(1.0, 1e7).unwrap();
        assert!(weakest.current_for(-1e7).is_finite());
    }

    #[test]
    fn eddy_time_constant_of_a_terfenol_rod() {
        // 10 mm solid rod, μ_r 5, ρ 6e-7 Ω m: τ = μ0·5·1e-4/(16·6e-7) ≈ 65 µs.
        let tau = eddy_time_constant_s(5.0, 0.01, 0.0, 6e-7, 1.0).unwrap();
        assert!((tau - 6.545e-5).abs() < 1e-7, "{tau}");
        assert!(eddy_time_constant_s(5.0, 0.01, 0.02, 6e-7, 1.0).is_err());
    }
}
