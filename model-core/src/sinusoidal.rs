//! Sinusoidal steady-state models of 000 (Zhu & Li): field diffusion into a conducting rod
//! (Kelvin functions, eq. 33–45) and the complex-permeability magnetization model (eq. 2–9,
//! 16–17) with its amplitude-dependent modification (eq. 50, 52–56).
//!
//! These evaluate closed forms for a drive I_m cos ωt, not a sample-by-sample recursion, so they
//! run in f64 (they are used to compare with sine recordings and to size the lumped models,
//! not in the 10 kHz loop).

use crate::error::{non_negative, positive, ParamError};
use crate::field::MU0;
use core::f64::consts::PI;

fn sq(x: f64) -> f64 {
    x * x
}

/// Kelvin functions ber(x) and bei(x): J_0(x e^{3πi/4}) = ber x + i bei x (000 eq. 40).
/// Power series (f64, converges for every x; used up to x = 30 where cancellation still
/// leaves ten digits). Beyond that use [`kelvin_modulus_phase`].
pub fn ber_bei(x: f64) -> (f64, f64) {
    let q = (0.5 * x) * (0.5 * x);
    let q2 = q * q;
    let (mut ber, mut bei) = (0.0, 0.0);
    let (mut t_ber, mut t_bei) = (1.0, q);
    let mut k = 0.0f64;
    while k < 200.0 {
        ber += t_ber;
        bei += t_bei;
        // t_{k+1} = −t_k (x/2)^4 / ((2k+1)(2k+2))², and ((2k+2)(2k+3))² for bei.
        t_ber *= -q2 / sq((2.0 * k + 1.0) * (2.0 * k + 2.0));
        t_bei *= -q2 / sq((2.0 * k + 2.0) * (2.0 * k + 3.0));
        if libm::fabs(t_ber) <= 1e-17 * libm::fabs(ber).max(1.0)
            && libm::fabs(t_bei) <= 1e-17 * libm::fabs(bei).max(1e-300)
        {
            break;
        }
        k += 1.0;
    }
    (ber, bei)
}

/// Modulus √(ber² + bei²) and unwrapped phase atan(bei/ber) of J_0(x e^{3πi/4}) for x ≥ 0.
/// Series up to x = 30; above, the asymptotic expansion (A&S 9.10.26–27 to 1/x²):
/// modulus e^{x/√2}/√(2πx) (1 + 1/(8√2 x) + 1/(256 x²)), phase x/√2 − π/8 − 1/(8√2 x) − 1/(16 x²).
pub fn kelvin_modulus_phase(x: f64) -> (f64, f64) {
    let x = libm::fabs(x);
    let r2 = core::f64::consts::SQRT_2;
    if x <= 30.0 {
        let (ber, bei) = ber_bei(x);
        let wrapped = libm::atan2(bei, ber);
        // Unwrap with the asymptotic phase (its error is far below π once x > 3).
        let phase = if x > 3.0 {
            let est = x / r2 - PI / 8.0;
            wrapped + 2.0 * PI * libm::round((est - wrapped) / (2.0 * PI))
        } else {
            wrapped
        };
        (libm::sqrt(ber * ber + bei * bei), phase)
    } else {
        let modulus = libm::exp(x / r2) / libm::sqrt(2.0 * PI * x)
            * (1.0 + 1.0 / (8.0 * r2 * x) + 1.0 / (256.0 * x * x));
        let phase = x / r2 - PI / 8.0 - 1.0 / (8.0 * r2 * x) - 1.0 / (16.0 * x * x);
        (modulus, phase)
    }
}

/// A solid conducting rod in an axial sinusoidal field (000 eq. 33–45): the field on the axis
/// is the surface field divided by J_0(r √(−jωγμ)).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct RodEddy {
    /// Rod radius r_G [m].
    pub radius_m: f32,
    /// Electrical conductivity γ [S/m] (Terfenol-D ≈ 1.67e6, 000 Table 1).
    pub conductivity_s_per_m: f32,
    /// Relative permeability μ_r of the rod (|μ_r|).
    pub relative_permeability: f32,
}

/// Amplitude ratio and lag of the field on the rod axis against the surface field (eq. 43–44).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EddyResponse {
    /// Kelvin argument x = r_G √(ωγμ).
    pub kelvin_argument: f64,
    /// 1 / √(ber² + bei²) (1 at DC, falling with frequency).
    pub amplitude: f64,
    /// θ_e = atan(bei / ber) [rad] (0 at DC, growing with frequency).
    pub lag_rad: f64,
}

impl RodEddy {
    /// 000 Table 1: r_G = 5 mm, γ = 1.67e6 S/m, |μ_r| = 5.
    pub const ZHU_LI_000: RodEddy =
        RodEddy { radius_m: 0.005, conductivity_s_per_m: 1.67e6, relative_permeability: 5.0 };

    /// Validates the rod (a zero conductivity is allowed: no eddy currents).
    pub fn validated(self) -> Result<Self, ParamError> {
        positive("eddy.radius_m", self.radius_m)?;
        non_negative("eddy.conductivity_s_per_m", self.conductivity_s_per_m)?;
        positive("eddy.relative_permeability", self.relative_permeability)?;
        Ok(self)
    }

    /// Response at `freq_hz` (≥ 0).
    pub fn response(&self, freq_hz: f64) -> EddyResponse {
        let omega = 2.0 * PI * libm::fabs(freq_hz);
        let mu = MU0 * self.relative_permeability as f64;
        let x = self.radius_m as f64 * libm::sqrt(omega * self.conductivity_s_per_m as f64 * mu);
        let (modulus, phase) = kelvin_modulus_phase(x);
        EddyResponse { kelvin_argument: x, amplitude: 1.0 / modulus, lag_rad: phase }
    }

    /// The lumped first-order time constant with the same low-frequency lag: θ_e ≈ x²/4 = ω γ μ r²/4,
    /// so τ = γ μ r² / 4 — the same as 002 eq. 2 for a solid rod (d_o = 2r, d_i = 0, k_J = 1).
    pub fn equivalent_tau_s(&self) -> f64 {
        let mu = MU0 * self.relative_permeability as f64;
        self.conductivity_s_per_m as f64 * mu * sq(self.radius_m as f64) / 4.0
    }
}

/// The complex-permeability transducer model of 000 with its amplitude correction.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ComplexPermeabilityParams {
    /// Coil field per ampere N/(k_f L_G) [A/m per A] (eq. 1).
    pub turns_per_m: f32,
    /// Bias field H_b [A/m].
    pub bias_a_per_m: f32,
    /// Modulus of the relative permeability |μ_r| (> 1).
    pub mu_r_abs: f32,
    /// k_u [1/A]: imaginary part μ''_h = k_u I_m (eq. 50).
    pub mu_imag_per_a: f32,
    /// Calibration point: displacement y_0 [m] at field amplitude H_0 (eq. 15–16).
    pub y0_m: f32,
    /// Field amplitude H_0 [A/m] of the calibration point.
    pub h0_a_per_m: f32,
    /// Reference current amplitude I_0 [A] the model was identified at (eq. 52).
    pub i0_a: f32,
    /// Amplitude correction ŷ_0 [m/A] (eq. 52; 000 finds ≈ 13 in its units).
    pub y_hat_m_per_a: f32,
    /// Rod for the eddy-current amplitude and lag (eq. 43–45).
    pub rod: RodEddy,
    /// Mechanics K/(m s² + C s + K): moving mass m [kg] (eq. 46, 53).
    pub mass_kg: f32,
    /// Damping C [N s/m].
    pub damping_n_s_per_m: f32,
    /// Stiffness K [N/m].
    pub stiffness_n_per_m: f32,
    /// Lumped amplifier + aftereffect time constant τ [s] (eq. 56; 0 leaves it out).
    pub tau_s: f32,
}

/// Validated complex-permeability model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ComplexPermeability {
    p: ComplexPermeabilityParams,
}

/// The model's steady state for one drive amplitude and frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SinusoidalResponse {
    /// μ''_h = k_u I_m.
    pub mu_imag: f64,
    /// Hysteresis lag θ_h [rad] (eq. 9).
    pub hysteresis_lag_rad: f64,
    /// Eddy-current response of the rod (eq. 43–44).
    pub eddy: EddyResponse,
    /// L_f (eq. 55): magnetization amplitude per field amplitude, eddy included.
    pub l_f: f64,
    /// Field amplitude H_m [A/m].
    pub field_amplitude_a_per_m: f64,
    /// Displacement scale (y_0 + (I_m − I_0) ŷ_0) / ((|μ_r| − 1)² ((H_0 + H_b)² − H_b²)) [m·m²/A²].
    gain: f64,
    bias_magnetization: f64,
    omega: f64,
    /// Mechanics × lag at DC, ω and 2ω, as (modulus, phase).
    g: [(f64, f64); 3],
}

impl ComplexPermeability {
    /// 000 Table 1 and §5: N = 1300, L_G = 80 mm, k_f = 1.2, M_b = 250 kA/m with |μ_r| = 5
    /// (H_b = M_b/(|μ_r| − 1)), μ''_h = 1.1 at 0.5 A, ŷ_0 = 13 µm/A, m = 0.1 kg, c = 3000 N s/m,
    /// K = 9.9e6 N/m, τ = 0.2 ms. y_0 and H_0 are not printed; 20 µm at H_0 = 0.5 A × N/(k_f L_G)
    /// is in the range of the paper's figures.
    pub const ZHU_LI_000: ComplexPermeabilityParams = ComplexPermeabilityParams {
        turns_per_m: 13_541.7,
        bias_a_per_m: 62_500.0,
        mu_r_abs: 5.0,
        mu_imag_per_a: 2.2,
        y0_m: 20e-6,
        h0_a_per_m: 6770.8,
        i0_a: 0.5,
        y_hat_m_per_a: 13e-6,
        rod: RodEddy::ZHU_LI_000,
        mass_kg: 0.1,
        damping_n_s_per_m: 3000.0,
        stiffness_n_per_m: 9.9e6,
        tau_s: 2e-4,
    };

    /// Validates the parameters.
    pub fn new(p: ComplexPermeabilityParams) -> Result<Self, ParamError> {
        positive("cp.turns_per_m", p.turns_per_m)?;
        non_negative("cp.bias_a_per_m", p.bias_a_per_m)?;
        crate::error::check("cp.mu_r_abs", p.mu_r_abs, |v| v > 1.0, "> 1")?;
        non_negative("cp.mu_imag_per_a", p.mu_imag_per_a)?;
        crate::error::check("cp.y0_m", p.y0_m, |v| v != 0.0, "non-zero")?;
        positive("cp.h0_a_per_m", p.h0_a_per_m)?;
        non_negative("cp.i0_a", p.i0_a)?;
        crate::error::check("cp.y_hat_m_per_a", p.y_hat_m_per_a, |_| true, "finite")?;
        p.rod.validated()?;
        positive("cp.mass_kg", p.mass_kg)?;
        non_negative("cp.damping_n_s_per_m", p.damping_n_s_per_m)?;
        positive("cp.stiffness_n_per_m", p.stiffness_n_per_m)?;
        non_negative("cp.tau_s", p.tau_s)?;
        Ok(Self { p })
    }

    /// The steady state for drive amplitude `i_m_a` [A] at `freq_hz`. Returns an error when the
    /// amplitude makes μ''_h ≥ |μ_r| (eq. 6 has no real μ').
    pub fn response(&self, i_m_a: f64, freq_hz: f64) -> Result<SinusoidalResponse, ParamError> {
        let p = &self.p;
        let i_m = libm::fabs(i_m_a);
        let mu_abs = p.mu_r_abs as f64;
        let mu_imag = p.mu_imag_per_a as f64 * i_m;
        if mu_imag >= mu_abs {
            return Err(ParamError::OutOfRange("drive amplitude", "such that k_u·I_m < |mu_r| (eq. 6)"));
        }
        let mu_real = libm::sqrt(mu_abs * mu_abs - mu_imag * mu_imag); // eq. 6
        let l_h = libm::sqrt(sq(mu_real - 1.0) + mu_imag * mu_imag); // eq. 8
        let hysteresis_lag_rad = libm::atan2(mu_imag, mu_real - 1.0); // eq. 9
        let eddy = p.rod.response(freq_hz);
        let (hb, h0) = (p.bias_a_per_m as f64, p.h0_a_per_m as f64);
        let denom = sq(mu_abs - 1.0) * (sq(h0 + hb) - hb * hb);
        let gain = (p.y0_m as f64 + (i_m - p.i0_a as f64) * p.y_hat_m_per_a as f64) / denom;
        let omega = 2.0 * PI * libm::fabs(freq_hz);
        let g = [0.0, omega, 2.0 * omega].map(|w| self.linear_dynamics(w));
        Ok(SinusoidalResponse {
            mu_imag,
            hysteresis_lag_rad,
            eddy,
            l_f: l_h * eddy.amplitude, // eq. 55
            field_amplitude_a_per_m: p.turns_per_m as f64 * i_m,
            gain,
            bias_magnetization: (mu_abs - 1.0) * hb,
            omega,
            g,
        })
    }

    /// K/(m s² + C s + K) · 1/(τ s + 1) at s = jω, as (modulus, phase).
    fn linear_dynamics(&self, w: f64) -> (f64, f64) {
        let p = &self.p;
        let (m, c, k, tau) =
            (p.mass_kg as f64, p.damping_n_s_per_m as f64, p.stiffness_n_per_m as f64, p.tau_s as f64);
        let (re, im) = (k - m * w * w, c * w);
        let modulus = k / libm::sqrt(re * re + im * im) / libm::sqrt(1.0 + sq(tau * w));
        let phase = -libm::atan2(im, re) - libm::atan(tau * w);
        (modulus, phase)
    }
}

impl SinusoidalResponse {
    /// M(t) [A/m] (eq. 54): L_f H_m cos(ωt − θ_h − θ_e) + (|μ_r| − 1) H_b.
    pub fn magnetization(&self, t_s: f64) -> f64 {
        let phi = self.omega * t_s - self.hysteresis_lag_rad - self.eddy.lag_rad;
        self.l_f * self.field_amplitude_a_per_m * libm::cos(phi) + self.bias_magnetization
    }

    /// Displacement y(t) [m] (eq. 56). M² − M_b² holds a DC term, the fundamental and the second
    /// harmonic; each passes the mechanics and τ lag at its own frequency.
    pub fn displacement(&self, t_s: f64) -> f64 {
        let a = self.l_f * self.field_amplitude_a_per_m;
        let mb = self.bias_magnetization;
        let phi = self.omega * t_s - self.hysteresis_lag_rad - self.eddy.lag_rad;
        let [g0, g1, g2] = self.g;
        self.gain
            * (0.5 * a * a * g0.0
                + 2.0 * a * mb * g1.0 * libm::cos(phi + g1.1)
                + 0.5 * a * a * g2.0 * libm::cos(2.0 * phi + g2.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kelvin_functions_match_tables() {
        // Abramowitz & Stegun Table 9.12.
        for (x, ber, bei) in [
            (1.0, 0.984_381_781_6, 0.249_566_040_0),
            (2.0, 0.751_734_182_6, 0.972_291_627_0),
            (5.0, -6.230_082_479, 0.116_034_382_9),
            (10.0, 138.840_466_3, 56.370_458_01),
        ] {
            let (r, i) = ber_bei(x);
            assert!((r - ber).abs() <= 1e-8 * ber.abs().max(1.0), "ber({x}) = {r}");
            assert!((i - bei).abs() <= 1e-8 * bei.abs().max(1.0), "bei({x}) = {i}");
        }
    }

    #[test]
    fn series_and_asymptote_join_at_30() {
        let (m_s, p_s) = kelvin_modulus_phase(30.0);
        let (m_a, p_a) = kelvin_modulus_phase(30.0 + 1e-9);
        assert!((m_s / m_a - 1.0).abs() < 1e-4, "modulus {m_s} vs {m_a}");
        assert!((p_s - p_a).abs() < 1e-4, "phase {p_s} vs {p_a}");
        // Phase is unwrapped and increasing.
        let mut last = -1.0;
        for k in 0..400 {
            let (_, ph) = kelvin_modulus_phase(k as f64 * 0.1);
            assert!(ph > last - 1e-12, "phase falls at x = {}", k as f64 * 0.1);
            last = ph;
        }
    }

    #[test]
    fn low_frequency_lag_equals_the_lumped_time_constant() {
        // θ_e ≈ ωτ with τ = γμr²/4 — the same τ as 002 eq. 2 for a solid rod.
        let rod = RodEddy::ZHU_LI_000;
        let tau = rod.equivalent_tau_s();
        let tau_002 = crate::field::eddy_time_constant_s(
            rod.relative_permeability,
            2.0 * rod.radius_m,
            0.0,
            1.0 / rod.conductivity_s_per_m,
            1.0,
        )
        .unwrap() as f64;
        assert!((tau / tau_002 - 1.0).abs() < 1e-5, "τ {tau} vs 002 eq. 2 {tau_002}");
        let f = 10.0;
        let r = rod.response(f);
        let lumped = (2.0 * PI * f * tau).atan();
        assert!((r.lag_rad / lumped - 1.0).abs() < 1e-3, "lag {} vs lumped {lumped}", r.lag_rad);
        // At high frequency the field on the axis keeps falling and lagging (skin effect).
        let hi = rod.response(20_000.0);
        assert!(hi.amplitude < 0.5 && hi.lag_rad > 1.0, "{hi:?}");
    }

    #[test]
    fn calibration_point_is_reproduced() {
        // Static, no hysteresis lag (k_u = 0), no eddy (γ = 0), at I_m = I_0 and H_m = H_0:
        // M peaks at (|μ_r| − 1)(H_0 + H_b), so y peaks at y_0 (eq. 15–16).
        let mut p = ComplexPermeability::ZHU_LI_000;
        p.mu_imag_per_a = 0.0;
        p.rod.conductivity_s_per_m = 0.0;
        p.tau_s = 0.0;
        p.damping_n_s_per_m = 0.0;
        let model = ComplexPermeability::new(p).unwrap();
        let i0 = p.h0_a_per_m as f64 / p.turns_per_m as f64;
        let r = model.response(i0, 1e-3).unwrap();
        let y = r.displacement(0.0);
        // Amplitude correction (I_m − I_0) ŷ_0 is zero at I_0 = 0.5 A only if i0 = 0.5 A.
        let expected = p.y0_m as f64 + (i0 - p.i0_a as f64) * p.y_hat_m_per_a as f64;
        assert!((y / expected - 1.0).abs() < 1e-6, "y {y} vs {expected}");
    }

    #[test]
    fn hysteresis_lag_grows_with_amplitude() {
        let model = ComplexPermeability::new(ComplexPermeability::ZHU_LI_000).unwrap();
        // 000: μ''_h = 1.1 at 0.5 A with |μ_r| = 5 → θ_h = atan(1.1 / (√(25 − 1.21) − 1)).
        let r = model.response(0.5, 1.0).unwrap();
        let expected = (1.1f64 / ((25.0f64 - 1.21).sqrt() - 1.0)).atan();
        assert!((r.hysteresis_lag_rad - expected).abs() < 1e-6, "θ_h {}", r.hysteresis_lag_rad);
        let small = model.response(0.25, 1.0).unwrap();
        let large = model.response(1.0, 1.0).unwrap();
        assert!(
            small.hysteresis_lag_rad < r.hysteresis_lag_rad
                && r.hysteresis_lag_rad < large.hysteresis_lag_rad
        );
        assert!(model.response(3.0, 1.0).is_err(), "k_u I_m ≥ |μ_r| must be refused");
    }
}
