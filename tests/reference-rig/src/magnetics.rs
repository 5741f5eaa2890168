//! Magnetization laws of one piece of Terfenol-D (one radial shell of the rod).
//!
//! Every law is written as a differential susceptibility χ = dM/dH that depends on the
//! present field H, magnetization M, the direction of the field change (δ = ±1) and, for the
//! Preisach model, a memory of past extrema. The rig uses χ twice: to advance M (dM/dt =
//! χ dH/dt) and as the differential permeability μ0(1 + χ) of the field-diffusion equation.
//!
//! Laws:
//! * Jiles–Atherton, three variants (see [`JaVariant`]), all on the Langevin anhysteretic
//!   M_an = M_s L(H_e/a), L(x) = coth x − 1/x, with effective field H_e = H + α̃ M.
//! * Classical Preisach model with a product-Gaussian relay density and exact memory of
//!   extrema (wiping-out property), see [`PreisachParams`].
//! * Anhysteretic (no hysteresis): M = M_s L((H + α̃ M)/a).

use crate::integrator::{DormandPrince, OdeSystem};
use std::f64::consts::PI;

/// Vacuum permeability μ0 [H/m] (CODATA 2018).
pub const MU0: f64 = 1.256_637_062_12e-6;

/// Smallest differential susceptibility returned by any law. The 1986 J–A form can give
/// dM/dH < 0 just after a field reversal; the floor keeps μ0(1 + χ) > 0 so that the
/// diffusion equation stays well-posed.
pub const CHI_MIN: f64 = -0.5;
/// Largest differential susceptibility returned by any law (guards the J–A denominators).
pub const CHI_MAX: f64 = 1e5;

/// Langevin function L(x) = coth x − 1/x (series near 0).
pub fn langevin(x: f64) -> f64 {
    let ax = x.abs();
    if ax < 1e-2 {
        let x2 = x * x;
        x * (1.0 / 3.0 - x2 / 45.0 + 2.0 * x2 * x2 / 945.0)
    } else if ax > 30.0 {
        x.signum() - 1.0 / x
    } else {
        1.0 / x.tanh() - 1.0 / x
    }
}

/// Derivative L'(x) = 1/x² − 1/sinh² x (series near 0).
pub fn langevin_deriv(x: f64) -> f64 {
    let ax = x.abs();
    if ax < 1e-2 {
        let x2 = x * x;
        1.0 / 3.0 - x2 / 15.0 + 2.0 * x2 * x2 / 189.0
    } else if ax > 30.0 {
        1.0 / (x * x)
    } else {
        let s = x.sinh();
        1.0 / (x * x) - 1.0 / (s * s)
    }
}

/// Jiles–Atherton coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JaParams {
    /// Saturation magnetization M_s [A/m].
    pub ms_a_per_m: f64,
    /// Anhysteretic shape parameter a [A/m].
    pub a_a_per_m: f64,
    /// Pinning coefficient k [A/m].
    pub k_a_per_m: f64,
    /// Mean-field (domain coupling) coefficient α (1), before any stress contribution.
    pub alpha: f64,
    /// Reversibility c (1), 0 ≤ c < 1.
    pub c: f64,
}

/// Which Jiles–Atherton formulation (same five coefficients, different equations).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JaVariant {
    /// Jiles & Atherton, J. Magn. Magn. Mater. 61 (1986) 48:
    /// dM/dH = 1/(1+c) · (M_an − M)/(δk − α̃(M_an − M)) + c/(1+c) · dM_an/dH_e.
    /// No guard against the negative slope after a reversal (only the global floor
    /// [`CHI_MIN`]).
    Original1986,
    /// "Bulk" form with the (1 − c) weighting and the δ_M switch (Venkataraman 1999; Dapino,
    /// Smith & Flatau 2000): dM/dH = [(1−c) δ_M (M_an − M)/(δk − α̃(M_an − M)) + c M_an'] /
    /// (1 − α̃ c M_an'), δ_M = 1 if δ(M_an − M) > 0 else 0. The denominator makes the
    /// reversible part see the effective field.
    BulkVenkataraman,
    /// Inverse (flux-density-driven) form of Sadowski, Batistela & Bastos, IEEE Trans. Magn.
    /// 38 (2002) 797, with δ_M: M_irr = (M − c M_an)/(1 − c),
    /// dM_irr/dB_e = δ_M (M_an − M_irr)/(μ0 δ k),
    /// dM/dB = [(1−c) dM_irr/dB_e + (c/μ0) M_an'] / [1 + μ0(1−c)(1−α̃) dM_irr/dB_e + c(1−α̃) M_an'],
    /// converted to the field derivative with B = μ0(H + M): dM/dH = μ0 χ_B/(1 − μ0 χ_B).
    InverseSadowski,
}

impl JaVariant {
    /// All variants.
    pub const ALL: [JaVariant; 3] =
        [JaVariant::Original1986, JaVariant::BulkVenkataraman, JaVariant::InverseSadowski];

    /// Short name (used by the binary).
    pub fn name(self) -> &'static str {
        match self {
            JaVariant::Original1986 => "ja-original",
            JaVariant::BulkVenkataraman => "ja-bulk",
            JaVariant::InverseSadowski => "ja-inverse",
        }
    }
}

/// Preisach model on the (h_c, h_u) plane: relay coercivity h_c = (α − β)/2 ~ N(μ_c, s_c²)
/// truncated to h_c ≥ 0, interaction (bias) field h_u = (α + β)/2 ~ N(0, s_u²), independent;
/// plus a reversible part: M = M_s [(1 − ρ) y_P(H) + ρ tanh(H/h_r)], y_P ∈ [−1, 1].
/// A narrow coercivity distribution and a wide interaction distribution give the slanted,
/// narrow loops of Terfenol-D.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreisachParams {
    /// Saturation magnetization M_s [A/m].
    pub ms_a_per_m: f64,
    /// Mean relay coercivity μ_c [A/m].
    pub coercive_a_per_m: f64,
    /// Standard deviation s_c of the relay coercivity [A/m].
    pub coercive_spread_a_per_m: f64,
    /// Standard deviation s_u of the interaction field [A/m].
    pub interaction_spread_a_per_m: f64,
    /// Reversible fraction ρ (1), 0 ≤ ρ < 1.
    pub reversible_fraction: f64,
    /// Field scale h_r of the reversible part [A/m].
    pub reversible_field_a_per_m: f64,
}

fn normal_pdf(x: f64, mean: f64, sd: f64) -> f64 {
    let z = (x - mean) / sd;
    (-0.5 * z * z).exp() / (sd * (2.0 * PI).sqrt())
}

/// Standard normal distribution function (handles ±∞).
fn std_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

/// Everett function of the Gaussian (h_c, h_u) density, E(a, b) = weight of the triangle
/// {b ≤ β ≤ α ≤ a}. With μ(α, β) = f_c((α−β)/2) f_u((α+β)/2)/2:
/// ∂E/∂a(a, b) = ∫_0^{(a−b)/2} f_c(h) f_u(a − h) dh and −∂E/∂b(a, b) = ∫_0^{(a−b)/2} f_c(h)
/// f_u(b + h) dh. Each integrand is a product of two Gaussians in h, hence a Gaussian: both
/// derivatives are closed-form (normal density × difference of normal distribution
/// functions). E itself (only for checks) is a 1-D quadrature.
#[derive(Clone, Debug)]
struct Everett {
    mc: f64,
    sc: f64,
    su: f64,
    v: f64,
    s_star: f64,
    total: f64,
    lo: f64,
    hi: f64,
}

impl Everett {
    fn new(p: &PreisachParams) -> Self {
        let (mc, sc, su) = (p.coercive_a_per_m, p.coercive_spread_a_per_m, p.interaction_spread_a_per_m);
        let v = sc * sc + su * su;
        let hi = mc + 12.0 * sc + 12.0 * su;
        Everett { mc, sc, su, v, s_star: sc * su / v.sqrt(), total: std_cdf(mc / sc), lo: -hi, hi }
    }

    /// ∫_0^{hm} N(h; μ_c, s_c²) N(h; x0, s_u²) dh = N(x0; μ_c, V) [Φ((hm − m)/s*) − Φ(−m/s*)].
    fn gauss_product_integral(&self, x0: f64, hm: f64) -> f64 {
        let (sc2, su2) = (self.sc * self.sc, self.su * self.su);
        let m = (self.mc * su2 + x0 * sc2) / self.v;
        normal_pdf(x0, self.mc, self.v.sqrt()) * (std_cdf((hm - m) / self.s_star) - std_cdf(-m / self.s_star))
    }

    /// ∂E/∂a.
    fn de_da(&self, a: f64, b: f64) -> f64 {
        if a <= b {
            return 0.0;
        }
        // f_u(a − h) = N(h; a, s_u²).
        self.gauss_product_integral(a, 0.5 * (a - b))
    }

    /// −∂E/∂b.
    fn minus_de_db(&self, a: f64, b: f64) -> f64 {
        if a <= b || b == f64::NEG_INFINITY {
            return 0.0;
        }
        // f_u(b + h) = N(h; −b, s_u²).
        self.gauss_product_integral(-b, 0.5 * (a - b))
    }

    /// E(a, b) = ∫_0^{(a−b)/2} f_c(h) [F_u(a − h) − F_u(b + h)] dh (composite Simpson).
    fn e(&self, a: f64, b: f64) -> f64 {
        if a <= b {
            return 0.0;
        }
        let hm = (0.5 * (a - b)).min(self.mc + 12.0 * self.sc);
        let n = 600;
        let dh = hm / n as f64;
        let f = |h: f64| {
            let lower = if b == f64::NEG_INFINITY { 0.0 } else { std_cdf((b + h) / self.su) };
            normal_pdf(h, self.mc, self.sc) * (std_cdf((a - h) / self.su) - lower)
        };
        let mut sum = f(0.0) + f(hm);
        for i in 1..n {
            sum += if i % 2 == 1 { 4.0 } else { 2.0 } * f(i as f64 * dh);
        }
        sum * dh / 3.0
    }
}

/// Memory of the Preisach plane: the alternating dominant extrema M_1 > M_2 > … and
/// m_1 < m_2 < … stored as `[M_1, m_1, M_2, m_2, …]`, the direction of the running branch and
/// the present input. Starts at negative saturation (empty, decreasing).
#[derive(Clone, Debug, PartialEq)]
pub struct PreisachMemory {
    ext: Vec<f64>,
    increasing: bool,
    h: f64,
}

impl PreisachMemory {
    fn negative_saturation(lo: f64) -> Self {
        PreisachMemory { ext: Vec::new(), increasing: false, h: lo }
    }

    /// Number of stored extrema.
    pub fn depth(&self) -> usize {
        self.ext.len()
    }

    /// Move the input to `h_new`; a reversal is stored only once the input has retreated by
    /// more than `eps` from the last extreme.
    fn move_to(&mut self, h_new: f64, lo: f64, hi: f64, eps: f64) {
        if h_new == self.h {
            return;
        }
        let up = h_new > self.h;
        if up != self.increasing {
            if (h_new - self.h).abs() <= eps {
                return;
            }
            if !(up && self.ext.is_empty()) {
                self.ext.push(self.h);
            }
            self.increasing = up;
        }
        if up {
            while self.ext.len() >= 2 && h_new >= self.ext[self.ext.len() - 2] {
                self.ext.truncate(self.ext.len() - 2);
            }
        } else {
            while self.ext.len() >= 3 && h_new <= self.ext[self.ext.len() - 2] {
                self.ext.truncate(self.ext.len() - 2);
            }
        }
        self.h = h_new;
        if h_new >= hi {
            self.ext.clear();
            self.increasing = true;
        } else if h_new <= lo {
            self.ext.clear();
            self.increasing = false;
        }
    }
}

/// The state of one piece of material: field, magnetization and (Preisach only) memory.
#[derive(Clone, Debug, PartialEq)]
pub struct ShellState {
    /// Field H [A/m].
    pub h: f64,
    /// Magnetization M [A/m].
    pub m: f64,
    /// Preisach memory (None for the other laws).
    pub memory: Option<PreisachMemory>,
    /// Direction δ of the present branch (true: increasing field).
    pub up: bool,
    /// Extreme field reached on the present branch [A/m]; the direction reverses once the
    /// field has retreated from it by more than the material's reversal threshold.
    pub h_turn: f64,
}

#[derive(Clone, Debug)]
enum Kind {
    Ja(JaVariant),
    Anhysteretic,
    Preisach(PreisachParams, Box<Everett>),
}

/// A compiled magnetization law (coefficients checked, tables built).
#[derive(Clone, Debug)]
pub struct Material {
    kind: Kind,
    ja: JaParams,
    alpha_eff: f64,
    reversal_eps: f64,
}

/// Default reversal threshold [A/m] (see [`Material::with_reversal_threshold`]). The
/// integrator's jitter of the held field reaches a few A/m: at 2 A/m M̄ still ratcheted by
/// 2 % M_s (J–A bulk) and 25 % M_s (Preisach) over 0.15 s at a held drive, at 5 A/m it held
/// (test `magnetization_holds_while_the_field_is_held`); 20 A/m keeps a margin and is
/// ≤ 0.6 % of the default k, so it leaves every loop of interest unchanged.
pub const DEFAULT_REVERSAL_THRESHOLD: f64 = 20.0;

impl Material {
    /// A Jiles–Atherton law. `alpha_extra` is added to α (the stress term
    /// 9 λ_s σ / (2 μ0 M_s²) of the rig, 0 for the bare law).
    pub fn jiles_atherton(variant: JaVariant, params: JaParams, alpha_extra: f64) -> Self {
        Material {
            kind: Kind::Ja(variant),
            ja: params,
            alpha_eff: params.alpha + alpha_extra,
            reversal_eps: DEFAULT_REVERSAL_THRESHOLD,
        }
    }

    /// The anhysteretic (reversible, single-valued) Langevin law of `params`.
    pub fn anhysteretic(params: JaParams, alpha_extra: f64) -> Self {
        Material {
            kind: Kind::Anhysteretic,
            ja: params,
            alpha_eff: params.alpha + alpha_extra,
            reversal_eps: DEFAULT_REVERSAL_THRESHOLD,
        }
    }

    /// A Preisach law.
    pub fn preisach(params: PreisachParams) -> Self {
        let ev = Everett::new(&params);
        let ja =
            JaParams { ms_a_per_m: params.ms_a_per_m, a_a_per_m: 1.0, k_a_per_m: 1.0, alpha: 0.0, c: 0.0 };
        Material {
            kind: Kind::Preisach(params, Box::new(ev)),
            ja,
            alpha_eff: 0.0,
            reversal_eps: DEFAULT_REVERSAL_THRESHOLD,
        }
    }

    /// Set the reversal threshold ε [A/m]: the branch direction δ (and the Preisach memory)
    /// reverses only once the field has retreated by more than ε from the extreme of the
    /// present branch; smaller back-and-forth moves run reversibly along the present branch.
    /// Without it, the numerical noise of an explicit integrator in the stiff diffusion
    /// modes (a fraction of an A/m) would flip δ at every step, and laws without
    /// return-point memory (J–A) would ratchet M at a constant field.
    pub fn with_reversal_threshold(mut self, eps_a_per_m: f64) -> Self {
        self.reversal_eps = eps_a_per_m.max(0.0);
        self
    }

    /// Branch direction for the field `h`, given the state at the last accepted step.
    pub fn direction(&self, state: &ShellState, h: f64) -> bool {
        if state.up {
            h >= state.h_turn - self.reversal_eps
        } else {
            h > state.h_turn + self.reversal_eps
        }
    }

    /// Saturation magnetization [A/m].
    pub fn ms(&self) -> f64 {
        match &self.kind {
            Kind::Preisach(p, _) => p.ms_a_per_m,
            _ => self.ja.ms_a_per_m,
        }
    }

    /// The effective mean-field coefficient α̃ (J–A and anhysteretic laws).
    pub fn alpha_eff(&self) -> f64 {
        self.alpha_eff
    }

    /// The demagnetised state at H = 0, M = 0; for Preisach the memory holds an
    /// AC-demagnetised staircase (alternating extrema decaying by 0.8 per reversal; M = 0 by
    /// the symmetry of the density, up to the last, sub-A/m step).
    pub fn virgin(&self) -> ShellState {
        match &self.kind {
            Kind::Preisach(_, ev) => {
                let mut mem = PreisachMemory::negative_saturation(ev.lo);
                let mut amp = ev.hi;
                let mut sign = 1.0;
                while amp > 1.0 {
                    mem.move_to(sign * amp, ev.lo, ev.hi, 0.0);
                    amp *= 0.8;
                    sign = -sign;
                }
                mem.move_to(0.0, ev.lo, ev.hi, 0.0);
                ShellState { h: 0.0, m: 0.0, memory: Some(mem), up: true, h_turn: 0.0 }
            }
            _ => ShellState { h: 0.0, m: 0.0, memory: None, up: true, h_turn: 0.0 },
        }
    }

    /// M_an(H_e) and dM_an/dH_e for the J–A/anhysteretic coefficients.
    pub fn anhysteretic_curve(&self, he: f64) -> (f64, f64) {
        let p = &self.ja;
        let x = he / p.a_a_per_m;
        (p.ms_a_per_m * langevin(x), p.ms_a_per_m / p.a_a_per_m * langevin_deriv(x))
    }

    /// Differential susceptibility dM/dH at field `h`, magnetization `m`, for a field that
    /// is increasing (`up`) or decreasing. `state` supplies the Preisach memory (its `h` is
    /// the field at which the memory was last updated); it is ignored by the other laws.
    pub fn susceptibility(&self, state: &ShellState, h: f64, m: f64, up: bool) -> f64 {
        let chi = match &self.kind {
            Kind::Ja(v) => self.ja_chi(*v, h, m, up),
            Kind::Anhysteretic => {
                let (_, dman) = self.anhysteretic_curve(h + self.alpha_eff * m);
                dman / (1.0 - self.alpha_eff * dman).max(0.05)
            }
            Kind::Preisach(p, ev) => {
                let dy = match &state.memory {
                    Some(mem) => preisach_dydu(ev, mem, h, up),
                    None => 0.0,
                };
                let r = p.reversible_fraction;
                let hr = p.reversible_field_a_per_m;
                let sech = 1.0 / (h / hr).cosh();
                p.ms_a_per_m * ((1.0 - r) * dy + r * sech * sech / hr)
            }
        };
        if chi.is_nan() {
            0.0
        } else {
            chi.clamp(CHI_MIN, CHI_MAX)
        }
    }

    fn ja_chi(&self, v: JaVariant, h: f64, m: f64, up: bool) -> f64 {
        let p = &self.ja;
        let alpha = self.alpha_eff;
        let c = p.c;
        let k = p.k_a_per_m;
        let delta = if up { 1.0 } else { -1.0 };
        let (man, dman) = self.anhysteretic_curve(h + alpha * m);
        // Keep δk − α̃Δ on the side of δ, at least 5 % of k (guards the pole of the J–A
        // denominator; inactive for the default coefficients except far from the loop).
        let guard = |den: f64| if delta * den < 0.05 * k { delta * 0.05 * k } else { den };
        match v {
            JaVariant::Original1986 => {
                let d = man - m;
                let den = guard(delta * k - alpha * d);
                (d / den) / (1.0 + c) + c / (1.0 + c) * dman
            }
            JaVariant::BulkVenkataraman => {
                let d = man - m;
                let dm = if delta * d > 0.0 { 1.0 } else { 0.0 };
                let den = guard(delta * k - alpha * d);
                ((1.0 - c) * dm * d / den + c * dman) / (1.0 - alpha * c * dman).max(0.05)
            }
            JaVariant::InverseSadowski => {
                let mirr = (m - c * man) / (1.0 - c);
                let d = man - mirr;
                let dm = if delta * d > 0.0 { 1.0 } else { 0.0 };
                let dmirr_dbe = dm * d / (MU0 * delta * k);
                let num = (1.0 - c) * dmirr_dbe + c / MU0 * dman;
                let den = 1.0 + MU0 * (1.0 - c) * (1.0 - alpha) * dmirr_dbe + c * (1.0 - alpha) * dman;
                let chi_b = num / den;
                MU0 * chi_b / (1.0 - MU0 * chi_b).max(0.02)
            }
        }
    }

    /// M from the Everett integrals of the memory (Preisach only; None for the other laws).
    /// The rig integrates M as an ODE with the closed-form dM/dH; this sum of Everett
    /// integrals is the independent check of that integration.
    pub fn algebraic_m(&self, state: &ShellState) -> Option<f64> {
        match (&self.kind, &state.memory) {
            (Kind::Preisach(p, ev), Some(mem)) => {
                let y = 2.0 * preisach_p(ev, mem) / ev.total - 1.0;
                let r = p.reversible_fraction;
                Some(p.ms_a_per_m * ((1.0 - r) * y + r * (mem.h / p.reversible_field_a_per_m).tanh()))
            }
            _ => None,
        }
    }

    /// Register `h` and `m` as the present field and magnetization of `state` (for
    /// Preisach: memory update with reversal detection and wiping out). Returns true if the
    /// Preisach memory changed shape (a reversal was stored or extrema were wiped out); M is
    /// then set to the Everett sum of the new memory.
    ///
    /// Why the Preisach M is reset there: inside the reversal threshold ε the branch (and χ)
    /// of the old direction is kept, so the integrated M runs back along the old branch until
    /// the reversal is confirmed, and every turn of the field would leave (χ_branch −
    /// χ_reversed) ε behind: 340 A/m per cycle of a ±200 A/m minor loop about 20 kA/m, a
    /// steady ratchet where the relay plane returns exactly to its starting point (test
    /// `preisach_minor_loops_close_when_stepped_in_time`). Between reversals the integration
    /// along one branch is exact to the integrator's tolerance; moves back and forth inside ε
    /// retrace the same branch and leave nothing behind.
    pub fn commit(&self, state: &mut ShellState, h: f64, m: f64) -> bool {
        let up = self.direction(state, h);
        if up != state.up || (up && h > state.h_turn) || (!up && h < state.h_turn) {
            state.h_turn = h;
        }
        state.up = up;
        state.h = h;
        state.m = m;
        if let (Kind::Preisach(..), Some(mem)) = (&self.kind, state.memory.as_mut()) {
            let (lo, hi) = self.preisach_support();
            let (depth, inc) = (mem.ext.len(), mem.increasing);
            mem.move_to(h, lo, hi, self.reversal_eps);
            let reshaped = mem.ext.len() != depth || mem.increasing != inc;
            if reshaped {
                state.m = self.algebraic_m(state).unwrap_or(m);
            }
            return reshaped;
        }
        false
    }

    /// Preisach only (None for the other laws): M at the field `h`, reached from the committed
    /// state along its committed branch, M(h) = state.m + ∫ χ dH from state.h to h, integrated
    /// on the path itself (three-point Gauss–Legendre per piece, split where the branch kinks
    /// at a stored extremum).
    ///
    /// Why not the integrator's M: its stages jitter around the accepted field (stiff
    /// diffusion modes), and where the branch kinks, at a stored extremum (the minor loop
    /// closes and the slope jumps from the minor loop's to the outer branch's), the stages
    /// that overshoot it see the outer branch's χ ≈ 19 and those below it χ ≈ 1.8: the
    /// jitter is rectified into M. The top of a ±200 A/m sine about 20 kA/m, where the field
    /// dwells at the extremum of the previous cycle, gained 17 kA/m in the outer shell per
    /// cycle. χ as a function of H along one branch has an exact antiderivative (the Everett
    /// function), so integrating it on the accepted path leaves no jitter behind.
    pub fn branch_m(&self, state: &ShellState, h: f64) -> Option<f64> {
        let (Kind::Preisach(..), Some(mem)) = (&self.kind, &state.memory) else {
            return None;
        };
        let (a, b) = (state.h, h);
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        // Gauss–Legendre nodes and weights on [−1, 1].
        const X: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
        const W: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
        let piece = |from: f64, to: f64| {
            let (mid, half) = (0.5 * (from + to), 0.5 * (to - from));
            X.iter()
                .zip(W)
                .map(|(x, wt)| wt * half * self.susceptibility(state, mid + half * x, state.m, state.up))
                .sum::<f64>()
        };
        // Called at every accepted step: the step rarely crosses a stored extremum, so the
        // split (and its allocation) is only made when it does.
        let integral = if mem.ext.iter().any(|&e| e > lo && e < hi) {
            let mut cuts: Vec<f64> = mem.ext.iter().copied().filter(|&e| e > lo && e < hi).collect();
            cuts.push(lo);
            cuts.push(hi);
            cuts.sort_by(f64::total_cmp);
            cuts.windows(2).map(|w| piece(w[0], w[1])).sum()
        } else {
            piece(lo, hi)
        };
        Some(state.m + if b >= a { integral } else { -integral })
    }

    fn preisach_support(&self) -> (f64, f64) {
        match &self.kind {
            Kind::Preisach(_, ev) => (ev.lo, ev.hi),
            _ => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }

    /// Move `state` quasi-statically (rate-independent, no eddy currents) to the field
    /// `h_target`, integrating dM/dH over H with the adaptive Dormand–Prince integrator
    /// (for Preisach the memory is updated at the end; reversal and wiping out within the
    /// sweep are handled by the branch selection of [`Material::susceptibility`]). Returns
    /// `n_points` (H, M) samples along the way, ending at `h_target`.
    pub fn sweep_to(&self, state: &mut ShellState, h_target: f64, n_points: usize) -> Vec<(f64, f64)> {
        let n = n_points.max(1);
        let h0 = state.h;
        let mut out = Vec::with_capacity(n);
        let dir = if h_target >= h0 { 1.0 } else { -1.0 };
        let span = (h_target - h0).abs();
        let mut sys = Sweep { mat: self, state: state.clone(), h0, dir };
        let mut dp = DormandPrince::new(1e-8, vec![1e-4], span.max(1.0) / 100.0, span.max(1.0) / 10.0);
        let mut y = [state.m];
        let mut s_prev = 0.0;
        for i in 1..=n {
            let s = span * i as f64 / n as f64;
            if s > s_prev {
                // A quasi-static sweep cannot fail for the clamped χ; keep the last value if
                // it ever did.
                let _ = dp.integrate(&mut sys, s_prev, s, &mut y);
            }
            s_prev = s;
            out.push((h0 + dir * s, y[0]));
        }
        self.commit(state, h_target, y[0]);
        // A sweep is monotone: its end is the extreme of a branch in its direction.
        state.up = dir > 0.0;
        state.h_turn = h_target;
        out
    }
}

struct Sweep<'a> {
    mat: &'a Material,
    state: ShellState,
    h0: f64,
    dir: f64,
}

impl OdeSystem for Sweep<'_> {
    fn rhs(&mut self, s: f64, y: &[f64], dy: &mut [f64]) {
        let h = self.h0 + self.dir * s;
        dy[0] = self.dir * self.mat.susceptibility(&self.state, h, y[0], self.dir > 0.0);
    }
}

/// P = weight of the relays that are up, for the memory's present input.
fn preisach_p(ev: &Everett, mem: &PreisachMemory) -> f64 {
    let e = &mem.ext;
    let n = e.len();
    if !mem.increasing && n == 0 {
        return 0.0;
    }
    let complete = if mem.increasing { n / 2 } else { (n - 1) / 2 };
    let mut p = 0.0;
    let mut m_prev = f64::NEG_INFINITY;
    for i in 0..complete {
        let (mx, mn) = (e[2 * i], e[2 * i + 1]);
        p += ev.e(mx, m_prev) - ev.e(mx, mn);
        m_prev = mn;
    }
    if mem.increasing {
        p += ev.e(mem.h, m_prev);
    } else {
        let mx = e[n - 1];
        p += ev.e(mx, m_prev) - ev.e(mx, mem.h);
    }
    p
}

/// dy_P/du at input `h` moving `up`/down from the memory's state, without changing it: a
/// reversal at the memory's present input and any wiping out are applied virtually.
fn preisach_dydu(ev: &Everett, mem: &PreisachMemory, h: f64, up: bool) -> f64 {
    let base = &mem.ext;
    let extra = if up == mem.increasing || (up && base.is_empty()) { None } else { Some(mem.h) };
    let len0 = base.len() + usize::from(extra.is_some());
    let at = |i: usize| if i < base.len() { base[i] } else { mem.h };
    let mut len = len0;
    let scale = 2.0 / ev.total;
    if up {
        while len >= 2 && h >= at(len - 2) {
            len -= 2;
        }
        let anchor = if len >= 1 { at(len - 1) } else { f64::NEG_INFINITY };
        scale * ev.de_da(h, anchor)
    } else {
        if len == 0 {
            return 0.0;
        }
        while len >= 3 && h <= at(len - 2) {
            len -= 2;
        }
        scale * ev.minus_de_db(at(len - 1), h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn langevin_series_and_closed_form_agree() {
        for &x in &[0.0099, 0.0101, 0.5, 3.0, 29.9, 30.1] {
            let h = 1e-6;
            let num = (langevin(x + h) - langevin(x - h)) / (2.0 * h);
            assert!((num - langevin_deriv(x)).abs() < 1e-6, "x = {x}");
        }
        assert!((langevin(1e-3) - (1e-3 / 3.0 - 1e-9 / 45.0)).abs() < 1e-15);
        assert!((langevin(-2.0) + langevin(2.0)).abs() < 1e-15);
    }

    fn preisach_params() -> PreisachParams {
        PreisachParams {
            ms_a_per_m: 7.6e5,
            coercive_a_per_m: 3000.0,
            coercive_spread_a_per_m: 1500.0,
            interaction_spread_a_per_m: 25e3,
            reversible_fraction: 0.1,
            reversible_field_a_per_m: 30e3,
        }
    }

    #[test]
    fn everett_total_and_derivatives_are_consistent() {
        let ev = Everett::new(&preisach_params());
        // Everything switched: E(+∞, −∞) = P(h_c ≥ 0).
        assert!((ev.e(ev.hi, f64::NEG_INFINITY) - ev.total).abs() < 1e-7);
        for &(a, b) in &[(5000.0, -12000.0), (30e3, 20e3), (-4000.0, -9000.0)] {
            let d = 1.0;
            let num_a = (ev.e(a + d, b) - ev.e(a - d, b)) / (2.0 * d);
            let num_b = -(ev.e(a, b + d) - ev.e(a, b - d)) / (2.0 * d);
            assert!((num_a - ev.de_da(a, b)).abs() < 1e-10, "{num_a} vs {}", ev.de_da(a, b));
            assert!((num_b - ev.minus_de_db(a, b)).abs() < 1e-10, "{num_b} vs {}", ev.minus_de_db(a, b));
        }
    }

    #[test]
    fn preisach_ode_matches_everett_sum_and_has_return_point_memory() {
        let p = preisach_params();
        let mat = Material::preisach(p);
        let mut s = mat.virgin();
        let mut at_5k = Vec::new();
        let mut depth_before_last = 0;
        for &h in &[60e3, -20e3, 40e3, 5e3, 30e3, 5e3, 20e3, 5e3, 50e3, 0.0, -60e3] {
            if h == -60e3 {
                depth_before_last = s.memory.as_ref().unwrap().depth();
            }
            mat.sweep_to(&mut s, h, 40);
            let alg = mat.algebraic_m(&s).unwrap();
            assert!((alg - s.m).abs() < 1e-4 * p.ms_a_per_m, "H = {h}: ODE {} vs Everett {alg}", s.m);
            if h == 5e3 {
                at_5k.push(s.m);
            }
        }
        // Returning to the reversal point 5 kA/m after minor loops gives the same M.
        assert!((at_5k[0] - at_5k[1]).abs() < 1e-4 * p.ms_a_per_m);
        assert!((at_5k[0] - at_5k[2]).abs() < 1e-4 * p.ms_a_per_m);
        // Going below −20 kA/m wiped out the minimum −20 kA/m and the maximum 50 kA/m.
        assert_eq!(s.memory.as_ref().unwrap().depth() + 2, depth_before_last);
    }
}
