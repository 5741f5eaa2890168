//! Adaptive explicit Runge–Kutta integrator: Dormand–Prince 5(4) with embedded error
//! estimate, first-same-as-last reuse and an elementary step-size controller.
//!
//! Coefficients: J. R. Dormand and P. J. Prince, "A family of embedded Runge–Kutta formulae",
//! J. Comput. Appl. Math. 6 (1980) 19–26; step control as in E. Hairer, S. P. Nørsett and
//! G. Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., Springer 1993, §II.4:
//! `err = sqrt(mean((e_i / (atol_i + rtol·max(|y_i|, |y_new_i|)))²))`, accept if err ≤ 1,
//! `h_new = h · clamp(0.9 · err^(-1/5), 0.2, 5)`.
//!
//! The method is explicit: on the stiff parts of the rig (field diffusion in fine radial
//! shells) the controller finds the step at the stability limit by itself, through
//! rejected steps. The integrator is written for this crate; it does not use any ODE crate.

/// A system of ODEs y' = f(t, y) with optional discrete updates after accepted steps.
pub trait OdeSystem {
    /// Evaluate f(t, y) into `dy` (same length as `y`).
    fn rhs(&mut self, t: f64, y: &[f64], dy: &mut [f64]);

    /// Called after every accepted step with the new state. The system may project the state
    /// (clamps, algebraic constraints) or update discrete memory (hysteresis history). Return
    /// `true` if anything the right-hand side depends on changed, so that the integrator
    /// re-evaluates f at the start of the next step instead of reusing the last stage.
    fn accepted(&mut self, _t: f64, _y: &mut [f64]) -> bool {
        false
    }
}

/// Counters of the integrator's work.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepStats {
    /// Accepted steps.
    pub accepted: u64,
    /// Rejected steps (error too large, or a non-finite stage).
    pub rejected: u64,
    /// Right-hand-side evaluations.
    pub rhs_evals: u64,
}

/// Why an integration stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum IntegrationError {
    /// The step size fell below the minimum (the system is too stiff, discontinuous at a
    /// point, or diverging).
    StepTooSmall {
        /// Time at which it happened (s).
        t: f64,
        /// The step size that was needed (s).
        h: f64,
    },
}

impl std::fmt::Display for IntegrationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            IntegrationError::StepTooSmall { t, h } => {
                write!(f, "integrator step size fell to {h:.3e} s at t = {t:.6} s")
            }
        }
    }
}

impl std::error::Error for IntegrationError {}

// Butcher tableau of DOPRI5.
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Error coefficients: 5th-order weights minus the embedded 4th-order weights.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// Dormand–Prince 5(4) integrator with preallocated work arrays.
#[derive(Clone, Debug)]
pub struct DormandPrince {
    rtol: f64,
    atol: Vec<f64>,
    h: f64,
    h_max: f64,
    h_min: f64,
    k: [Vec<f64>; 7],
    y_stage: Vec<f64>,
    y_new: Vec<f64>,
    fsal_valid: bool,
    stats: StepStats,
}

impl DormandPrince {
    /// A new integrator for a state of `atol.len()` components, with relative tolerance
    /// `rtol`, per-component absolute tolerances `atol`, an initial step `h_init` and a
    /// largest step `h_max` [same unit as t].
    pub fn new(rtol: f64, atol: Vec<f64>, h_init: f64, h_max: f64) -> Self {
        let n = atol.len();
        let z = || vec![0.0; n];
        DormandPrince {
            rtol,
            atol,
            h: h_init.min(h_max),
            h_max,
            h_min: 1e-14 * h_max.max(1e-300),
            k: [z(), z(), z(), z(), z(), z(), z()],
            y_stage: z(),
            y_new: z(),
            fsal_valid: false,
            stats: StepStats::default(),
        }
    }

    /// Work counters so far.
    pub fn stats(&self) -> StepStats {
        self.stats
    }

    /// Forget the last stage (call after changing the state or the system from outside).
    pub fn invalidate(&mut self) {
        self.fsal_valid = false;
    }

    /// Integrate `y` from `t0` to `t1` (> t0), landing exactly on `t1`.
    pub fn integrate<S: OdeSystem>(
        &mut self,
        sys: &mut S,
        t0: f64,
        t1: f64,
        y: &mut [f64],
    ) -> Result<(), IntegrationError> {
        let n = y.len();
        debug_assert_eq!(n, self.atol.len());
        let mut t = t0;
        let span = t1 - t0;
        while t1 - t > 1e-12 * span.abs().max(1e-300) {
            let remaining = t1 - t;
            let mut h = self.h.min(self.h_max);
            let truncated = h >= remaining * (1.0 - 1e-9);
            if truncated {
                h = remaining;
            }
            if !self.fsal_valid {
                sys.rhs(t, y, &mut self.k[0]);
                self.stats.rhs_evals += 1;
                self.fsal_valid = true;
            }
            self.stages(sys, t, h, y);
            // Error estimate.
            let mut sum = 0.0;
            for (i, (&yi, &yn)) in y.iter().zip(&self.y_new).enumerate() {
                let e = h
                    * (E1 * self.k[0][i]
                        + E3 * self.k[2][i]
                        + E4 * self.k[3][i]
                        + E5 * self.k[4][i]
                        + E6 * self.k[5][i]
                        + E7 * self.k[6][i]);
                let sc = self.atol[i] + self.rtol * yi.abs().max(yn.abs());
                let r = e / sc;
                sum += r * r;
            }
            let err = (sum / n as f64).sqrt();
            if err.is_finite() && err <= 1.0 {
                y.copy_from_slice(&self.y_new);
                t = if truncated { t1 } else { t + h };
                self.k.swap(0, 6);
                self.stats.accepted += 1;
                if sys.accepted(t, y) {
                    self.fsal_valid = false;
                }
                let fac = if err > 0.0 { (0.9 * err.powf(-0.2)).clamp(0.2, 5.0) } else { 5.0 };
                let h_next = (h * fac).min(self.h_max);
                // A step shortened to hit t1 says nothing about the step the system allows.
                self.h = if truncated { self.h.max(h_next).min(self.h_max) } else { h_next };
            } else {
                self.stats.rejected += 1;
                let fac = if err.is_finite() { (0.9 * err.powf(-0.2)).clamp(0.2, 1.0) } else { 0.25 };
                self.h = h * fac;
                if self.h < self.h_min {
                    return Err(IntegrationError::StepTooSmall { t, h: self.h });
                }
            }
        }
        Ok(())
    }

    fn stages<S: OdeSystem>(&mut self, sys: &mut S, t: f64, h: f64, y: &[f64]) {
        let n = y.len();
        let [k1, k2, k3, k4, k5, k6, k7] = &mut self.k;
        let ys = &mut self.y_stage;
        for i in 0..n {
            ys[i] = y[i] + h * A21 * k1[i];
        }
        sys.rhs(t + C2 * h, ys, k2);
        for i in 0..n {
            ys[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        sys.rhs(t + C3 * h, ys, k3);
        for i in 0..n {
            ys[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        sys.rhs(t + C4 * h, ys, k4);
        for i in 0..n {
            ys[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        sys.rhs(t + C5 * h, ys, k5);
        for i in 0..n {
            ys[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        sys.rhs(t + h, ys, k6);
        let yn = &mut self.y_new;
        for i in 0..n {
            yn[i] = y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        sys.rhs(t + h, yn, k7);
        self.stats.rhs_evals += 6;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Decay;
    impl OdeSystem for Decay {
        fn rhs(&mut self, _t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = -y[0];
        }
    }

    struct Oscillator(f64);
    impl OdeSystem for Oscillator {
        fn rhs(&mut self, _t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = y[1];
            dy[1] = -self.0 * self.0 * y[0];
        }
    }

    #[test]
    fn dormand_prince_meets_its_tolerance() {
        let mut dp = DormandPrince::new(1e-9, vec![1e-12], 1e-3, 0.1);
        let mut y = [1.0];
        dp.integrate(&mut Decay, 0.0, 3.0, &mut y).unwrap();
        assert!((y[0] - (-3.0f64).exp()).abs() < 1e-8, "{}", y[0]);
        let w = 2.0 * std::f64::consts::PI * 5.0;
        let mut dp = DormandPrince::new(1e-8, vec![1e-10, 1e-8], 1e-4, 1e-2);
        let mut y = [1.0, 0.0];
        dp.integrate(&mut Oscillator(w), 0.0, 1.0, &mut y).unwrap();
        assert!((y[0] - 1.0).abs() < 1e-5, "{}", y[0]);
        // Adaptive: far fewer steps than a fixed step at the error bound would need.
        assert!(dp.stats().accepted < 2000 && dp.stats().accepted > 10);
    }

    #[test]
    fn stiff_decay_is_stable_through_rejections() {
        struct Stiff;
        impl OdeSystem for Stiff {
            fn rhs(&mut self, _t: f64, y: &[f64], dy: &mut [f64]) {
                dy[0] = -1e5 * (y[0] - 1.0);
            }
        }
        let mut dp = DormandPrince::new(1e-6, vec![1e-9], 1e-2, 1e-2);
        let mut y = [0.0];
        dp.integrate(&mut Stiff, 0.0, 0.05, &mut y).unwrap();
        assert!((y[0] - 1.0).abs() < 1e-5);
    }
}
