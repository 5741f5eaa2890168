//! The workbench's J–A integration ([`JilesAtherton::second_order`]): each sub-step corrected
//! to second order (Heun's trapezoid), as many sub-steps per sample as a tolerance on their error
//! estimate asks. The board steps the explicit sub-steps of the module above; these repeat their
//! predictor rather than share a body with it, so that the board's code stays what it was (its
//! budget is tight).

use super::{direction_of, JaState, JaVariant, JilesAtherton, MIN_DENOMINATOR};
use crate::math::{at_least, langevin_with_slope, within};

/// The corrected sub-steps' tolerance, a share of M_s: each sample is redone in more sub-steps
/// while one sub-step's corrected and explicit magnetizations (Heun's and Euler's) differ by
/// more. Measured on the textbook rig's files at its own parameters (`recovery_suite
/// forward_fidelity`): 2·10⁻³ takes held steps from 3.1× to 0.5× the noise floor (the fixed
/// span's figure), 10⁻³ gains little more and costs `diagnose8` a tenth more time, 10⁻² loses
/// what the control gained. Small loops at fs/20 want 2·10⁻⁴ (`tests/rate_independence.rs`:
/// within 0.2 % of their range), at twice `diagnose8`'s time.
const CORRECTED_TOLERANCE: f32 = 2e-3;
/// The corrected sub-steps' first try spans up to 8× the explicit sub-step (2 min(a, 2k)): most
/// samples pass at once, and a sample that fails is redone from a count sized by how far it
/// missed, so a coarse first try costs little.
const CORRECTED_FIRST_SPAN: f32 = 1.0 / 8.0;

impl JilesAtherton {
    /// The bulk form's sub-step corrected to second order ([`Self::second_order`]): Heun's
    /// trapezoid on M_irr, the end's slope from the Euler prediction and the anhysteretic at the
    /// end (the end's mean-field factor 1/(1 − α dM/dH_e) to first order from the start's,
    /// which keeps the step second order without a second division).
    #[inline(always)]
    fn substep_bulk_corrected(&self, s: &mut JaState, dh: f32, dir: f32) -> f32 {
        let p = &self.p;
        let (dm_dhe, chi_irr) = self.slopes(s, dir);
        let mean_field = 1.0 / at_least(1.0 - p.alpha * dm_dhe, MIN_DENOMINATOR);
        let dhe = dh * mean_field;
        let m_irr_start = s.m_irr_a_per_m;
        let m_irr_predicted = within(m_irr_start + chi_irr * dhe, p.ms_a_per_m);
        let m_predicted = within(s.m_a_per_m + dm_dhe * dhe, p.ms_a_per_m);
        s.h_a_per_m += dh;
        let (l, dl) = langevin_with_slope((s.h_a_per_m + p.alpha * m_predicted) * self.inv_a);
        let chi_irr_end = at_least((p.ms_a_per_m * l - m_irr_predicted) * dir, 0.0) * self.inv_k;
        let dm_dhe_end = self.c_ms_over_a * dl + self.one_minus_c * chi_irr_end;
        let mean_field_end = mean_field + mean_field * mean_field * p.alpha * (dm_dhe_end - dm_dhe);
        s.m_irr_a_per_m = within(
            m_irr_start + 0.5 * dh * (chi_irr * mean_field + chi_irr_end * mean_field_end),
            p.ms_a_per_m,
        );
        s.m_a_per_m = within(self.c_ms * l + self.one_minus_c * s.m_irr_a_per_m, p.ms_a_per_m);
        s.langevin = l;
        s.langevin_slope_offset = dl - 1.0 / 3.0;
        (s.m_irr_a_per_m - m_irr_predicted).abs()
    }

    /// The 1986 form's sub-step corrected to second order ([`Self::substep_bulk_corrected`]'s
    /// trapezoid on M_irr in the applied field). The mean field is predicted with M's own slope,
    /// ((1 − c) dM_irr/dh + c dM_an/dH_e)/(1 − α c dM_an/dH_e): the susceptibility's
    /// reversible-only mean-field factor leaves the anhysteretic at the end a first-order error
    /// the trapezoid inherits.
    #[inline(always)]
    fn substep_1986_corrected(&self, s: &mut JaState, dh: f32, dir: f32) -> f32 {
        let p = &self.p;
        let m_irr_start = s.m_irr_a_per_m;
        let slope_start = self.pinned_slope(s, m_irr_start, dir);
        let c_dman = p.c * self.anhysteretic_slope(s);
        let chi =
            (self.one_minus_c * slope_start + c_dman) / at_least(1.0 - p.alpha * c_dman, MIN_DENOMINATOR);
        s.m_irr_a_per_m = within(m_irr_start + slope_start * dh, p.ms_a_per_m);
        let m_predicted = s.m_a_per_m + chi * dh;
        self.close_with_irreversible(s, dh, m_predicted);
        let m_irr_predicted = s.m_irr_a_per_m;
        let slope_end = self.pinned_slope(s, m_irr_predicted, dir);
        s.m_irr_a_per_m = within(m_irr_start + 0.5 * (slope_start + slope_end) * dh, p.ms_a_per_m);
        s.m_a_per_m = within(self.c_ms * s.langevin + self.one_minus_c * s.m_irr_a_per_m, p.ms_a_per_m);
        (s.m_irr_a_per_m - m_irr_predicted).abs()
    }

    /// The total-magnetization forms' sub-step corrected to second order (Heun's trapezoid on
    /// M; the cached anhysteretic stays the one at the predicted mean field).
    #[inline(always)]
    fn substep_szewczyk_corrected(&self, s: &mut JaState, dh: f32, dir: f32) -> f32 {
        let (m_start, chi_start) = (s.m_a_per_m, self.susceptibility(s, dir));
        self.substep_szewczyk(s, dh, dir);
        let m_predicted = s.m_a_per_m;
        let m = within(m_start + 0.5 * (chi_start + self.susceptibility(s, dir)) * dh, self.p.ms_a_per_m);
        s.m_a_per_m = m;
        s.m_irr_a_per_m = m;
        (m - m_predicted).abs()
    }

    /// The field's move by `dh_total` on the branch of `dir` in corrected sub-steps, as many as
    /// [`CORRECTED_TOLERANCE`] asks (at most `max_substeps`): out of the board's line (it steps
    /// explicitly and pays one compare per sample for this).
    #[inline(never)]
    pub(super) fn integrate_corrected(&self, s: &mut JaState, dh_total: f32, dir: f32, max_substeps: u32) {
        let n = self.first_corrected_count(dh_total).min(max_substeps);
        let start = *s;
        let err = self.substeps_corrected(s, n, dh_total, dir);
        self.within_tolerance(s, start, (n, err), (dh_total, dir), max_substeps);
    }

    /// `n` corrected sub-steps of `dh_total`/n on the branch of `dir`; returns their largest
    /// error estimate (the corrected and the explicit integrated magnetization's difference).
    #[inline(always)]
    pub(super) fn substeps_corrected(&self, s: &mut JaState, n: u32, dh_total: f32, dir: f32) -> f32 {
        let dh = dh_total / n as f32;
        let mut worst = 0.0f32;
        match self.p.variant {
            JaVariant::Bulk => {
                (0..n).for_each(|_| worst = worst.max(self.substep_bulk_corrected(s, dh, dir)))
            }
            JaVariant::Original1986 => {
                (0..n).for_each(|_| worst = worst.max(self.substep_1986_corrected(s, dh, dir)))
            }
            JaVariant::Szewczyk | JaVariant::Ungated1986 => {
                (0..n).for_each(|_| worst = worst.max(self.substep_szewczyk_corrected(s, dh, dir)))
            }
        }
        worst
    }

    /// The corrected sub-steps' first try at a field change of `dh`: sub-steps of at most
    /// [`CORRECTED_FIRST_SPAN`]'s span.
    #[inline(always)]
    pub(super) fn first_corrected_count(&self, dh: f32) -> u32 {
        ((dh.abs() * self.inv_max_substep * CORRECTED_FIRST_SPAN + 1.0) as u32).min(self.max_substeps).max(1)
    }

    /// A sample tried in `n` corrected sub-steps whose largest error estimate was `err`, redone
    /// from `start` in more while that is above [`CORRECTED_TOLERANCE`] (and fewer than
    /// `max_substeps`). The estimate falls with the square of the sub-step, so the next count is
    /// n·√(err/tol) with a fifth to spare: one redo at most, mostly.
    #[inline(never)]
    fn within_tolerance(
        &self,
        s: &mut JaState,
        start: JaState,
        tried: (u32, f32),
        field: (f32, f32),
        max_substeps: u32,
    ) {
        let ((mut n, mut err), (dh_total, dir)) = (tried, field);
        let tol = CORRECTED_TOLERANCE * self.p.ms_a_per_m;
        while err > tol && n < max_substeps {
            n = ((n as f32 * crate::math::sqrt(err / tol) * 1.2) as u32 + 1).min(max_substeps);
            *s = start;
            err = self.substeps_corrected(s, n, dh_total, dir);
        }
    }

    /// [`Self::step_beside`] of two second-order rods: both first tries interleaved, then each
    /// rod's redo (if any) alone, as its own `step` would.
    #[inline(never)]
    pub(super) fn step_beside_corrected(
        &self,
        (s, h, dh): (&mut JaState, f32, f32),
        (other, s_other, h_other, dh_other): (&JilesAtherton, &mut JaState, f32, f32),
    ) -> (f32, f32) {
        let (start, start_other) = (*s, *s_other);
        let (n, n_other) = (self.first_corrected_count(dh), other.first_corrected_count(dh_other));
        let rods =
            [(self, &mut *s, n, dh / n as f32), (other, &mut *s_other, n_other, dh_other / n_other as f32)];
        let (err, err_other) = match self.p.variant {
            JaVariant::Bulk => {
                interleave_worst(rods, |ja, s, dh| ja.substep_bulk_corrected(s, dh, direction_of(dh)))
            }
            JaVariant::Original1986 => {
                interleave_worst(rods, |ja, s, dh| ja.substep_1986_corrected(s, dh, direction_of(dh)))
            }
            JaVariant::Szewczyk | JaVariant::Ungated1986 => {
                interleave_worst(rods, |ja, s, dh| ja.substep_szewczyk_corrected(s, dh, direction_of(dh)))
            }
        };
        self.within_tolerance(s, start, (n, err), (dh, direction_of(dh)), self.max_substeps);
        let field_other = (dh_other, direction_of(dh_other));
        other.within_tolerance(s_other, start_other, (n_other, err_other), field_other, other.max_substeps);
        s.h_a_per_m = h;
        s_other.h_a_per_m = h_other;
        (s.m_a_per_m, s_other.m_a_per_m)
    }
}

/// As the explicit sub-steps' `interleave`, each rod's largest sub-step error estimate returned.
#[inline(always)]
fn interleave_worst(
    [(ja, s, n, dh), (ja_other, s_other, n_other, dh_other)]: [(&JilesAtherton, &mut JaState, u32, f32); 2],
    substep: impl Fn(&JilesAtherton, &mut JaState, f32) -> f32,
) -> (f32, f32) {
    let both = n.min(n_other);
    let (mut e, mut e_other) = (0.0f32, 0.0f32);
    for _ in 0..both {
        e = e.max(substep(ja, s, dh));
        e_other = e_other.max(substep(ja_other, s_other, dh_other));
    }
    (both..n).for_each(|_| e = e.max(substep(ja, s, dh)));
    (both..n_other).for_each(|_| e_other = e_other.max(substep(ja_other, s_other, dh_other)));
    (e, e_other)
}
