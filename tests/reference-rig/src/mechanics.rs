//! Two-degree-of-freedom mechanics of the actuator.
//!
//! Chain: housing (fixed) — rod (spring k1 = E A / L, damper c1, its natural length changed
//! by the free strain: x_free = L (λ + ε_T)) — head mass m1 (rod's share + end cap) — output
//! stem (spring k2, damper c2) — output mass m2 — preload spring k_s and damper c_s to the
//! housing. The output displacement is x2.
//!
//! m1 ẍ1 = −k1 (x1 − x_free) − c1 ẋ1 − k2 (x1 − x2) − c2 (ẋ1 − ẋ2)
//! m2 ẍ2 = −k2 (x2 − x1) − c2 (ẋ2 − ẋ1) − k_s x2 − c_s ẋ2
//!
//! With the second mode switched off the stem is rigid (x1 = x2, one mass m1 + m2).
//! Lumped-parameter model in the spirit of the rod/output-rod chain of the cited vibrator
//! paper (their Eqs. 8–10) and of any two-mass textbook model (e.g. S. S. Rao, *Mechanical
//! Vibrations*, ch. 5).

/// Mechanical parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mechanics {
    /// Head mass m1 (end cap + one third of the rod) (kg).
    pub m1_kg: f64,
    /// Output mass m2 (output stem, load) (kg).
    pub m2_kg: f64,
    /// Stiffness k2 of the output stem between m1 and m2 [N/m].
    pub k2_n_per_m: f64,
    /// Stiffness k_s of the preload spring from m2 to the housing [N/m].
    pub ks_n_per_m: f64,
    /// Damping c1 of the rod [N s/m].
    pub c1_n_s_per_m: f64,
    /// Damping c2 of the stem [N s/m].
    pub c2_n_s_per_m: f64,
    /// Damping c_s of the preload spring [N s/m].
    pub cs_n_s_per_m: f64,
}

impl Mechanics {
    /// Accelerations (ẍ1, ẍ2) for the rod stiffness `k1`, free displacement `x_free` and
    /// state `[x1, v1, x2, v2]`.
    pub fn accelerations(&self, k1: f64, x_free: f64, s: [f64; 4], two_modes: bool) -> (f64, f64) {
        let [x1, v1, x2, v2] = s;
        if two_modes {
            let f_stem = self.k2_n_per_m * (x1 - x2) + self.c2_n_s_per_m * (v1 - v2);
            let a1 = (-k1 * (x1 - x_free) - self.c1_n_s_per_m * v1 - f_stem) / self.m1_kg;
            let a2 = (f_stem - self.ks_n_per_m * x2 - self.cs_n_s_per_m * v2) / self.m2_kg;
            (a1, a2)
        } else {
            let a = (-k1 * (x1 - x_free)
                - self.c1_n_s_per_m * v1
                - self.ks_n_per_m * x1
                - self.cs_n_s_per_m * v1)
                / (self.m1_kg + self.m2_kg);
            (a, a)
        }
    }

    /// Static positions (x1, x2) for a constant free displacement.
    pub fn static_positions(&self, k1: f64, x_free: f64, two_modes: bool) -> (f64, f64) {
        let (k2, ks) = (self.k2_n_per_m, self.ks_n_per_m);
        if two_modes {
            let x1 = k1 * x_free / (k1 + k2 * ks / (k2 + ks));
            (x1, k2 * x1 / (k2 + ks))
        } else {
            let x = k1 * x_free / (k1 + ks);
            (x, x)
        }
    }

    /// Undamped natural frequencies (Hz) (lower, upper) of the two-mass chain for rod
    /// stiffness `k1`.
    pub fn natural_frequencies_hz(&self, k1: f64) -> (f64, f64) {
        let (m1, m2, k2, ks) = (self.m1_kg, self.m2_kg, self.k2_n_per_m, self.ks_n_per_m);
        let a = (k1 + k2) / m1;
        let d = (k2 + ks) / m2;
        let tr = a + d;
        let det = a * d - (k2 / m1) * (k2 / m2);
        let disc = (tr * tr - 4.0 * det).max(0.0).sqrt();
        let w = |l: f64| l.max(0.0).sqrt() / (2.0 * std::f64::consts::PI);
        (w(0.5 * (tr - disc)), w(0.5 * (tr + disc)))
    }

    /// Steady-state complex gain X2/X_free at `f_hz` as (magnitude, phase (rad)), from the
    /// same equations in the frequency domain.
    pub fn frequency_response(&self, k1: f64, f_hz: f64, two_modes: bool) -> (f64, f64) {
        let w = 2.0 * std::f64::consts::PI * f_hz;
        type C = (f64, f64);
        let mul = |a: C, b: C| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
        let sub = |a: C, b: C| (a.0 - b.0, a.1 - b.1);
        let div = |a: C, b: C| {
            let d = b.0 * b.0 + b.1 * b.1;
            ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
        };
        let (m1, m2) = (self.m1_kg, self.m2_kg);
        let (c1, c2, cs) = (self.c1_n_s_per_m, self.c2_n_s_per_m, self.cs_n_s_per_m);
        let (k2, ks) = (self.k2_n_per_m, self.ks_n_per_m);
        let g = if two_modes {
            let a11: C = (k1 + k2 - w * w * m1, w * (c1 + c2));
            let a12: C = (-k2, -w * c2);
            let a22: C = (k2 + ks - w * w * m2, w * (c2 + cs));
            // [a11 a12; a12 a22] [X1; X2] = [k1; 0] → X2 = −a12 k1 / det.
            let det = sub(mul(a11, a22), mul(a12, a12));
            div(mul((-a12.0, -a12.1), (k1, 0.0)), det)
        } else {
            let den: C = (k1 + ks - w * w * (m1 + m2), w * (c1 + cs));
            div((k1, 0.0), den)
        };
        ((g.0 * g.0 + g.1 * g.1).sqrt(), g.1.atan2(g.0))
    }
}
