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
//!   stays finite; and |M|, |M_irr| ≤ M_s always hold.
//!
//! Differential form integrated per sub-step (h is the applied field, H_e = h + αM):
//! χ_irr = max(0, (M_an − M_irr)/(δk)),  dM/dH_e = c dM_an/dH_e + (1 − c) χ_irr,
//! dH_e = dh / (1 − α dM/dH_e),  dM_irr = χ_irr dH_e,  dM = (dM/dH_e) dH_e.

use crate::error::{check, positive, ParamError};
use crate::math::{at_least, langevin_with_slope, within};

/// Most sub-steps one sample may take (bounds the worst-case time per sample).
pub const MAX_SUBSTEPS: u32 = 64;
/// Floor of the mean-field denominator 1 − α dM/dH_e.
const MIN_DENOMINATOR: f32 = 0.05;

/// The five J–A parameters and the integration step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
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
    // Reciprocals and products folded once (the sub-step multiplies instead of dividing).
    inv_a: f32,
    inv_k: f32,
    ms_over_a: f32,
}

/// J–A state: applied field, total and irreversible magnetization (mutable, per sample).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JaState {
    /// Last applied field h [A/m].
    pub h_a_per_m: f32,
    /// Total magnetization M [A/m].
    pub m_a_per_m: f32,
    /// Irreversible magnetization M_irr [A/m].
    pub m_irr_a_per_m: f32,
}

impl JilesAtherton {
    /// Validates the parameters; the sub-step is min(a, k)/4.
    pub fn new(p: JaParams) -> Result<Self, ParamError> {
        positive("ja.ms_a_per_m", p.ms_a_per_m)?;
        positive("ja.a_a_per_m", p.a_a_per_m)?;
        check("ja.alpha", p.alpha, |v| v.abs() < 1.0, "in (-1, 1)")?;
        positive("ja.k_a_per_m", p.k_a_per_m)?;
        check("ja.c", p.c, |v| (0.0..1.0).contains(&v), "in [0, 1)")?;
        Ok(Self {
            p,
            max_substep: p.a_a_per_m.min(p.k_a_per_m) * 0.25,
            inv_a: 1.0 / p.a_a_per_m,
            inv_k: 1.0 / p.k_a_per_m,
            ms_over_a: p.ms_a_per_m / p.a_a_per_m,
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
        let n = (dh.abs() / self.max_substep) as u32 + 1;
        n.min(MAX_SUBSTEPS)
    }

    /// dM/dH_e at state `s` for a field moving in direction `dir` (+1 or −1), and the
    /// irreversible part χ_irr. Both are ≥ 0.
    #[inline]
    fn slopes(&self, s: &JaState, dir: f32) -> (f32, f32) {
        let p = &self.p;
        let he = s.h_a_per_m + p.alpha * s.m_a_per_m;
        let (l, dl) = langevin_with_slope(he * self.inv_a);
        let man = p.ms_a_per_m * l;
        let dman = self.ms_over_a * dl;
        let chi_irr = at_least((man - s.m_irr_a_per_m) * dir, 0.0) * self.inv_k;
        (p.c * dman + (1.0 - p.c) * chi_irr, chi_irr)
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
        let ms = self.p.ms_a_per_m;
        let dir = if dh >= 0.0 { 1.0 } else { -1.0 };
        let (dm_dhe, chi_irr) = self.slopes(s, dir);
        let dhe = dh / at_least(1.0 - self.p.alpha * dm_dhe, MIN_DENOMINATOR);
        s.m_irr_a_per_m = within(s.m_irr_a_per_m + chi_irr * dhe, ms);
        s.m_a_per_m = within(s.m_a_per_m + dm_dhe * dhe, ms);
        s.h_a_per_m += dh;
    }

    /// Moves the applied field to `h` and returns M [A/m]. A non-finite `h` holds the state.
    #[inline]
    pub fn step(&self, s: &mut JaState, h: f32) -> f32 {
        let dh_total = h - s.h_a_per_m;
        if !dh_total.is_finite() {
            return s.m_a_per_m;
        }
        let n = self.substeps_for(dh_total);
        let dh = dh_total / n as f32;
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
