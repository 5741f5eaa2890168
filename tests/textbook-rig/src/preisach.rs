//! Preisach relay plane with the documented Lorentzian density, its Everett function computed
//! accurately (closed form in one coordinate, adaptive Gauss–Kronrod in the other), and the
//! memory as the list of dominant alternating extrema (Mayergoyz's wiping-out rule).

use crate::params::PreisachParams;

/// Lorentzian shape L(x) = 1/(1 + x²).
fn lor(x: f64) -> f64 {
    1.0 / (1.0 + x * x)
}

const XGK: [f64; 8] = [
    0.991_455_371_120_812_6,
    0.949_107_912_342_758_5,
    0.864_864_423_359_769_1,
    0.741_531_185_599_394_4,
    0.586_087_235_467_691_1,
    0.405_845_151_377_397_2,
    0.207_784_955_007_898_5,
    0.0,
];
const WGK: [f64; 8] = [
    0.022_935_322_010_529_22,
    0.063_092_092_629_978_55,
    0.104_790_010_322_250_2,
    0.140_653_259_715_525_9,
    0.169_004_726_639_267_9,
    0.190_350_578_064_785_4,
    0.204_432_940_075_298_9,
    0.209_482_141_084_728_8,
];
const WG: [f64; 4] =
    [0.129_484_966_168_869_7, 0.279_705_391_489_276_7, 0.381_830_050_505_118_9, 0.417_959_183_673_469_4];

fn gk15<F: Fn(f64) -> f64>(f: &F, a: f64, b: f64) -> (f64, f64) {
    let c = 0.5 * (a + b);
    let hl = 0.5 * (b - a);
    let fc = f(c);
    let mut k = fc * WGK[7];
    let mut g = fc * WG[3];
    for j in 0..7 {
        let x = hl * XGK[j];
        let s = f(c - x) + f(c + x);
        k += WGK[j] * s;
        if j % 2 == 1 {
            g += WG[j / 2] * s;
        }
    }
    (k * hl, ((k - g) * hl).abs())
}

/// Adaptive Gauss–Kronrod 7–15 to an absolute tolerance.
pub fn integrate<F: Fn(f64) -> f64>(f: &F, a: f64, b: f64, tol: f64) -> f64 {
    fn rec<F: Fn(f64) -> f64>(f: &F, a: f64, b: f64, tol: f64, depth: u32) -> f64 {
        let (v, e) = gk15(f, a, b);
        if e <= tol || depth > 40 || (b - a).abs() < 1e-12 * (a.abs() + b.abs() + 1.0) {
            return v;
        }
        let m = 0.5 * (a + b);
        rec(f, a, m, 0.5 * tol, depth + 1) + rec(f, m, b, 0.5 * tol, depth + 1)
    }
    if b <= a {
        return 0.0;
    }
    rec(f, a, b, tol, 0)
}

/// The Everett function and the plane's geometry.
#[derive(Clone, Debug)]
pub struct Everett {
    hc: f64,
    sigma: f64,
    sigma_u: Option<f64>,
    /// Plane half-extent H_max.
    pub hm: f64,
    /// Total measure of the plane.
    pub total: f64,
    tol: f64,
}

impl Everett {
    /// The Everett function of the parameters' density.
    pub fn new(p: &PreisachParams) -> Everett {
        let mut e = Everett {
            hc: p.coercive_a_per_m,
            sigma: p.spread_a_per_m,
            sigma_u: p.interaction_spread_a_per_m,
            hm: p.h_max_a_per_m,
            total: 1.0,
            tol: 0.0,
        };
        e.tol = 0.0;
        // First pass with a relative tolerance on a rough scale, then fix the tolerance.
        let rough = e.raw(e.hm, -e.hm, 1e-6 * e.hm * e.hm);
        e.tol = 1e-13 * rough;
        e.total = e.raw(e.hm, -e.hm, e.tol);
        e
    }

    /// Measure (density integral) of the triangle {b ≤ β ≤ α ≤ a}, not normalised.
    fn raw(&self, a: f64, b: f64, tol: f64) -> f64 {
        if a <= b {
            return 0.0;
        }
        match self.sigma_u {
            Some(su) => {
                // α = u + h, β = u − h, dα dβ = 2 dh du; closed form in u.
                let f = |h: f64| {
                    2.0 * lor((h - self.hc) / self.sigma)
                        * su
                        * (((a - h) / su).atan() - ((b + h) / su).atan())
                };
                integrate(&f, 0.0, 0.5 * (a - b), tol)
            }
            None => {
                // L((α − h_c)/σ) L((β + h_c)/σ); closed form in α from β to a.
                let s = self.sigma;
                let ta = ((a - self.hc) / s).atan();
                let f = |beta: f64| lor((beta + self.hc) / s) * s * (ta - ((beta - self.hc) / s).atan());
                integrate(&f, b, a, tol)
            }
        }
    }

    /// Everett function E(a, b): the measure of {b ≤ β ≤ α ≤ a}, normalised to the plane's total.
    pub fn e(&self, a: f64, b: f64) -> f64 {
        self.raw(a, b, self.tol) / self.total
    }
}

/// Relay-plane memory: alternating dominant extrema x₀ = −H_max (a minimum), x₁ (max), x₂ (min), …;
/// the last one is the running input. The up measure is Σ_j term_j with term_j = +E(x_j, x_{j−1})
/// for odd j, −E(x_{j−1}, x_j) for even j.
#[derive(Clone, Debug)]
pub struct Memory {
    x: Vec<f64>,
    prefix: Vec<f64>,
}

fn term(ev: &Everett, j: usize, prev: f64, xj: f64) -> f64 {
    if j % 2 == 1 {
        ev.e(xj, prev)
    } else {
        -ev.e(prev, xj)
    }
}

impl Memory {
    /// Negative saturation.
    pub fn negative(ev: &Everett) -> Memory {
        Memory { x: vec![-ev.hm], prefix: vec![0.0] }
    }

    fn running_dir(&self) -> f64 {
        let n = self.x.len() - 1;
        if n % 2 == 1 {
            1.0
        } else {
            -1.0
        }
    }

    fn wipe(&self, mut m: usize, h: f64) -> usize {
        loop {
            if m % 2 == 1 {
                if m >= 3 && h >= self.x[m - 2] {
                    m -= 2;
                    continue;
                }
            } else if m >= 2 && h <= self.x[m - 2] {
                m -= 2;
                continue;
            }
            return m;
        }
    }

    /// Up measure (in [0, 1]) if the input moved to `h` in direction `delta` from the memory.
    pub fn up(&self, ev: &Everett, h: f64, delta: f64) -> f64 {
        let h = h.clamp(-ev.hm, ev.hm);
        let n = self.x.len() - 1;
        if delta == self.running_dir() || (n == 0 && delta < 0.0) {
            let m = self.wipe(n, h);
            if m == 0 {
                return 0.0;
            }
            self.prefix[m - 1] + term(ev, m, self.x[m - 1], h)
        } else {
            let m = self.wipe(n + 1, h);
            if m == 0 {
                return 0.0;
            }
            let p = if m - 1 == n {
                if n == 0 {
                    0.0
                } else {
                    self.prefix[n - 1] + term(ev, n, self.x[n - 1], self.x[n])
                }
            } else {
                self.prefix[m - 1]
            };
            p + term(ev, m, self.x[m - 1], h)
        }
    }

    /// Move the input to `h` in direction `delta` and keep the result.
    pub fn commit(&mut self, ev: &Everett, h: f64, delta: f64) {
        let h = h.clamp(-ev.hm, ev.hm);
        let n = self.x.len() - 1;
        if !(delta == self.running_dir() || (n == 0 && delta < 0.0)) {
            if n >= 1 {
                let p = self.prefix[n - 1] + term(ev, n, self.x[n - 1], self.x[n]);
                self.prefix.push(p);
            }
            self.x.push(h);
        }
        let n = self.x.len() - 1;
        let m = self.wipe(n, h);
        self.x.truncate(m);
        self.x.push(h);
        self.prefix.truncate(m.max(1));
    }

    /// Number of stored extrema (for statistics).
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether only the saturation reference is stored.
    pub fn is_empty(&self) -> bool {
        self.x.len() <= 1
    }

    /// AC-demagnetised state around `centre`: a decaying alternation of `k` reversals from
    /// ±H_max (linear decay), which approximates the line u = centre of the ideal state with
    /// steps of H_max/k. Ends with the input at `centre`.
    pub fn ac_demagnetised(ev: &Everett, centre: f64, k: usize) -> Memory {
        let mut m = Memory::negative(ev);
        let mut dir = 1.0;
        for j in 0..k {
            let amp = ev.hm * (1.0 - j as f64 / k as f64);
            let h = (centre + dir * amp).clamp(-ev.hm, ev.hm);
            m.commit(ev, h, dir);
            dir = -dir;
        }
        m.commit(ev, centre, dir);
        m
    }
}
