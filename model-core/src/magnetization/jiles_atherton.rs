//! Jiles–Atherton hysteresis in three published variants ([`JaVariant`]; the equations with
//! their papers are in `model-core/README.md` and docs/references.md), made robust for stepping
//! at a fixed sample rate on an f32 FPU:
//!
//! - the Langevin function uses its series near zero and its asymptote for large arguments
//!   ([`crate::math::langevin`]);
//! - the irreversible susceptibility is never negative: it is zero whenever M_an − M_irr (M_an − M
//!   for the total-magnetization form) has the opposite sign of the field change (the δ_M gate
//!   that removes the classic non-physical negative slopes after reversals);
//! - a sample's field change is integrated in sub-steps (at most [`MAX_SUBSTEPS`]), so accuracy
//!   does not depend on the sample rate: explicit ones of at most `max_substep_a_per_m`
//!   = min(a/4, k/2) (the board's), or ones corrected to second order
//!   ([`JilesAtherton::second_order`], the workbench's) as many as a tolerance on their error
//!   estimate asks;
//! - every mean-field denominator (1 − α dM/dH_e, k − α g) is floored, so large α (steep, nearly
//!   square loops) stays finite; and |M|, |M_irr| ≤ M_s always hold.
//!
//! The default, [`JaVariant::Bulk`] (the only form before variants were selectable), integrates
//! only M_irr; the total M = c M_an(H_e) + (1 − c) M_irr is algebraic at the end of every
//! sub-step. Integrating M too (as a differential dM = (dM/dH_e) dH_e) lets the two drift apart:
//! under a biased drive that ratchets the loop by tens of percent over a few dozen cycles, by an
//! amount that depends on the sample rate. [`JaVariant::Szewczyk`] is a total-magnetization form
//! by definition and integrates M.
//!
//! Per sub-step of `Bulk` (h is the applied field, H_e = h + αM; M_an and dM_an/dH_e come from
//! the end of the previous sub-step, so each sub-step evaluates the Langevin function once):
//! χ_irr = max(0, (M_an − M_irr)/(δk)),  dM/dH_e = c dM_an/dH_e + (1 − c) χ_irr,
//! dH_e = dh / (1 − α dM/dH_e),  M_irr += χ_irr dH_e,  M = c M_an(h + dh + αM̂) + (1 − c) M_irr
//! with M̂ = M + (dM/dH_e) dH_e.

use crate::error::{check, field_scale, saturation, ParamError};
use crate::math::{at_least, langevin_with_slope, within};

/// Most sub-steps one sample may take (bounds the worst-case time per sample on the board;
/// a [`JilesAtherton::refined`] law takes that many times more).
pub const MAX_SUBSTEPS: u32 = 64;
/// A sub-step spans at most a/4 and K_SPAN·k/4 = k/2 of field: M_irr relaxes towards M_an over
/// a field scale k, and explicit steps of k/2 keep loops within 2·10⁻³ M_s of ones with
/// sub-steps 20× finer (tests below); steps of k/4 made fits that wander to small k about a
/// third slower.
const K_SPAN: f32 = 2.0;
/// Floor of the mean-field denominator 1 − α dM/dH_e (and of (k − α g)/k).
const MIN_DENOMINATOR: f32 = 0.05;

/// Which published form of the J–A equations a model integrates (δ = sign dH; δ_M = 1 when
/// δ(M_an − M_irr) > 0, else 0: the gate against negative slopes after a reversal; M_an =
/// M_s L(H_e/a), H_e = H + αM).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum JaVariant {
    /// Venkataraman's "bulk", energy-consistent form (R. Venkataraman, PhD thesis, Univ. of
    /// Maryland 1999; Dapino, Smith & Flatau, IEEE Trans. Magn. 36 (2000) 545): irreversible
    /// change driven by the effective field, dM_irr/dH_e = δ_M (M_an − M_irr)/(δk);
    /// M = c M_an + (1 − c) M_irr;
    /// dM/dH = χ_e/(1 − α χ_e) with χ_e = c dM_an/dH_e + (1 − c) dM_irr/dH_e. The default.
    #[default]
    Bulk,
    /// Jiles & Atherton, J. Magn. Magn. Mater. 61 (1986) 48, eq. 8–11 as usually implemented:
    /// dM_irr/dH = δ_M (M_an − M_irr)/(δk − α(M_an − M_irr)) in the applied field;
    /// M_rev = c (M_an − M_irr), so
    /// M = c M_an + (1 − c) M_irr.
    Original1986,
    /// The total-magnetization form of Jiles, Thoelke & Devine, IEEE Trans. Magn. 28 (1992) 27,
    /// as implemented and identified by Szewczyk (AISC 267 (2014) 275; his JAmodel code):
    /// dM/dH = δ_M (M_an − M)/((1 + c)(δk − α(M_an − M))) + c/(1 + c) dM_an/dH_e, δ_M gated
    /// on M_an − M.
    Szewczyk,
    /// The 1986 paper's total-magnetization equation as printed, without the δ_M gate (Jiles &
    /// Atherton, J. Magn. Magn. Mater. 61 (1986) 48; the form most coefficient sets published
    /// before 1992 were fitted in): dM/dH = (M_an − M)/((1 + c)(δk − α(M_an − M))) + c/(1 + c)
    /// dM_an/dH_e. Just after a reversal, while M_an − M still has the old direction's sign, the
    /// equation's slope is negative (its known flaw); there dM/dH is held at 0 (M waits until the
    /// slope turns positive) instead of running backwards.
    Ungated1986,
}

impl JaVariant {
    /// Every variant, the default first.
    pub const ALL: [JaVariant; 4] =
        [JaVariant::Bulk, JaVariant::Original1986, JaVariant::Szewczyk, JaVariant::Ungated1986];

    /// Name in parameter files (`[ja] variant = "…"`) and reports.
    pub const fn name(self) -> &'static str {
        match self {
            JaVariant::Bulk => "bulk",
            JaVariant::Original1986 => "ja1986",
            JaVariant::Szewczyk => "szewczyk",
            JaVariant::Ungated1986 => "ja1986-ungated",
        }
    }

    /// The variant a name denotes.
    pub fn from_name(s: &str) -> Option<JaVariant> {
        JaVariant::ALL.into_iter().find(|v| v.name() == s)
    }

    /// dM/dH of the variant, in one line (help texts, docs).
    pub const fn equation(self) -> &'static str {
        match self {
            JaVariant::Bulk => {
                "dM/dH = χ_e/(1 − αχ_e), χ_e = c dM_an/dH_e + (1 − c) δ_M (M_an − M_irr)/(δk); M = c M_an + (1 − c) M_irr"
            }
            JaVariant::Original1986 => {
                "dM_irr/dH = δ_M (M_an − M_irr)/(δk − α(M_an − M_irr)); M = c M_an + (1 − c) M_irr"
            }
            JaVariant::Szewczyk => {
                "dM/dH = δ_M (M_an − M)/((1 + c)(δk − α(M_an − M))) + c/(1 + c) dM_an/dH_e (δ_M on M_an − M)"
            }
            JaVariant::Ungated1986 => {
                "dM/dH = max(0, (M_an − M)/((1 + c)(δk − α(M_an − M))) + c/(1 + c) dM_an/dH_e) (no δ_M)"
            }
        }
    }

    /// Whether the form integrates the total M (its reversibility weighs c/(1 + c), so c near 1
    /// is common) rather than M_irr.
    pub const fn is_total_magnetization(self) -> bool {
        matches!(self, JaVariant::Szewczyk | JaVariant::Ungated1986)
    }

    /// The paper the variant follows.
    pub const fn paper(self) -> &'static str {
        match self {
            JaVariant::Bulk => "Venkataraman 1999 (thesis); Dapino, Smith & Flatau 2000",
            JaVariant::Original1986 => "Jiles & Atherton 1986, J. Magn. Magn. Mater. 61, 48",
            JaVariant::Szewczyk => "Jiles, Thoelke & Devine 1992; Szewczyk 2014, AISC 267, 275",
            JaVariant::Ungated1986 => "Jiles & Atherton 1986, J. Magn. Magn. Mater. 61, 48 (as printed)",
        }
    }
}

impl core::fmt::Display for JaVariant {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.pad(self.name())
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for JaVariant {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for JaVariant {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = JaVariant;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("a J–A variant: \"bulk\", \"ja1986\", \"szewczyk\" or \"ja1986-ungated\"")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<JaVariant, E> {
                JaVariant::from_name(v).ok_or_else(|| {
                    E::custom(format_args!(
                        "unknown J–A variant `{v}`: expected \"bulk\" (the default), \"ja1986\", \"szewczyk\" or \"ja1986-ungated\""
                    ))
                })
            }
        }
        d.deserialize_str(Name)
    }
}

/// The five J–A parameters and the variant of the equations they belong to.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct JaParams {
    /// Saturation magnetization M_s [A/m].
    pub ms_a_per_m: f32,
    /// Anhysteretic shape parameter a [A/m].
    pub a_a_per_m: f32,
    /// Mean-field (domain interaction) coefficient α (dimensionless; may be negative, 002).
    pub alpha: f32,
    /// Pinning (irreversible loss) coefficient k [A/m].
    pub k_a_per_m: f32,
    /// Reversibility coefficient c, 0 ≤ c < 1.
    pub c: f32,
    /// The form of the equations (parameter files: `variant = "…"`; a file without it means the
    /// default). Always written: the firmware's postcard encoding has no optional fields.
    #[cfg_attr(feature = "serde", serde(default))]
    pub variant: JaVariant,
}

impl JaParams {
    /// 001 Table 4, mean of the immune-GA identifications (Terfenol-D vibrator).
    pub const VIBRATOR_001: JaParams = JaParams {
        ms_a_per_m: 6.282e5,
        a_a_per_m: 7085.5,
        alpha: 0.080,
        k_a_per_m: 3316.0,
        c: 0.163,
        variant: JaVariant::Bulk,
    };
    /// 002 Table III, first rod.
    pub const TSMA_ROD1_002: JaParams = JaParams {
        ms_a_per_m: 6.0e5,
        a_a_per_m: 6512.0,
        alpha: -0.035,
        k_a_per_m: 4000.0,
        c: 0.2,
        variant: JaVariant::Bulk,
    };

    /// α·M_s/(3a): the mean field's share of the anhysteretic's initial slope. At ≥ 1 the
    /// anhysteretic M = M_s L((H + αM)/a) is multivalued and any loop an integration artefact.
    pub fn mean_field_ratio(&self) -> f32 {
        self.alpha * self.ms_a_per_m / (3.0 * self.a_a_per_m)
    }
}

/// Validated J–A model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JilesAtherton {
    p: JaParams,
    max_substep: f32,
    inv_max_substep: f32,
    /// Most sub-steps a sample takes ([`MAX_SUBSTEPS`] × the refinement).
    max_substeps: u32,
    // Reciprocals and products folded once (the sub-step multiplies instead of dividing).
    inv_a: f32,
    inv_k: f32,
    ms_over_a: f32,
    c_ms: f32,
    c_ms_over_a: f32,
    one_minus_c: f32,
    /// Each sub-step's order: 1 explicit, 2 corrected ([`JilesAtherton::second_order`]). A word
    /// like the other fields: the board's sub-step took 148 instructions with a `bool` here
    /// (how the struct was kept in registers), 138 with this word, 136 with neither.
    order: u32,
}

/// J–A state: applied field, total and irreversible magnetization (mutable, per sample). The
/// default is the demagnetised rod at zero field. The total-magnetization form
/// ([`JaVariant::Szewczyk`]) has no separate M_irr: it keeps M there too.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JaState {
    /// Last applied field h [A/m].
    pub h_a_per_m: f32,
    /// Total magnetization M [A/m].
    pub m_a_per_m: f32,
    /// Irreversible magnetization M_irr [A/m].
    pub m_irr_a_per_m: f32,
    /// Cached L(H_e/a) at the present state.
    langevin: f32,
    /// Cached L'(H_e/a) − 1/3 (offset so that the all-zero default is consistent).
    langevin_slope_offset: f32,
}

/// A branch of a drive whose wiggles below a threshold are noise ([`JilesAtherton::step_on_branch`]):
/// the state at the furthest field it has reached.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JaBranch {
    furthest: JaState,
}

impl JaBranch {
    /// A branch starting at state `s`.
    pub fn from(s: JaState) -> Self {
        Self { furthest: s }
    }
}

impl JilesAtherton {
    /// Validates the parameters; the sub-step is min(a/4, k/2).
    pub fn new(p: JaParams) -> Result<Self, ParamError> {
        saturation("ja.ms_a_per_m", p.ms_a_per_m)?;
        field_scale("ja.a_a_per_m", p.a_a_per_m)?;
        check("ja.alpha", p.alpha, |v| v.abs() < 1.0, "in (-1, 1)")?;
        field_scale("ja.k_a_per_m", p.k_a_per_m)?;
        check("ja.c", p.c, |v| (0.0..1.0).contains(&v), "in [0, 1)")?;
        Ok(Self {
            p,
            max_substep: p.a_a_per_m.min(K_SPAN * p.k_a_per_m) * 0.25,
            inv_max_substep: 4.0 / p.a_a_per_m.min(K_SPAN * p.k_a_per_m),
            max_substeps: MAX_SUBSTEPS,
            inv_a: 1.0 / p.a_a_per_m,
            inv_k: 1.0 / p.k_a_per_m,
            ms_over_a: p.ms_a_per_m / p.a_a_per_m,
            c_ms: p.c * p.ms_a_per_m,
            c_ms_over_a: p.c * p.ms_a_per_m / p.a_a_per_m,
            one_minus_c: 1.0 - p.c,
            order: 1,
        })
    }

    /// This law with sub-steps `factor` (in [1, 16]) times finer, and that many times more of
    /// them allowed per sample: for a caller whose time per sample is not budgeted (the
    /// workbench). The explicit sub-step's error falls with its size, the second-order one's
    /// ([`Self::second_order`]) with its square (`tests/rate_independence.rs`).
    pub fn refined(self, factor: u32) -> Self {
        let factor = factor.clamp(1, 16);
        Self {
            max_substep: self.max_substep / factor as f32,
            inv_max_substep: self.inv_max_substep * factor as f32,
            max_substeps: MAX_SUBSTEPS * factor,
            ..self
        }
    }

    /// This law with every sub-step corrected to second order (Heun's trapezoid, its end slope
    /// taken from the anhysteretic the sub-step evaluates anyway, so it costs no second
    /// Langevin function): the explicit sub-step's error falls with the square of its size, not
    /// linearly. For a caller whose time per sample is not budgeted (the workbench); the board
    /// steps the explicit law.
    pub fn second_order(self) -> Self {
        Self { order: 2, ..self }
    }

    /// The parameters.
    pub fn params(&self) -> &JaParams {
        &self.p
    }

    /// Largest field change integrated in one sub-step [A/m].
    pub fn max_substep_a_per_m(&self) -> f32 {
        self.max_substep
    }

    /// Sub-steps a field change of `dh` takes.
    #[inline]
    pub fn substeps_for(&self, dh: f32) -> u32 {
        // Add in f32: `as` saturates at u32::MAX for huge steps, where an integer add would wrap to 0.
        ((dh.abs() * self.inv_max_substep + 1.0) as u32).min(self.max_substeps)
    }

    /// A consistent state at field `h` with the given magnetizations (M = c M_an + (1 − c) M_irr
    /// is recomputed from `m_irr`; `m` seeds the mean field).
    pub fn state(&self, h: f32, m: f32, m_irr: f32) -> JaState {
        let p = &self.p;
        let m_irr = within(m_irr, p.ms_a_per_m);
        let (l, dl) = langevin_with_slope((h + p.alpha * m) * self.inv_a);
        let (m, m_irr) = match p.variant {
            JaVariant::Szewczyk | JaVariant::Ungated1986 => {
                (within(m, p.ms_a_per_m), within(m, p.ms_a_per_m))
            }
            _ => (within(p.c * p.ms_a_per_m * l + (1.0 - p.c) * m_irr, p.ms_a_per_m), m_irr),
        };
        JaState {
            h_a_per_m: h,
            m_a_per_m: m,
            m_irr_a_per_m: m_irr,
            langevin: l,
            langevin_slope_offset: dl - 1.0 / 3.0,
        }
    }

    /// The rod demagnetised at field `h`: the integrated magnetization is 0 there (M_irr for the
    /// bulk and 1986 forms, whose M = c M_an(h + αM) is then solved; M for the total forms).
    pub fn demagnetized_at(&self, h: f32) -> JaState {
        if self.p.variant.is_total_magnetization() {
            return self.state(h, 0.0, 0.0);
        }
        // M = c M_an(h + αM) by fixed-point iteration: |α c dM_an/dH_e| < |α| M_s/(3a) < 1
        // for a single-valued anhysteretic, so it contracts (once per record: rounds are cheap).
        let mut s = self.state(h, 0.0, 0.0);
        for _ in 0..48 {
            s = self.state(h, s.m_a_per_m, 0.0);
        }
        s
    }

    /// dM/dH_e at state `s` for a field moving in direction `dir` (+1 or −1), and the
    /// irreversible part χ_irr = dM_irr/dH_e of the bulk form. Both are ≥ 0.
    #[inline]
    fn slopes(&self, s: &JaState, dir: f32) -> (f32, f32) {
        let man = self.p.ms_a_per_m * s.langevin;
        let c_dman = self.c_ms_over_a * (s.langevin_slope_offset + 1.0 / 3.0);
        let chi_irr = at_least((man - s.m_irr_a_per_m) * dir, 0.0) * self.inv_k;
        (c_dman + self.one_minus_c * chi_irr, chi_irr)
    }

    /// dM_an/dH_e at state `s`.
    #[inline]
    fn anhysteretic_slope(&self, s: &JaState) -> f32 {
        self.ms_over_a * (s.langevin_slope_offset + 1.0 / 3.0)
    }

    /// δ_M (M_an − m)/(δk − α(M_an − m)) = g/(k − α g) with g = max(0, δ(M_an − `m`)): the
    /// applied-field irreversible slope of the 1986 and total-magnetization forms, its
    /// denominator floored like 1 − α dM/dH_e.
    #[inline]
    fn pinned_slope(&self, s: &JaState, m: f32, dir: f32) -> f32 {
        let p = &self.p;
        let g = at_least((p.ms_a_per_m * s.langevin - m) * dir, 0.0);
        g / at_least(p.k_a_per_m - p.alpha * g, MIN_DENOMINATOR * p.k_a_per_m)
    }

    /// (M_an − M)/(δk − α(M_an − M)) = g/(k − α g) with g = δ(M_an − M) of either sign: the
    /// 1986 paper's irreversible slope without the δ_M gate (negative after a reversal, down to
    /// −1/α), its denominator floored like [`Self::pinned_slope`]'s.
    #[inline]
    fn ungated_slope(&self, s: &JaState, dir: f32) -> f32 {
        let p = &self.p;
        let g = (p.ms_a_per_m * s.langevin - s.m_a_per_m) * dir;
        g / at_least(p.k_a_per_m - p.alpha * g, MIN_DENOMINATOR * p.k_a_per_m)
    }

    /// Incremental susceptibility dM/dh at `s` for a field moving in direction `dir`.
    #[inline]
    pub fn susceptibility(&self, s: &JaState, dir: f32) -> f32 {
        let p = &self.p;
        match p.variant {
            JaVariant::Bulk => {
                let (dm_dhe, _) = self.slopes(s, dir);
                dm_dhe / at_least(1.0 - p.alpha * dm_dhe, MIN_DENOMINATOR)
            }
            JaVariant::Original1986 => {
                let c_dman = p.c * self.anhysteretic_slope(s);
                let rev = c_dman / at_least(1.0 - p.alpha * c_dman, MIN_DENOMINATOR);
                self.one_minus_c * self.pinned_slope(s, s.m_irr_a_per_m, dir) + rev
            }
            JaVariant::Szewczyk => {
                let irr = self.pinned_slope(s, s.m_a_per_m, dir);
                (irr + p.c * self.anhysteretic_slope(s)) / (1.0 + p.c)
            }
            JaVariant::Ungated1986 => {
                let irr = self.ungated_slope(s, dir);
                at_least((irr + p.c * self.anhysteretic_slope(s)) / (1.0 + p.c), 0.0)
            }
        }
    }

    /// One explicit integration sub-step of size `dh` (sign gives δ): the board's, whatever
    /// [`Self::second_order`] says (the corrected one is taken per sample, in [`Self::step`]).
    #[inline(always)]
    pub fn substep(&self, s: &mut JaState, dh: f32) {
        // One dispatch per sub-step; each form's step is straight-line code (the budgeted
        // bulk sub-step pays no more than one compare for the variants).
        let dir = direction_of(dh);
        match self.p.variant {
            JaVariant::Bulk => self.substep_bulk(s, dh, dir),
            JaVariant::Original1986 => self.substep_1986(s, dh, dir),
            JaVariant::Szewczyk | JaVariant::Ungated1986 => self.substep_szewczyk(s, dh, dir),
        }
    }

    #[inline(always)]
    fn substep_bulk(&self, s: &mut JaState, dh: f32, dir: f32) {
        let p = &self.p;
        let (dm_dhe, chi_irr) = self.slopes(s, dir);
        let dhe = dh / at_least(1.0 - p.alpha * dm_dhe, MIN_DENOMINATOR);
        s.m_irr_a_per_m = within(s.m_irr_a_per_m + chi_irr * dhe, p.ms_a_per_m);
        let m_predicted = s.m_a_per_m + dm_dhe * dhe;
        self.close_with_irreversible(s, dh, m_predicted);
    }

    #[inline(always)]
    fn substep_1986(&self, s: &mut JaState, dh: f32, dir: f32) {
        let chi = self.susceptibility(s, dir);
        s.m_irr_a_per_m =
            within(s.m_irr_a_per_m + self.pinned_slope(s, s.m_irr_a_per_m, dir) * dh, self.p.ms_a_per_m);
        let m_predicted = s.m_a_per_m + chi * dh;
        self.close_with_irreversible(s, dh, m_predicted);
    }

    #[inline(always)]
    fn substep_szewczyk(&self, s: &mut JaState, dh: f32, dir: f32) {
        let p = &self.p;
        let m = within(s.m_a_per_m + self.susceptibility(s, dir) * dh, p.ms_a_per_m);
        s.m_irr_a_per_m = m;
        s.h_a_per_m += dh;
        let (l, dl) = langevin_with_slope((s.h_a_per_m + p.alpha * m) * self.inv_a);
        s.m_a_per_m = m;
        s.langevin = l;
        s.langevin_slope_offset = dl - 1.0 / 3.0;
    }

    /// The end of a bulk or 1986 sub-step: the anhysteretic curve at the new field with the
    /// predicted mean field, and M = c M_an + (1 − c) M_irr.
    #[inline(always)]
    fn close_with_irreversible(&self, s: &mut JaState, dh: f32, m_predicted: f32) {
        let p = &self.p;
        s.h_a_per_m += dh;
        // Within ±M_s as M itself: a huge field step made the prediction infinite, and the mean
        // field α·∞ NaN for α = 0 (the wrong sign for α < 0).
        let m_predicted = within(m_predicted, p.ms_a_per_m);
        let (l, dl) = langevin_with_slope((s.h_a_per_m + p.alpha * m_predicted) * self.inv_a);
        s.m_a_per_m = within(self.c_ms * l + self.one_minus_c * s.m_irr_a_per_m, p.ms_a_per_m);
        s.langevin = l;
        s.langevin_slope_offset = dl - 1.0 / 3.0;
    }

    /// Moves the applied field to `h` and returns M [A/m]. A non-finite `h` holds the state.
    #[inline]
    pub fn step(&self, s: &mut JaState, h: f32) -> f32 {
        self.step_in_at_most(s, h, self.max_substeps)
    }

    /// [`Self::step`] in at most `max_substeps` (≥ 1) sub-steps, coarser ones when the field
    /// change needs more: for a caller with less time per sample (the inverse compensator's
    /// trial steps).
    #[inline]
    pub fn step_in_at_most(&self, s: &mut JaState, h: f32, max_substeps: u32) -> f32 {
        self.integrate(s, h, None, max_substeps)
    }

    /// Moves the applied field to `h` along the branch of direction `dir` (+1 rising, −1
    /// falling) whatever the sign of the change: a move against `dir` retraces that branch
    /// rather than reversing onto another. A non-finite `h` holds the state.
    #[inline]
    pub fn step_along(&self, s: &mut JaState, h: f32, dir: f32) -> f32 {
        self.integrate(s, h, Some(direction_of(dir)), self.max_substeps)
    }

    /// Moves the field to `h` on the branch `b` (direction `dir`) of a drive whose small
    /// wiggles are noise, not reversals: `s` becomes the state at `h`. A field beyond the
    /// branch's furthest (in `dir`) advances the branch; one behind it retraces the branch from
    /// there, keeping nothing (noise on the drive opens no minor loop); a change of `dir` starts
    /// the new branch at the old one's furthest field, where the drive turned.
    #[inline]
    pub fn step_on_branch(&self, s: &mut JaState, b: &mut JaBranch, h: f32, dir: f32) -> f32 {
        let dir = direction_of(dir);
        if !h.is_finite() {
            return s.m_a_per_m;
        }
        if (h - b.furthest.h_a_per_m) * dir >= 0.0 {
            self.step(&mut b.furthest, h);
            *s = b.furthest;
        } else {
            *s = b.furthest;
            self.step_along(s, h, dir);
        }
        s.m_a_per_m
    }

    /// The field's move to `h` in sub-steps (at most `max_substeps`), each on the branch of
    /// `dir` when given, else of the move's own sign.
    #[inline(always)]
    fn integrate(&self, s: &mut JaState, h: f32, dir: Option<f32>, max_substeps: u32) -> f32 {
        let dh_total = h - s.h_a_per_m;
        if !dh_total.is_finite() {
            return s.m_a_per_m;
        }
        if self.order == 2 {
            self.integrate_corrected(s, dh_total, dir.unwrap_or(direction_of(dh_total)), max_substeps);
        } else {
            let n = self.substeps_for(dh_total).min(max_substeps).max(1);
            let dh = if n == 1 { dh_total } else { dh_total / n as f32 };
            let dir = dir.unwrap_or(direction_of(dh));
            // The form is chosen once per sample, not once per sub-step.
            match self.p.variant {
                JaVariant::Bulk => (0..n).for_each(|_| self.substep_bulk(s, dh, dir)),
                JaVariant::Original1986 => (0..n).for_each(|_| self.substep_1986(s, dh, dir)),
                JaVariant::Szewczyk | JaVariant::Ungated1986 => {
                    (0..n).for_each(|_| self.substep_szewczyk(s, dh, dir))
                }
            }
        }
        s.h_a_per_m = h;
        s.m_a_per_m
    }

    /// [`Self::step`] of this rod and of `other` (each with its own state and field) at once,
    /// their sub-steps interleaved: each sub-step is a chain of dependent arithmetic that keeps
    /// a core waiting on latency, and a second, independent chain beside it fills those waits.
    /// Each rod's M is the same bits as its own `step` gives. Rods of different variants (or a
    /// non-finite field) step one after the other.
    #[inline]
    pub fn step_beside(
        &self,
        s: &mut JaState,
        h: f32,
        other: &JilesAtherton,
        s_other: &mut JaState,
        h_other: f32,
    ) -> (f32, f32) {
        let (dh, dh_other) = (h - s.h_a_per_m, h_other - s_other.h_a_per_m);
        if !(dh.is_finite() && dh_other.is_finite())
            || self.p.variant != other.p.variant
            || self.order != other.order
        {
            return (self.step(s, h), other.step(s_other, h_other));
        }
        if self.order == 2 {
            return self.step_beside_corrected((s, h, dh), (other, s_other, h_other, dh_other));
        }
        // As `step`'s: n ≥ 1 sub-steps of equal size.
        let per_substep = |ja: &JilesAtherton, dh: f32| {
            let n = ja.substeps_for(dh).max(1);
            (n, if n == 1 { dh } else { dh / n as f32 })
        };
        let ((n, dh), (n_other, dh_other)) = (per_substep(self, dh), per_substep(other, dh_other));
        let rods = [(self, &mut *s, n, dh), (other, &mut *s_other, n_other, dh_other)];
        match self.p.variant {
            JaVariant::Bulk => interleave(rods, |ja, s, dh| ja.substep_bulk(s, dh, direction_of(dh))),
            JaVariant::Original1986 => interleave(rods, |ja, s, dh| ja.substep_1986(s, dh, direction_of(dh))),
            JaVariant::Szewczyk | JaVariant::Ungated1986 => {
                interleave(rods, |ja, s, dh| ja.substep_szewczyk(s, dh, direction_of(dh)))
            }
        }
        s.h_a_per_m = h;
        s_other.h_a_per_m = h_other;
        (s.m_a_per_m, s_other.m_a_per_m)
    }
}

/// δ: +1 for a rising field (a change of 0 too), −1 for a falling one.
#[inline(always)]
fn direction_of(dh: f32) -> f32 {
    if dh >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// `n` sub-steps of `dh` of each rod: both in turn while both have some left, then the rest of
/// either.
#[inline(always)]
fn interleave(
    [(ja, s, n, dh), (ja_other, s_other, n_other, dh_other)]: [(&JilesAtherton, &mut JaState, u32, f32); 2],
    substep: impl Fn(&JilesAtherton, &mut JaState, f32),
) {
    let both = n.min(n_other);
    for _ in 0..both {
        substep(ja, s, dh);
        substep(ja_other, s_other, dh_other);
    }
    (both..n).for_each(|_| substep(ja, s, dh));
    (both..n_other).for_each(|_| substep(ja_other, s_other, dh_other));
}

mod corrected;
#[cfg(test)]
mod tests;
