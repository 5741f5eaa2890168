//! Dormand–Prince 5(4) with error control and the 4th-order continuous extension
//! (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4–II.6, the coefficients of their `DOPRI5`).
//!
//! Written out here (about 150 lines) rather than taken from a crate because the rig needs
//! three things the crates' fixed-grid output does not give: the dense output at arbitrary
//! (delayed) times, per-state absolute tolerances, and step boundaries placed exactly at the
//! reversals of the field (event location) and at the drive's discontinuities.

/// One accepted step with everything its continuous extension needs.
#[derive(Clone, Debug)]
pub struct Step {
    /// Start time.
    pub t0: f64,
    /// Step size.
    pub h: f64,
    /// The five coefficient vectors of the continuous extension.
    rcont: [Vec<f64>; 5],
}

impl Step {
    /// The dense-output state at time `t` in `[t0, t0 + h]` (4th order, C¹ across steps).
    pub fn eval(&self, t: f64, out: &mut [f64]) {
        let th = if self.h > 0.0 { (t - self.t0) / self.h } else { 1.0 };
        let th1 = 1.0 - th;
        let [r1, r2, r3, r4, r5] = &self.rcont;
        for i in 0..out.len() {
            out[i] = r1[i] + th * (r2[i] + th1 * (r3[i] + th * (r4[i] + th1 * r5[i])));
        }
    }
}

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
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// Work space of one Dormand–Prince step.
pub struct Dopri {
    n: usize,
    k: [Vec<f64>; 7],
    ytmp: Vec<f64>,
    /// The state at the end of the last trial step.
    pub y1: Vec<f64>,
    /// The derivative at the end of the last trial step (FSAL).
    pub k7: Vec<f64>,
}

impl Dopri {
    /// Work space for `n` states.
    pub fn new(n: usize) -> Dopri {
        let z = || vec![0.0; n];
        Dopri { n, k: [z(), z(), z(), z(), z(), z(), z()], ytmp: z(), y1: z(), k7: z() }
    }

    /// One trial step from (t, y) with derivative `k1` there and size `h`; returns the scaled
    /// RMS error estimate (accept when ≤ 1). `f(t, y, dy)` is the right-hand side.
    #[allow(clippy::too_many_arguments)]
    pub fn try_step<F: FnMut(f64, &[f64], &mut [f64])>(
        &mut self,
        f: &mut F,
        t: f64,
        y: &[f64],
        k1: &[f64],
        h: f64,
        atol: &[f64],
        rtol: f64,
    ) -> f64 {
        let n = self.n;
        self.k[0].copy_from_slice(k1);
        macro_rules! stage {
            ($dst:expr, $c:expr, $($a:expr => $j:expr),+) => {{
                for i in 0..n {
                    self.ytmp[i] = y[i] + h * (0.0 $(+ $a * self.k[$j][i])+);
                }
                let mut d = std::mem::take(&mut self.k[$dst]);
                f(t + $c * h, &self.ytmp, &mut d);
                self.k[$dst] = d;
            }};
        }
        stage!(1, C2, A21 => 0);
        stage!(2, C3, A31 => 0, A32 => 1);
        stage!(3, C4, A41 => 0, A42 => 1, A43 => 2);
        stage!(4, C5, A51 => 0, A52 => 1, A53 => 2, A54 => 3);
        stage!(5, 1.0, A61 => 0, A62 => 1, A63 => 2, A64 => 3, A65 => 4);
        for i in 0..n {
            self.y1[i] = y[i]
                + h * (A71 * self.k[0][i]
                    + A73 * self.k[2][i]
                    + A74 * self.k[3][i]
                    + A75 * self.k[4][i]
                    + A76 * self.k[5][i]);
        }
        let mut d = std::mem::take(&mut self.k[6]);
        f(t + h, &self.y1, &mut d);
        self.k[6] = d;
        self.k7.copy_from_slice(&self.k[6]);
        let mut sum = 0.0;
        for i in 0..n {
            let e = h
                * (E1 * self.k[0][i]
                    + E3 * self.k[2][i]
                    + E4 * self.k[3][i]
                    + E5 * self.k[4][i]
                    + E6 * self.k[5][i]
                    + E7 * self.k[6][i]);
            let sc = atol[i] + rtol * y[i].abs().max(self.y1[i].abs());
            sum += (e / sc) * (e / sc);
        }
        (sum / n as f64).sqrt()
    }

    /// The continuous extension of the last trial step (call after `try_step` accepted it).
    pub fn dense(&self, t: f64, y: &[f64], h: f64) -> Step {
        let n = self.n;
        let mut r = [y.to_vec(), vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for i in 0..n {
            let ydiff = self.y1[i] - y[i];
            let bspl = h * self.k[0][i] - ydiff;
            r[1][i] = ydiff;
            r[2][i] = bspl;
            r[3][i] = ydiff - h * self.k[6][i] - bspl;
            r[4][i] = h
                * (D1 * self.k[0][i]
                    + D3 * self.k[2][i]
                    + D4 * self.k[3][i]
                    + D5 * self.k[4][i]
                    + D6 * self.k[5][i]
                    + D7 * self.k[6][i]);
        }
        Step { t0: t, h, rcont: r }
    }
}

/// Step-size factor from an error estimate (order 5 controller with safety 0.9).
pub fn step_factor(err: f64, rejected_before: bool) -> f64 {
    let fac = if err == 0.0 { 10.0 } else { 0.9 * err.powf(-0.2) };
    let hi = if rejected_before { 1.0 } else { 10.0 };
    fac.clamp(0.2, hi)
}
