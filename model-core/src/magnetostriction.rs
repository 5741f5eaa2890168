//! Quadratic magnetostriction λ = (3/2)(λ_s/M_s²)(M² − M_b²) (000 eq. 10–11, 001 eq. 1), the bias
//! magnetization M_b subtracted so that λ = 0 at the operating point, with the optional static
//! preload factor of 002 eq. 3–4.

use crate::error::{check, non_negative, positive, saturation, ParamError};

/// Static mechanical preload on the rod (002 eq. 3–4). It must leave at least 1 % of the free
/// strain ([`Preload::MIN_FACTOR`]): at F = F_s + F_max it cancels it, k_λ is 0 and the inverse
/// divides by it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct Preload {
    /// Preload force F [N].
    pub force_n: f32,
    /// Optimal preload F_s [N] (largest strain gain).
    pub optimal_force_n: f32,
    /// F_max = (3/2) λ_s E_G A_G [N], the force that cancels the strain.
    pub max_force_n: f32,
}

impl Preload {
    /// Smallest strain factor accepted: a preload that leaves less of the strain is a clamped
    /// rod, not an actuator.
    pub const MIN_FACTOR: f32 = 0.01;

    /// The strain factor (1 + ½ tanh(2F/F_s)), times (1 − (F − F_s)/F_max) above F_s.
    pub fn factor(&self) -> Result<f32, ParamError> {
        let f = non_negative("magnetostriction.preload.force_n", self.force_n)?;
        let fs = positive("magnetostriction.preload.optimal_force_n", self.optimal_force_n)?;
        let fmax = positive("magnetostriction.preload.max_force_n", self.max_force_n)?;
        let base = 1.0 + 0.5 * libm::tanhf(2.0 * f / fs);
        let factor = if f <= fs { base } else { (1.0 - (f - fs) / fmax) * base };
        check(
            "magnetostriction.preload.force_n",
            factor,
            |v| v >= Self::MIN_FACTOR,
            "below F_s + 0.99 F_max (the preload leaves at least 1 % of the strain)",
        )
    }
}

/// Parameters of the quadratic magnetostriction.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct QuadraticParams {
    /// Saturation magnetostriction λ_s (dimensionless, ~1e-3 for Terfenol-D), in [1e-9, 1]: the
    /// floor is Terfenol-D's strain with displacements in m read as µm (nickel's, among the
    /// weakest, is 3e-5); below it k_λ loses its digits and the inverse overflows.
    pub lambda_s: f32,
    /// Saturation magnetization M_s [A/m] the strain is normalised by.
    pub ms_a_per_m: f32,
    /// Bias magnetization M_b [A/m] subtracted (000 eq. 11); 0 without bias.
    pub bias_m_a_per_m: f32,
    /// Optional static preload (002 eq. 3).
    pub preload: Option<Preload>,
}

/// Validated quadratic magnetostriction: λ = k_λ (M² − M_b²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadraticMagnetostriction {
    k_lambda: f32,
    mb2: f32,
    params: QuadraticParams,
}

impl QuadraticMagnetostriction {
    /// Validates and folds the constants into k_λ = (3/2) λ_s/M_s² × preload factor.
    pub fn new(p: QuadraticParams) -> Result<Self, ParamError> {
        // A strain, not ppm (Terfenol-D: about 1e-3). Simplified models fitted to real strokes
        // can need more than any material's λ_s, so the cap only keeps outputs finite.
        check(
            "magnetostriction.lambda_s",
            p.lambda_s,
            |v| (1e-9..=1.0).contains(&v),
            "in [1e-9, 1] (a strain, not ppm)",
        )?;
        let ms = saturation("magnetostriction.ms_a_per_m", p.ms_a_per_m)?;
        check("magnetostriction.bias_m_a_per_m", p.bias_m_a_per_m, |b| b.abs() < ms, "|M_b| < M_s")?;
        let factor = match p.preload {
            Some(pl) => pl.factor()?,
            None => 1.0,
        };
        let k_lambda = 1.5 * p.lambda_s / (ms * ms) * factor;
        Ok(Self { k_lambda, mb2: p.bias_m_a_per_m * p.bias_m_a_per_m, params: p })
    }

    /// The parameters.
    pub fn params(&self) -> &QuadraticParams {
        &self.params
    }

    /// k_λ [m²/A²] (000 eq. 12 calls it k_λ too).
    pub fn k_lambda(&self) -> f32 {
        self.k_lambda
    }

    /// Strain λ(M).
    #[inline]
    pub fn strain(&self, m: f32) -> f32 {
        self.k_lambda * (m * m - self.mb2)
    }

    /// The magnetization that gives strain `lambda` on the branch with the sign of `sign_of_m`
    /// (λ is even in M); strains below −k_λ M_b² are unreachable and clamp to M = 0.
    #[inline]
    pub fn magnetization_for(&self, lambda: f32, sign_of_m: f32) -> f32 {
        let m2 = crate::math::at_least(lambda / self.k_lambda + self.mb2, 0.0);
        crate::math::sqrt(m2).copysign(sign_of_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_with_bias_and_inverse() {
        let q = QuadraticMagnetostriction::new(QuadraticParams {
            lambda_s: 1.2e-3,
            ms_a_per_m: 7.65e5,
            bias_m_a_per_m: 2.5e5,
            preload: None,
        })
        .unwrap();
        assert_eq!(q.strain(2.5e5), 0.0);
        let m = 4.0e5;
        let lam = q.strain(m);
        assert!((lam - 1.5 * 1.2e-3 / 7.65e5f32.powi(2) * (m * m - 2.5e5f32.powi(2))).abs() < 1e-9);
        assert!((q.magnetization_for(lam, 1.0) - m).abs() < 1.0);
    }

    /// The divisors of the inverse have physical floors: a preload that cancels the strain
    /// (F = F_s + F_max: k_λ = 0, the compensator's state NaN) or a subnormal λ_s (1e-40: k_λ
    /// = 0) is refused by name; at the floors M for a strain is finite.
    #[test]
    fn a_strain_scale_that_vanishes_is_refused_by_name() {
        let p = QuadraticParams { lambda_s: 1e-3, ms_a_per_m: 6e5, bias_m_a_per_m: 0.0, preload: None };
        let cancelling = Preload { force_n: 11_000.0, optimal_force_n: 1000.0, max_force_n: 10_000.0 };
        for bad in
            [QuadraticParams { preload: Some(cancelling), ..p }, QuadraticParams { lambda_s: 1e-40, ..p }]
        {
            let name = QuadraticMagnetostriction::new(bad).err().map(|e| e.name());
            assert!(
                matches!(name, Some("magnetostriction.preload.force_n" | "magnetostriction.lambda_s")),
                "{bad:?}"
            );
        }
        let weakest = Preload { force_n: 10_900.0, ..cancelling };
        for q in [
            QuadraticParams { preload: Some(weakest), ..p },
            QuadraticParams { lambda_s: 1e-9, ms_a_per_m: 1e7, ..p },
        ] {
            let q = QuadraticMagnetostriction::new(q).unwrap();
            assert!(q.k_lambda() > 0.0 && q.magnetization_for(1e-2, 1.0).is_finite(), "{q:?}");
        }
    }

    #[test]
    fn preload_factor_peaks_at_the_optimal_force() {
        let pl = |f| Preload { force_n: f, optimal_force_n: 1000.0, max_force_n: 10_000.0 }.factor().unwrap();
        assert_eq!(pl(0.0), 1.0);
        assert!(pl(1000.0) > pl(500.0) && pl(1000.0) > pl(3000.0));
        assert!(Preload { force_n: 1e6, optimal_force_n: 1000.0, max_force_n: 10_000.0 }.factor().is_err());
    }
}
