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
    /// Field per ampere N/(k_f L) [A/m per A] = [1/m].
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

    /// Validates the field gain (> 0) and the bias (finite).
    pub fn new(turns_per_m: f32, bias_a_per_m: f32) -> Result<Self, ParamError> {
        check("coil.turns_per_m", turns_per_m, |n| n > 0.0 && n <= 1e7, "in (0, 1e7] 1/m")?;
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

/// First-order lag y' = (g u − y)/τ, discretised exactly for a held input:
/// y[n+1] = p y[n] + (1 − p) g u[n], p = e^{−T/τ}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirstOrderLag {
    pole: f32,
    gain: f32,
    /// (1 − p) g, folded once: the same rounding as forming it per sample, and a step the
    /// compiler no longer vectorises with a wide load across the neighbouring state fields
    /// (that load missed store forwarding and halved the plant simulator's speed on x86-64).
    input_gain: f32,
    tau_s: f32,
}

impl FirstOrderLag {
    /// τ > 0 (named `name` in errors), any finite gain, sample period `dt_s`.
    pub fn new(name: &'static str, tau_s: f32, gain: f32, dt_s: f32) -> Result<Self, ParamError> {
        positive(name, tau_s)?;
        check(name, gain, |_| true, "finite gain")?;
        positive("dt_s", dt_s)?;
        let pole = libm::exp(-(dt_s as f64) / tau_s as f64) as f32;
        Ok(Self { pole, gain, input_gain: (1.0 - pole) * gain, tau_s })
    }

    /// The time constant τ [s].
    pub fn tau_s(&self) -> f32 {
        self.tau_s
    }

    /// The discrete pole p = e^{−T/τ}.
    pub fn pole(&self) -> f32 {
        self.pole
    }

    /// The static gain.
    pub fn gain(&self) -> f32 {
        self.gain
    }

    /// One sample: advances `y` towards g u and returns it.
    #[inline]
    pub fn step(&self, y: &mut f32, u: f32) -> f32 {
        *y = self.pole * *y + self.input_gain * u;
        *y
    }

    /// The input that takes `y` to `target` in one sample (the lag's exact one-step inverse).
    #[inline]
    pub fn input_for(&self, y: f32, target: f32) -> f32 {
        (target - self.pole * y) / self.input_gain
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lag_matches_the_exponential() {
        let lag = FirstOrderLag::new("t", 2e-4, 2.0, 1e-4).unwrap();
        let mut y = 0.0;
        for n in 1..=10 {
            lag.step(&mut y, 1.0);
            let exact = 2.0 * (1.0 - (-(n as f64) * 0.5).exp());
            assert!((y as f64 - exact).abs() < 1e-6);
        }
        let u = lag.input_for(y, 0.3);
        lag.step(&mut y, u);
        assert!((y - 0.3).abs() < 1e-5);
    }

    #[test]
    fn eddy_time_constant_of_a_terfenol_rod() {
        // 10 mm solid rod, μ_r 5, ρ 6e-7 Ω m: τ = μ0·5·1e-4/(16·6e-7) ≈ 65 µs.
        let tau = eddy_time_constant_s(5.0, 0.01, 0.0, 6e-7, 1.0).unwrap();
        assert!((tau - 6.545e-5).abs() < 1e-7, "{tau}");
        assert!(eddy_time_constant_s(5.0, 0.01, 0.02, 6e-7, 1.0).is_err());
    }
}
