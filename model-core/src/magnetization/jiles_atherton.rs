//! Jiles–Atherton hysteresis (001 eq. 2, 002 appendix B eq. 6), made robust for stepping at a
//! fixed sample rate on an f32 FPU:
//!
//! - the Langevin function uses its series near zero and its asymptote for large arguments
//!   ([`crate::math::langevin`]);
//! - the irreversible susceptibility is never negative: it is zero whenever M_an − M_irr has the
//!   opposite sign of the field change (the δ_M gate that removes the classic non-physical
//!   negative slopes after reversals);
//! - a sample's field change is integrated in sub-steps of at most `max_substep_a_per_m`
//!   (at most [`MAX_SUBSTEPS`]), so accuracy does not depend on the sample rate;
//! - the mean-field denominator 1 − α dM/dH_e is floored, so large α (steep, nearly square loops)
//!   stays finite; and |M|, |M_irr| ≤ M_s always hold;
//! - only M_irr is integrated; the total M = c M_an(H_e) + (1 − c) M_irr is algebraic at the end
//!   of every sub-step. Integrating M too (as a differential dM = (dM/dH_e) dH_e) lets the two
//!   drift apart: under a biased drive that ratchets the loop by tens of percent over a few dozen
//!   cycles, by an amount that depends on the sample rate.
//!
//! Per sub-step (h is the applied field, H_e = h + αM; M_an and dM_an/dH_e come from the end of
//! the previous sub-step, so each sub-step evaluates the Langevin function once):
//! χ_irr = max(0, (M_an − M_irr)/(δk)),  dM/dH_e = c dM_an/dH_e + (1 − c) χ_irr,
//! dH_e = dh / (1 − α dM/dH_e),  M_irr += χ_irr dH_e,  M = c M_an(h + dh + αM̂) + (1 − c) M_irr
//! with M̂ = M + (dM/dH_e) dH_e.

use crate::error::{check, field_scale, saturation, ParamError};
use crate::math::{at_least, langevin_with_slope, within};

/// Most sub-steps one sample may take (bounds the worst-case time per sample).
pub const MAX_SUBSTEPS: u32 = 64;
/// Floor of the mean-field denominator 1 − α dM/dH_e.
const MIN_DENOMINATOR: f32 = 0.05;

/// The five J–A parameters and the integration step.
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
}

impl JaParams {
    /// 001 Table 4, mean of the immune-GA identifications (Terfenol-D vibrator).
    pub const VIBRATOR_001: JaParams =
        JaParams { ms_a_per_m: 6.282e5, a_a_per_m: 7085.5, alpha: 0.080, k_a_per_m: 3316.0, c: 0.163 };
    /// 002 Table III, first rod.
    pub const TSMA_ROD1_002: JaParams =
        JaParams { ms_a_per_m: 6.0e5, a_a_per_m: 6512.0, alpha: -0.035, k_a_per_m: 4000.0, c: 0.2 };
}

/// Validated J–A model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JilesAtherton {
    p: JaParams,
    max_substep: f32,
    inv_max_substep: f32,
    // Reciprocals and products folded once (the sub-step multiplies instead of dividing).
    inv_a: f32,
    inv_k: f32,
    c_ms: f32,
    c_ms_over_a: f32,
    one_minus_c: f32,
}

/// J–A state: applied field, total and irreversible magnetization (mutable, per sample). The
/// default is the demagnetised rod at zero field.
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

impl JilesAtherton {
    /// Validates the parameters; the sub-step is min(a, k)/4.
    pub fn new(p: JaParams) -> Result<Self, ParamError> {
        saturation("ja.ms_a_per_m", p.ms_a_per_m)?;
        field_scale("ja.a_a_per_m", p.a_a_per_m)?;
        check("ja.alpha", p.alpha, |v| v.abs() < 1.0, "in (-1, 1)")?;
        field_scale("ja.k_a_per_m", p.k_a_per_m)?;
        check("ja.c", p.c, |v| (0.0..1.0).contains(&v), "in [0, 1)")?;
        Ok(Self {
            p,
            max_substep: p.a_a_per_m.min(p.k_a_per_m) * 0.25,
            inv_max_substep: 4.0 / p.a_a_per_m.min(p.k_a_per_m),
            inv_a: 1.0 / p.a_a_per_m,
            inv_k: 1.0 / p.k_a_per_m,
            c_ms: p.c * p.ms_a_per_m,
            c_ms_over_a: p.c * p.ms_a_per_m / p.a_a_per_m,
            one_minus_c: 1.0 - p.c,
        })
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
        ((dh.abs() * self.inv_max_substep + 1.0) as u32).min(MAX_SUBSTEPS)
    }

    /// A consistent state at field `h` with the given magnetizations (M = c M_an + (1 − c) M_irr
    /// is recomputed from `m_irr`; `m` seeds the mean field).
    pub fn state(&self, h: f32, m: f32, m_irr: f32) -> JaState {
        let p = &self.p;
        let m_irr = within(m_irr, p.ms_a_per_m);
        let (l, dl) = langevin_with_slope((h + p.alpha * m) * self.inv_a);
        JaState {
            h_a_per_m: h,
            m_a_per_m: within(p.c * p.ms_a_per_m * l + (1.0 - p.c) * m_irr, p.ms_a_per_m),
            m_irr_a_per_m: m_irr,
            langevin: l,
            langevin_slope_offset: dl - 1.0 / 3.0,
        }
    }

    /// dM/dH_e at state `s` for a field moving in direction `dir` (+1 or −1), and the
    /// irreversible part χ_irr. Both are ≥ 0.
    #[inline]
    fn slopes(&self, s: &JaState, dir: f32) -> (f32, f32) {
        let man = self.p.ms_a_per_m * s.langevin;
        let c_dman = self.c_ms_over_a * (s.langevin_slope_offset + 1.0 / 3.0);
        let chi_irr = at_least((man - s.m_irr_a_per_m) * dir, 0.0) * self.inv_k;
        (c_dman + self.one_minus_c * chi_irr, chi_irr)
    }

    /// Incremental susceptibility dM/dh at `s` for a field moving in direction `dir`.
    #[inline]
    pub fn susceptibility(&self, s: &JaState, dir: f32) -> f32 {
        let (dm_dhe, _) = self.slopes(s, dir);
        dm_dhe / at_least(1.0 - self.p.alpha * dm_dhe, MIN_DENOMINATOR)
    }

    /// One integration sub-step of size `dh` (sign gives δ).
    #[inline]
    pub fn substep(&self, s: &mut JaState, dh: f32) {
        let p = &self.p;
        let ms = p.ms_a_per_m;
        let dir = if dh >= 0.0 { 1.0 } else { -1.0 };
        let (dm_dhe, chi_irr) = self.slopes(s, dir);
        let dhe = dh / at_least(1.0 - p.alpha * dm_dhe, MIN_DENOMINATOR);
        s.m_irr_a_per_m = within(s.m_irr_a_per_m + chi_irr * dhe, ms);
        s.h_a_per_m += dh;
        let m_predicted = s.m_a_per_m + dm_dhe * dhe;
        let (l, dl) = langevin_with_slope((s.h_a_per_m + p.alpha * m_predicted) * self.inv_a);
        s.m_a_per_m = within(self.c_ms * l + self.one_minus_c * s.m_irr_a_per_m, ms);
        s.langevin = l;
        s.langevin_slope_offset = dl - 1.0 / 3.0;
    }

    /// Moves the applied field to `h` and returns M [A/m]. A non-finite `h` holds the state.
    #[inline]
    pub fn step(&self, s: &mut JaState, h: f32) -> f32 {
        let dh_total = h - s.h_a_per_m;
        if !dh_total.is_finite() {
            return s.m_a_per_m;
        }
        let n = self.substeps_for(dh_total);
        let dh = if n == 1 { dh_total } else { dh_total / n as f32 };
        for _ in 0..n {
            self.substep(s, dh);
        }
        s.h_a_per_m = h;
        s.m_a_per_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Found by the model_step fuzz target: a field jump beyond u32::MAX sub-steps wrapped the
    /// integer count to 0 sub-steps (a panic in debug builds).
    #[test]
    fn a_huge_field_step_takes_the_most_sub_steps_not_none() {
        let ja = JilesAtherton::new(JaParams { a_a_per_m: 1.0, k_a_per_m: 1.0, ..JaParams::TSMA_ROD1_002 })
            .unwrap();
        assert_eq!(ja.substeps_for(f32::MAX), MAX_SUBSTEPS);
        assert_eq!(ja.substeps_for(1e12), MAX_SUBSTEPS);
        assert_eq!(ja.substeps_for(0.0), 1);
    }

    /// Found by the model_step fuzz target: a subnormal k made 1/k infinite and M NaN. The
    /// characteristic fields are now bounded to [1, 1e7] A/m.
    #[test]
    fn subnormal_or_huge_field_scales_are_refused() {
        for k in [1e-42, 0.5, 2e7] {
            assert!(
                JilesAtherton::new(JaParams { k_a_per_m: k, ..JaParams::TSMA_ROD1_002 }).is_err(),
                "k = {k}"
            );
            assert!(
                JilesAtherton::new(JaParams { a_a_per_m: k, ..JaParams::TSMA_ROD1_002 }).is_err(),
                "a = {k}"
            );
        }
        assert!(JilesAtherton::new(JaParams { ms_a_per_m: 3e10, ..JaParams::TSMA_ROD1_002 }).is_err());
    }

    fn sine_drive(
        ja: &JilesAtherton,
        amp: f32,
        bias: f32,
        cycles: usize,
        per_cycle: usize,
    ) -> Vec<(f32, f32)> {
        let mut s = JaState::default();
        let mut out = Vec::with_capacity(cycles * per_cycle);
        for n in 0..cycles * per_cycle {
            let ph = 2.0 * core::f32::consts::PI * n as f32 / per_cycle as f32;
            let h = bias + amp * libm::sinf(ph);
            out.push((h, ja.step(&mut s, h)));
        }
        out
    }

    #[test]
    fn reaches_periodic_steady_state_with_a_symmetric_loop() {
        for p in [JaParams::TSMA_ROD1_002, JaParams::VIBRATOR_001] {
            let ja = JilesAtherton::new(p).unwrap();
            let per = 400;
            let loop_ = sine_drive(&ja, 60_000.0, 0.0, 5, per);
            let ms = p.ms_a_per_m;
            // Cycle 4 equals cycle 5.
            let drift =
                (0..per).map(|i| (loop_[3 * per + i].1 - loop_[4 * per + i].1).abs()).fold(0.0, f32::max);
            assert!(drift < 2e-3 * ms, "{p:?}: cycle-to-cycle drift {drift}");
            // Symmetric drive ⇒ M(t + T/2) = −M(t).
            let asym = (0..per / 2)
                .map(|i| (loop_[4 * per + i].1 + loop_[4 * per + i + per / 2].1).abs())
                .fold(0.0, f32::max);
            assert!(asym < 5e-3 * ms, "{p:?}: loop asymmetry {asym}");
            // A real hysteresis loop: M at H = 0 differs between the branches (remanence).
            let up = loop_[4 * per].1; // h = 0 rising
            let down = loop_[4 * per + per / 2].1; // h = 0 falling
            assert!(down - up > 0.01 * ms, "{p:?}: no remanence ({up}, {down})");
            assert!(loop_.iter().all(|&(_, m)| m.abs() <= ms));
        }
    }

    #[test]
    fn substep_size_does_not_change_the_loop() {
        // The sample-rate independence the sub-steps promise: 100 or 4000 samples per cycle.
        let ja = JilesAtherton::new(JaParams::TSMA_ROD1_002).unwrap();
        let coarse = sine_drive(&ja, 50_000.0, 5_000.0, 3, 100);
        let fine = sine_drive(&ja, 50_000.0, 5_000.0, 3, 4000);
        let err = (0..300).map(|i| (coarse[i].1 - fine[i * 40].1).abs()).fold(0.0, f32::max);
        assert!(err < 0.01 * 6.0e5, "max difference {err}");
    }

    /// A biased minor loop closes: no ratcheting over dozens of cycles, whatever the sample rate
    /// (the failure mode of integrating M differentially).
    #[test]
    fn biased_minor_loops_close_at_every_sample_rate() {
        let p = JaParams { ms_a_per_m: 6.0e5, a_a_per_m: 7012.0, alpha: -0.01, k_a_per_m: 4283.0, c: 0.18 };
        let ja = JilesAtherton::new(p).unwrap();
        let mut finals = Vec::new();
        for per in [25usize, 400, 8000] {
            let loop_ = sine_drive(&ja, 27_000.0, 22_700.0, 40, per);
            let m_at = |cycle: usize| loop_[cycle * per].1;
            let drift = (m_at(39) - m_at(10)).abs();
            assert!(drift < 1e-3 * p.ms_a_per_m, "{per} samples/cycle: drift {drift} A/m over 29 cycles");
            finals.push(m_at(39));
        }
        let spread =
            finals.iter().fold(f32::MIN, |a, &b| a.max(b)) - finals.iter().fold(f32::MAX, |a, &b| a.min(b));
        assert!(spread < 5e-3 * p.ms_a_per_m, "sample-rate dependence {spread} A/m: {finals:?}");
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = JaParams::TSMA_ROD1_002;
        assert_eq!(
            JilesAtherton::new(JaParams { c: 1.0, ..p }),
            Err(ParamError::OutOfRange("ja.c", "in [0, 1)"))
        );
        assert_eq!(
            JilesAtherton::new(JaParams { k_a_per_m: f32::INFINITY, ..p }),
            Err(ParamError::NonFinite("ja.k_a_per_m"))
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn never_nan_and_bounded(
            ms in 1e3f32..2e6, a in 10.0f32..5e4, alpha in -0.99f32..0.99, k in 1.0f32..5e4, c in 0.0f32..0.999,
            fields in proptest::collection::vec(-1e7f32..1e7, 1..200),
        ) {
            let ja = JilesAtherton::new(JaParams { ms_a_per_m: ms, a_a_per_m: a, alpha, k_a_per_m: k, c }).unwrap();
            let mut s = JaState::default();
            for h in fields {
                let m = ja.step(&mut s, h);
                prop_assert!(m.is_finite() && m.abs() <= ms);
                prop_assert!(s.m_irr_a_per_m.is_finite() && s.m_irr_a_per_m.abs() <= ms);
            }
        }
    }
}
