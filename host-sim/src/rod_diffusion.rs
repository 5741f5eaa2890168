//! Distributed eddy currents for the plant simulator (SIMULATED rigs): the axial field diffusing
//! into a solid conducting rod, ∂H/∂t = D ∇²H (radial), with the coil field H_coil on the surface
//! (linear, constant permeability: the diffusivity D = 1/(σμ)). The cross-section average field,
//! which drives the magnetization, is exactly a sum of first-order lags over the rod's modes:
//!
//! ```text
//! H_avg(s) / H_coil(s) = 2 I₁(qR) / (qR I₀(qR)),  q = √(s/D)
//!                      = Σ_k (4/j_k²) / (1 + s τ_k),  τ_k = R² / (D j_k²)
//! ```
//!
//! with j_k the zeros of J₀ (Σ 4/j_k² = 1). Its low-frequency lag (first moment) is R²/(8D) =
//! σμR²/8, half the axis field's σμR²/4 that 000 and 002 eq. 2 use. The rod is set by that lag,
//! `eddy_tau_s`, so it lags like the lumped first-order model of the same τ at low frequency and
//! departs from it where the skin depth falls below the radius (phase towards 45°, amplitude
//! falling as 1/√ω instead of 1/ω): a plant richer than the model.
//!
//! Each mode is integrated exactly for an input held over the step; modes much faster than the
//! step, and the tail of the series, pass straight through.

use anyhow::{bail, Result};

/// Most modes kept (the slowest ones; the rest pass straight through).
const MAX_MODES: usize = 32;
/// A mode whose time constant is below this fraction of the step is treated as instantaneous.
const FASTEST_MODE_PER_STEP: f64 = 0.05;

/// The k-th positive zero of the Bessel function J₀ (k ≥ 1): McMahon's expansion, then Newton.
pub fn bessel_j0_zero(k: usize) -> f64 {
    let beta = (k as f64 - 0.25) * std::f64::consts::PI;
    let b8 = 8.0 * beta;
    let mut x = beta + 1.0 / b8 - 124.0 / (3.0 * b8.powi(3));
    for _ in 0..4 {
        // J₀' = −J₁
        x += libm::j0(x) / libm::j1(x);
    }
    x
}

/// Field diffusion into a solid rod, discretised at a fixed step (immutable).
#[derive(Debug, Clone, PartialEq)]
pub struct RodDiffusion {
    /// e^{−dt/τ_k} per kept mode.
    pole: Vec<f64>,
    /// (1 − e^{−dt/τ_k}) w_k per kept mode.
    input_gain: Vec<f64>,
    /// w_k = 4/j_k² per kept mode (the mode's share of the average field at rest).
    weight: Vec<f64>,
    /// The weight of every faster mode: passed straight through.
    direct: f64,
}

/// Modal fields of a [`RodDiffusion`] [A/m] (mutable, per step).
#[derive(Debug, Clone, PartialEq)]
pub struct RodDiffusionState {
    modes: Vec<f64>,
}

impl RodDiffusion {
    /// A rod whose average field lags the surface field by `lag_s` at low frequency (the lumped
    /// eddy time constant), stepped every `dt_s`.
    pub fn new(lag_s: f64, dt_s: f64) -> Result<Self> {
        if !(lag_s.is_finite() && lag_s > 0.0) {
            bail!("eddy_tau_s must be > 0 s for distributed eddy currents, got {lag_s}");
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            bail!("the integration step must be > 0 s, got {dt_s}");
        }
        let r2_over_d = 8.0 * lag_s;
        let (mut pole, mut input_gain, mut weight) = (Vec::new(), Vec::new(), Vec::new());
        let mut direct = 1.0;
        for k in 1..=MAX_MODES {
            let j = bessel_j0_zero(k);
            let tau = r2_over_d / (j * j);
            if tau < FASTEST_MODE_PER_STEP * dt_s {
                break;
            }
            let w = 4.0 / (j * j);
            let p = (-dt_s / tau).exp();
            pole.push(p);
            input_gain.push((1.0 - p) * w);
            weight.push(w);
            direct -= w;
        }
        Ok(Self { pole, input_gain, weight, direct })
    }

    /// Number of modes integrated (the others pass straight through).
    pub fn modes(&self) -> usize {
        self.pole.len()
    }

    /// The state in equilibrium with a steady surface field `h` [A/m] (a rod at rest).
    pub fn rest_state(&self, h: f64) -> RodDiffusionState {
        RodDiffusionState { modes: self.weight.iter().map(|w| w * h).collect() }
    }

    /// One step with the surface field `h_coil` [A/m] held; returns the average field [A/m].
    #[inline]
    pub fn step(&self, s: &mut RodDiffusionState, h_coil: f64) -> f64 {
        let mut sum = self.direct * h_coil;
        for ((y, p), g) in s.modes.iter_mut().zip(&self.pole).zip(&self.input_gain) {
            *y = p * *y + g * h_coil;
            sum += *y;
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Complex numbers for the reference solution (just what the series needs).
    #[derive(Clone, Copy, Debug)]
    struct C(f64, f64);
    impl C {
        fn mul(self, o: C) -> C {
            C(self.0 * o.0 - self.1 * o.1, self.0 * o.1 + self.1 * o.0)
        }
        fn div(self, o: C) -> C {
            let d = o.0 * o.0 + o.1 * o.1;
            C((self.0 * o.0 + self.1 * o.1) / d, (self.1 * o.0 - self.0 * o.1) / d)
        }
        fn abs(self) -> f64 {
            self.0.hypot(self.1)
        }
    }

    /// I_n(z) by its power series (|z| ≲ 20 here; 80 terms are far beyond convergence).
    fn bessel_i(n: u32, z: C) -> C {
        let half = C(z.0 / 2.0, z.1 / 2.0);
        let q = half.mul(half);
        let mut term = C(1.0, 0.0);
        for _ in 0..n {
            term = term.mul(half);
        }
        for i in 1..=n {
            term = C(term.0 / i as f64, term.1 / i as f64);
        }
        let mut sum = term;
        for m in 1..80u32 {
            let f = (m * (m + n)) as f64;
            term = term.mul(q);
            term = C(term.0 / f, term.1 / f);
            sum = C(sum.0 + term.0, sum.1 + term.1);
        }
        sum
    }

    /// The exact average-field response 2 I₁(qR)/(qR I₀(qR)) at angular frequency ω.
    fn exact_average(omega: f64, r2_over_d: f64) -> C {
        // qR = √(jω R²/D) = √(ω R²/D) e^{jπ/4}
        let m = (omega * r2_over_d).sqrt();
        let qr = C(m * std::f64::consts::FRAC_1_SQRT_2, m * std::f64::consts::FRAC_1_SQRT_2);
        let two_i1 = bessel_i(1, qr);
        C(2.0 * two_i1.0, 2.0 * two_i1.1).div(qr.mul(bessel_i(0, qr)))
    }

    #[test]
    fn zeros_of_j0() {
        assert!((bessel_j0_zero(1) - 2.404_825_557_695_773).abs() < 1e-12);
        assert!((bessel_j0_zero(2) - 5.520_078_110_286_311).abs() < 1e-12);
        assert!((bessel_j0_zero(10) - 30.634_606_468_431_975).abs() < 1e-10);
        assert!(bessel_j0_zero(3) - bessel_j0_zero(2) > 3.0);
    }

    /// The stepped rod reproduces the exact distributed response in sinusoidal steady state,
    /// from far below to far above the lag's corner frequency, where the lumped lag does not.
    #[test]
    fn matches_the_exact_solution_and_departs_from_the_lumped_lag() {
        let (tau, dt) = (3e-4, 1e-6);
        let rod = RodDiffusion::new(tau, dt).unwrap();
        assert!(rod.modes() >= 20, "{} modes", rod.modes());
        for f in [20.0, 200.0, 1000.0, 5000.0] {
            let omega = 2.0 * std::f64::consts::PI * f;
            let mut s = rod.rest_state(0.0);
            let per = (1.0 / (f * dt)).round() as usize;
            let n = per * ((20.0 * tau * f).ceil() as usize + 3);
            // In-phase and quadrature parts of the last full period.
            let (mut re, mut im) = (0.0, 0.0);
            for i in 0..n {
                // The input held over the step is the sine at its midpoint; y is the end value.
                let y = rod.step(&mut s, (omega * (i as f64 + 0.5) * dt).sin());
                let t = (i + 1) as f64 * dt;
                if i >= n - per {
                    re += y * (omega * t).sin();
                    im += y * (omega * t).cos();
                }
            }
            let got = C(2.0 * re / per as f64, 2.0 * im / per as f64);
            let exact = exact_average(omega, 8.0 * tau);
            let err = C(got.0 - exact.0, got.1 - exact.1).abs();
            assert!(err < 1e-3, "{f} Hz: stepped {got:?}, exact {exact:?}");
            let lumped = C(1.0, 0.0).div(C(1.0, omega * tau));
            let gap = C(lumped.0 - exact.0, lumped.1 - exact.1).abs();
            println!("{f} Hz: stepped error {err:.1e}, lumped lag off by {gap:.3}");
            if f >= 1000.0 {
                assert!(gap > 0.05, "{f} Hz: the lumped lag is as good ({gap})");
            } else if f <= 20.0 {
                assert!(gap < 0.01, "{f} Hz: the rods should agree at low frequency ({gap})");
            }
        }
    }

    #[test]
    fn at_rest_the_rod_holds_the_surface_field_and_its_lag_is_tau() {
        let rod = RodDiffusion::new(2e-4, 5e-5).unwrap();
        let mut s = rod.rest_state(2e4);
        for _ in 0..10 {
            assert!((rod.step(&mut s, 2e4) - 2e4).abs() < 1e-6);
        }
        // First moment of the modal weights: Σ w_k τ_k = τ (+ the straight-through tail's ~0).
        let lag: f64 = (1..=MAX_MODES)
            .map(|k| {
                let j = bessel_j0_zero(k);
                4.0 / (j * j) * 8.0 * 2e-4 / (j * j)
            })
            .sum();
        assert!((lag - 2e-4).abs() < 1e-8, "{lag}");
        assert!(RodDiffusion::new(0.0, 5e-5).is_err() && RodDiffusion::new(f64::NAN, 5e-5).is_err());
    }
}
