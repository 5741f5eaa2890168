//! Classical (rate-independent) Preisach hysteresis (003 eq. 1):
//! M = ∫∫_{α≥β} μ(α, β) γ_αβ[H] dα dβ, with relays γ_αβ = ±1 switching up at α and down at β.
//!
//! The relay plane is discretised on a fixed grid of [`PREISACH_LEVELS`] field levels in
//! ±H_max and parameterised by its **Everett table** E(α_i, β_j) (the integral of μ over the
//! triangle β ≤ β' ≤ α' ≤ α, 003 §3). Between grid points √E is interpolated (bilinear off the
//! diagonal, linear on the diagonal cells so that E(h, h) = 0 exactly) and squared, which keeps
//! the output continuous and monotone in the input. Why √E: near the diagonal a smooth density
//! gives E(α, β) ≈ ½ μ (α − β)², so a minor loop smaller than a grid cell follows Rayleigh's law
//! (the relays' slope is zero at a reversal and grows with the excursion; the loop opens). E
//! itself interpolated linearly made every such loop a closed straight line with the whole
//! cell's slope, 8–16× the relays' swing at 1/16–1/8 of a cell, and the reversible part could
//! not be told from it: on the held-out Lorentzian-Preisach rig (small-signal files about a bias)
//! the complete `preisach` structure validated at 1.78 % with the reversible part searched and
//! E linear, 0.76 % with √E.
//!
//! The state is the staircase memory: the alternating dominant extrema M_1 > M_2 > … and
//! m_1 < m_2 < … since negative saturation, the current input last. An input beyond a stored
//! extremum wipes it out together with its partner (wiping-out property); the output is
//!
//! M = 2 Σ_k [E(M_k, m_{k−1}) − E(M_k, m_k)] − E(H_max, −H_max),  m_0 = −H_max,
//!
//! so minor loops between the same two extrema are congruent whatever came before. The memory
//! holds [`PREISACH_MEMORY`] extrema; a deeper nesting merges the two adjacent turning points
//! whose removal changes the staircase least (in a decaying oscillation, two nearly equal loops
//! deep in the memory).
//!
//! A reversible part adds what the relays cannot: a slope right after every reversal (small
//! signals ride on it). With a reversible fraction ρ and field scale h_r,
//!
//! M = (1 − ρ) M_P[H] + ρ M_s tanh(H/h_r),
//!
//! M_P the relay plane's output above (±M_s at ±H_max). Without it (ρ = 0, parameter sets that
//! do not give it) a minor loop starts nearly flat: the measured loops of ferrites, which move at
//! once after a reversal, were fitted to 0.7–1.1 % NRMSE with relays alone and 0.2–0.3 % with
//! the reversible part.
//!
//! Resolution: the grid step is 2 H_max / 31, and the table follows the continuous density to
//! about 3 % of M_s when the density's features are two steps wide, so choose H_max no larger
//! than the fields the actuator really sees.

// Triangular index loops over the Everett table read clearer than iterator chains.
#![allow(clippy::needless_range_loop)]

use crate::error::{field_scale, saturation, ParamError, MS_MAX, MS_MIN};

/// Field levels of the Everett grid (the relay plane has LEVELS·(LEVELS−1)/2 cells).
pub const PREISACH_LEVELS: usize = 32;
/// Stored turning points (alternating maxima and minima, the current input included). A
/// voltage-driven chirp nests a loop at every reversal (the current's amplitude falls with
/// frequency): 0.4 s from 20 Hz to 2.5 kHz fills the memory and stays within 0.13 % M_s of an
/// unbounded one (16 points: 0.91 %, 32: 0.27 %, 64: 0.05 %; test
/// `a_chirp_through_a_coil_stays_within_the_memory`). 192 B of state; the firmware's smoke
/// run keeps its stack budget with 48 (64 went over).
pub const PREISACH_MEMORY: usize = 48;

/// A Preisach density as the workbench identifies it, normalised so that saturation is ±M_s at
/// ±H_max. With an interaction spread σ_u it is a product of Lorentzians on the relays'
/// coercivity h = (α − β)/2 (centre h_c, spread σ) and interaction field u = (α + β)/2 (centre
/// 0, spread σ_u), the two widths of a measured FORC diagram (Mayergoyz 1991; Terfenol-D: a
/// narrow coercivity, a wide interaction, slanted narrow loops). Without it, the factorised
/// Lorentzian L((α − h_c)/σ) L((β + h_c)/σ) of parameter files before 2026-11-24, which ties the
/// two widths together.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct PreisachParams {
    /// Output at positive saturation M_s [A/m].
    pub ms_a_per_m: f32,
    /// Coercive field h_c [A/m]: relays switch up around +h_c and down around −h_c.
    pub coercive_a_per_m: f32,
    /// Spread σ [A/m] of the relays' coercivity (with no interaction spread: of both switching
    /// fields).
    pub spread_a_per_m: f32,
    /// Spread σ_u [A/m] of the interaction field (larger: a more slanted loop of the same width).
    #[cfg_attr(feature = "serde", serde(default))]
    pub interaction_spread_a_per_m: Option<f32>,
    /// Reversible fraction ρ (1), 0 ≤ ρ < 1 (none: 0, no reversible part).
    #[cfg_attr(feature = "serde", serde(default))]
    pub reversible_fraction: Option<f32>,
    /// Field scale h_r of the reversible part [A/m] (none: the interaction spread, else the
    /// spread: the loop's own field scale).
    #[cfg_attr(feature = "serde", serde(default))]
    pub reversible_field_a_per_m: Option<f32>,
    /// Field range ±H_max [A/m] the relay plane covers (beyond it the rod is saturated).
    pub h_max_a_per_m: f32,
}

/// Everett table on the fixed grid: `e[i][j]` = E(α = h_i, β = h_j) for i ≥ j, with
/// h_k = −H_max + 2 H_max k / (LEVELS − 1). Entries with i < j are unused (zero).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EverettTable {
    h_max: f32,
    /// √E at the grid points (row α index, column β index; zero for i ≤ j): what
    /// [`EverettTable::everett`] interpolates.
    root: [[f32; PREISACH_LEVELS]; PREISACH_LEVELS],
    /// E(H_max, −H_max).
    total: f32,
}

impl EverettTable {
    /// Validates a measured or fitted table: H_max in [1, 1e7] A/m (as every characteristic
    /// field: the grid's scale is its inverse), finite entries, zero on the diagonal, a total
    /// E(H_max, −H_max) (the saturation magnetization) in [1e3, 1e7] A/m, and non-negative relay
    /// weights (every mixed difference ≥ 0, i.e. E grows with α and falls with β), so that every
    /// entry lies between 0 and the total. A subnormal H_max gave NaN, a total near f32::MAX an
    /// infinite output.
    pub fn new(h_max_a_per_m: f32, e: [[f32; PREISACH_LEVELS]; PREISACH_LEVELS]) -> Result<Self, ParamError> {
        let h_max = field_scale("preisach.h_max_a_per_m", h_max_a_per_m)?;
        for i in 0..PREISACH_LEVELS {
            for j in 0..=i {
                if !e[i][j].is_finite() {
                    return Err(ParamError::NonFinite("preisach.everett"));
                }
            }
        }
        let total = e[PREISACH_LEVELS - 1][0];
        if !(MS_MIN..=MS_MAX).contains(&total) {
            return Err(ParamError::OutOfRange("preisach.everett", "in [1e3, 1e7] A/m at (H_max, -H_max)"));
        }
        let tol = 1e-5 * total;
        // E at (p, q), zero off the lower triangle.
        let at = |p: usize, q: usize| if p > q { e[p][q] } else { 0.0 };
        let mut root = [[0.0; PREISACH_LEVELS]; PREISACH_LEVELS];
        for i in 0..PREISACH_LEVELS {
            if e[i][i].abs() > tol {
                return Err(ParamError::OutOfRange("preisach.everett", "zero on the diagonal E(h, h)"));
            }
            for j in 0..i {
                // Weight of the relay cell α ∈ [h_{i−1}, h_i], β ∈ [h_j, h_{j+1}]; one that
                // overflows (entries far beyond the total) or is NaN is refused too.
                let weight = at(i, j) - at(i - 1, j) - at(i, j + 1) + at(i - 1, j + 1);
                if !(weight.is_finite() && weight >= -tol) {
                    return Err(ParamError::OutOfRange(
                        "preisach.everett",
                        "a table with non-negative relay weights (E rising in alpha, falling in beta)",
                    ));
                }
                root[i][j] = crate::math::sqrt(e[i][j].max(0.0));
            }
        }
        // The total as the interpolation gives it at (H_max, −H_max): saturation is exactly ±M_s.
        let total = root[PREISACH_LEVELS - 1][0] * root[PREISACH_LEVELS - 1][0];
        Ok(Self { h_max, root, total })
    }

    /// Builds the table over ±`h_max_a_per_m` (in [1, 1e7] A/m) from a density μ(α, β) ≥ 0 (any
    /// scale) and normalises the total to `total` (in [1e3, 1e7] A/m). Each grid cell gets the
    /// mean of μ over 4 × 4 points inside it (only those with α ≥ β on the diagonal cells) times
    /// its area.
    pub fn from_density(
        h_max_a_per_m: f32,
        total: f32,
        density: impl Fn(f32, f32) -> f32,
    ) -> Result<Self, ParamError> {
        let h_max = field_scale("preisach.h_max_a_per_m", h_max_a_per_m)?;
        let total = saturation("preisach.ms_a_per_m", total)?;
        let mut table = Self::unfilled(h_max);
        table.fill(total, density);
        if !(table.total.is_finite() && table.total > 0.0) {
            return Err(ParamError::OutOfRange(
                "preisach density",
                "positive and finite somewhere in the relay plane",
            ));
        }
        Ok(table)
    }

    /// A table over ±`h_max` (> 0) to [`Self::fill`]: zero everywhere.
    fn unfilled(h_max: f32) -> Self {
        Self { h_max, root: [[0.0; PREISACH_LEVELS]; PREISACH_LEVELS], total: 0.0 }
    }

    /// Integrates the density into this table (`total` > 0; the table's total is not positive
    /// and finite when μ is zero everywhere or not finite), in place: the table is 4 KB, and the firmware
    /// builds one on its deepest stack path (a model constructed at boot or by a `load`
    /// command), where each builder that returned a copy held one.
    fn fill(&mut self, total: f32, density: impl Fn(f32, f32) -> f32) {
        let h_max = self.h_max;
        let step = 2.0 * h_max / (PREISACH_LEVELS - 1) as f32;
        let level = |k: usize| -h_max + step * k as f32;
        // E first, in the array that then holds √E.
        let e = &mut self.root;
        // E[i][j] = E[i−1][j] + E[i][j+1] − E[i−1][j+1] + w(cell α∈[h_{i−1},h_i], β∈[h_j,h_{j+1}]).
        for d in 1..PREISACH_LEVELS {
            for j in 0..PREISACH_LEVELS - d {
                let i = j + d;
                let mut sum = 0.0;
                for p in 0..4 {
                    for q in 0..4 {
                        let a = level(i - 1) + step * (p as f32 + 0.5) / 4.0;
                        let b = level(j) + step * (q as f32 + 0.5) / 4.0;
                        if a >= b {
                            sum += density(a, b).max(0.0);
                        }
                    }
                }
                let w = sum / 16.0 * step * step;
                let inner = if d >= 2 { e[i - 1][j + 1] } else { 0.0 };
                e[i][j] = e[i - 1][j] + e[i][j + 1] - inner + w;
            }
        }
        // Every cell weight is ≥ 0, so the table needs none of `new`'s checks but the total's.
        let scale = total / e[PREISACH_LEVELS - 1][0];
        for row in e.iter_mut() {
            for v in row.iter_mut() {
                *v = crate::math::sqrt((*v * scale).max(0.0));
            }
        }
        self.total = self.root[PREISACH_LEVELS - 1][0] * self.root[PREISACH_LEVELS - 1][0];
    }

    /// Field range ±H_max [A/m].
    pub fn h_max_a_per_m(&self) -> f32 {
        self.h_max
    }

    /// E(H_max, −H_max): the output swing from negative saturation to the middle.
    pub fn total(&self) -> f32 {
        self.total
    }

    /// The grid values E (row α index, column β index), as stored: the squares of √E.
    pub fn values(&self) -> [[f32; PREISACH_LEVELS]; PREISACH_LEVELS] {
        self.root.map(|row| row.map(|r| r * r))
    }

    /// One (maximum, minimum) pair's share of the relay output's sum, E(M_k, m_{k−1}) −
    /// E(M_k, m_k): the forward output, the inverse's pair sums and its trial evaluations all
    /// add it so, in the same order, bit for bit.
    #[inline]
    fn pair_term(&self, max: f32, m_prev: f32, m_next: f32) -> f32 {
        self.everett(max, m_prev) - self.everett(max, m_next)
    }

    /// E(α, β) for α ≥ β (clamped to the grid); 0 when α ≤ β.
    #[inline]
    pub fn everett(&self, alpha: f32, beta: f32) -> f32 {
        if alpha <= beta {
            return 0.0;
        }
        let scale = (PREISACH_LEVELS - 1) as f32 / (2.0 * self.h_max);
        let top = (PREISACH_LEVELS - 1) as f32;
        // Compare-and-select, not `f32::clamp`: a library call on the M4F (no VMAXNM), and this
        // runs twice per evaluation of the inverse's search.
        let on_grid = |u: f32| {
            if u < 0.0 {
                0.0
            } else if u > top {
                top
            } else {
                u
            }
        };
        let ua = on_grid((alpha + self.h_max) * scale);
        let ub = on_grid((beta + self.h_max) * scale);
        // Cell indices (the last level belongs to the cell below it).
        let ia = (ua as usize).min(PREISACH_LEVELS - 2);
        let ib = (ub as usize).min(PREISACH_LEVELS - 2);
        let (fa, fb) = (ua - ia as f32, ub - ib as f32);
        let r = &self.root;
        let root_e = if ia == ib {
            // Diagonal cell: linear on the triangle (ib, ib)–(ib+1, ib)–(ib+1, ib+1).
            r[ia + 1][ib] * crate::math::at_least(fa - fb, 0.0)
        } else {
            let low = r[ia][ib] + (r[ia][ib + 1] - r[ia][ib]) * fb;
            let high = r[ia + 1][ib] + (r[ia + 1][ib + 1] - r[ia + 1][ib]) * fb;
            low + (high - low) * fa
        };
        root_e * root_e
    }
}

/// [`PreisachParams`] checked, before the table is built: the Lorentzian density of checked
/// widths is positive everywhere, so building its table cannot fail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ValidPreisachParams {
    ms: f32,
    hc: f32,
    sigma: f32,
    interaction_spread: Option<f32>,
    h_max: f32,
    rho: f32,
    h_r: f32,
}

impl PreisachParams {
    /// Checks every parameter (names the first one out of range).
    pub(crate) fn validated(&self) -> Result<ValidPreisachParams, ParamError> {
        let ms = saturation("preisach.ms_a_per_m", self.ms_a_per_m)?;
        let hc = field_scale("preisach.coercive_a_per_m", self.coercive_a_per_m)?;
        let sigma = field_scale("preisach.spread_a_per_m", self.spread_a_per_m)?;
        let h_max = field_scale("preisach.h_max_a_per_m", self.h_max_a_per_m)?;
        if hc >= h_max {
            return Err(ParamError::OutOfRange("preisach.coercive_a_per_m", "below preisach.h_max_a_per_m"));
        }
        let rho = self.reversible_fraction_or_default();
        if !(rho.is_finite() && (0.0..0.95).contains(&rho)) {
            return Err(ParamError::OutOfRange("preisach.reversible_fraction", "in [0, 0.95)"));
        }
        let h_r = field_scale("preisach.reversible_field_a_per_m", self.reversible_field_or_default())?;
        let interaction_spread = match self.interaction_spread_a_per_m {
            Some(su) => Some(field_scale("preisach.interaction_spread_a_per_m", su)?),
            None => None,
        };
        Ok(ValidPreisachParams { ms, hc, sigma, interaction_spread, h_max, rho, h_r })
    }

    /// ρ as the model uses it (0 when not given).
    pub fn reversible_fraction_or_default(&self) -> f32 {
        self.reversible_fraction.unwrap_or(0.0)
    }

    /// h_r as the model uses it (the interaction spread, else the spread, when not given).
    pub fn reversible_field_or_default(&self) -> f32 {
        self.reversible_field_a_per_m
            .unwrap_or(self.interaction_spread_a_per_m.unwrap_or(self.spread_a_per_m))
    }
}

/// Most evaluations one inverse solve makes: Brent's rule halves a bracket at least every
/// other step, so the bracket reaches 2⁻²³ of the range within them whatever the law's shape.
/// Measured: 1.9 on average on a 100 Hz sine, 8 at most there; at most 16 over a grid of moves
/// from one range end to the other (`the_inverse_meets_every_reachable_target`).
const SOLVE_EVALUATIONS: usize = 72;

/// Validated Preisach model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preisach {
    table: EverettTable,
    /// The relays' share 1 − ρ.
    relay_share: f32,
    /// ρ·M_s [A/m].
    reversible_ms: f32,
    /// 1/h_r [m/A].
    inv_reversible_field: f32,
}

/// Staircase memory of the relay plane (mutable, per sample). Fixed size, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreisachState {
    turning: [f32; PREISACH_MEMORY],
    len: u8,
    /// The input as applied, not clamped to ±H_max (the reversible part goes on rising).
    h: f32,
}

impl Default for PreisachState {
    /// Negative saturation (every relay down), at H = −∞.
    fn default() -> Self {
        Self { turning: [0.0; PREISACH_MEMORY], len: 0, h: f32::NEG_INFINITY }
    }
}

/// What the inverse keeps between samples for one state sequence. The running sums of the relay
/// plane's completed (maximum, minimum) pairs: `sum[q]` is the sum of pair 0..q's terms in
/// [`Preisach::output`]'s order, so an output is `sum[q] +` its last pair's term, the same
/// additions in the same order, bit for bit; a field iteration then costs two Everett look-ups
/// instead of the whole staircase. And the last solve's slope dM/dH, the first secant step's.
/// (`CompensatorState` holds one; `scripts/fw bench inverse-preisach`: 65 000 instructions per
/// compensator step on the M4F with a copy of the state per iteration and 24 halvings.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseCache {
    /// One more than a full memory's pairs: a trial may count one more turning point.
    sum: [f32; PREISACH_MEMORY / 2 + 1],
    /// `sum[..=valid]` hold for the state they follow.
    valid: u8,
    /// dM/dH over the last solve's step [1]; 0 before the first.
    slope: f32,
}

impl Default for InverseCache {
    fn default() -> Self {
        Self { sum: [0.0; PREISACH_MEMORY / 2 + 1], valid: 0, slope: 0.0 }
    }
}

impl InverseCache {
    /// The state's point `lowest` and those after it changed: drop the sums that used them
    /// (`sum[q]` uses the points below index 2q).
    fn changed_from(&mut self, lowest: usize) {
        self.valid = self.valid.min((lowest / 2) as u8);
    }

    /// `sum[q]` for the points `pts` (pairs below q complete in `pts`).
    fn up_to(&mut self, t: &EverettTable, pts: &[f32], q: usize) -> f32 {
        while (self.valid as usize) < q {
            let p = self.valid as usize;
            let m_prev = if p == 0 { -t.h_max } else { pts[2 * p - 1] };
            let max = pts[2 * p];
            self.sum[p + 1] = self.sum[p] + t.pair_term(max, m_prev, pts[2 * p + 1]);
            self.valid += 1;
        }
        self.sum[q]
    }
}

impl PreisachState {
    /// The stored turning points, oldest first (maxima at even positions); the last is the
    /// current input.
    pub fn turning_points(&self) -> &[f32] {
        &self.turning[..self.len as usize]
    }

    /// Appends `h`; returns the lowest index whose point changed (the merge's, when full).
    fn push(&mut self, h: f32, h_max: f32) -> usize {
        let lowest = if self.len as usize == PREISACH_MEMORY {
            self.merge_closest_pair(h_max)
        } else {
            self.len as usize
        };
        self.turning[self.len as usize] = h;
        self.len += 1;
        lowest
    }

    /// Full memory: drops the two adjacent turning points whose removal moves the staircase
    /// least. Removing t[j], t[j+1] cuts off the rectangle |t[j] − t[j+2]| × |t[j+1] − t[j−1]|
    /// of the relay plane (t[−1] = −H_max), the smallest is taken; the staircase stays
    /// alternating and monotone. In a slowly decaying oscillation — a chirp whose current falls
    /// with frequency, an AC demagnetisation — that is a pair of nearly equal loops deep in the
    /// memory, a change of second order. Dropping the innermost loop instead (as before) made M
    /// jump at every reversal once the memory was full: a forcing at twice the drive frequency
    /// that rang a 1 kHz actuator mode during a 550 Hz chirp segment forty times above the
    /// measured response.
    fn merge_closest_pair(&mut self, h_max: f32) -> usize {
        let n = self.len as usize;
        let t = &self.turning;
        let mut best = (f32::INFINITY, n - 3);
        for j in 0..n - 2 {
            let before = if j == 0 { -h_max } else { t[j - 1] };
            let area = (t[j] - t[j + 2]).abs() * (t[j + 1] - before).abs();
            if area < best.0 {
                best = (area, j);
            }
        }
        let j = best.1;
        self.turning.copy_within(j + 2..n, j);
        self.len -= 2;
        j
    }

    /// Moves the input to `h` (already clamped to ±H_max), applying the wiping-out rule. Returns
    /// the lowest index whose point changed or went (for [`InverseCache`]).
    fn apply(&mut self, h: f32, h_max: f32) -> usize {
        let n = self.len as usize;
        if n == 0 {
            if h > -h_max {
                self.push(h, h_max);
            }
            return 0;
        }
        let rising = n % 2 == 1; // the last stored point is a maximum
        let last = self.turning[n - 1];
        let mut lowest = if (rising && h >= last) || (!rising && h <= last) {
            self.turning[n - 1] = h;
            n - 1
        } else {
            self.push(h, h_max)
        };
        loop {
            let n = self.len as usize;
            if n >= 3 {
                let (cur, older) = (self.turning[n - 1], self.turning[n - 3]);
                let is_max = n % 2 == 1;
                if (is_max && cur >= older) || (!is_max && cur <= older) {
                    // The input passed an older extremum of its kind: wipe it and its partner.
                    self.turning[n - 3] = cur;
                    self.len -= 2;
                    lowest = lowest.min(n - 3);
                    continue;
                }
            }
            if n == 2 && self.turning[1] <= -h_max {
                self.len = 0; // back to negative saturation
                lowest = 0;
            }
            break;
        }
        lowest
    }
}

impl Preisach {
    /// From the parametric (Lorentzian) density of [`PreisachParams`].
    pub fn new(p: PreisachParams) -> Result<Self, ParamError> {
        Ok(Self::lorentzian(&p.validated()?))
    }

    /// The model of validated parameters, its table filled in place (`EverettTable::fill`:
    /// infallible, so built where it is returned).
    pub(crate) fn lorentzian(v: &ValidPreisachParams) -> Self {
        let ValidPreisachParams { ms, hc, sigma, interaction_spread, h_max, rho, h_r } = *v;
        let mut model = Self {
            table: EverettTable::unfilled(h_max),
            relay_share: 1.0 - rho,
            reversible_ms: rho * ms,
            inv_reversible_field: 1.0 / h_r,
        };
        let lorentz = |x: f32| 1.0 / (1.0 + x * x);
        match interaction_spread {
            Some(su) => model
                .table
                .fill(ms, |a, b| lorentz((0.5 * (a - b) - hc) / sigma) * lorentz(0.5 * (a + b) / su)),
            None => model.table.fill(ms, |a, b| lorentz((a - hc) / sigma) * lorentz((b + hc) / sigma)),
        }
        model
    }

    /// From an Everett table (measured first-order reversal curves, or fitted), without a
    /// reversible part.
    pub fn from_table(table: EverettTable) -> Self {
        Self { table, relay_share: 1.0, reversible_ms: 0.0, inv_reversible_field: 0.0 }
    }

    /// The Everett table.
    pub fn table(&self) -> &EverettTable {
        &self.table
    }

    /// The state after AC demagnetisation (alternating, decaying field from ±H_max to zero).
    pub fn demagnetized(&self) -> PreisachState {
        let mut s = PreisachState::default();
        let h_max = self.table.h_max;
        let pairs = PREISACH_MEMORY / 2 - 1;
        for k in 0..pairs {
            let h = h_max * (pairs - k) as f32 / pairs as f32;
            s.apply(h, h_max);
            s.apply(-0.999 * h, h_max);
        }
        s.apply(0.0, h_max);
        s.h = 0.0;
        s
    }

    /// Output for the state `s`: the relays' and the reversible part's.
    #[inline]
    pub fn output(&self, s: &PreisachState) -> f32 {
        let reversible = if self.reversible_ms > 0.0 {
            self.reversible_ms * crate::math::tanh(s.h * self.inv_reversible_field)
        } else {
            0.0
        };
        self.relay_share * self.relay_output(s) + reversible
    }

    /// The relay plane's output for `s` (its last turning point is the current input).
    #[inline]
    fn relay_output(&self, s: &PreisachState) -> f32 {
        let t = &self.table;
        let pts = s.turning_points();
        let mut m_prev = -t.h_max;
        let mut up = 0.0;
        let mut k = 0;
        while k < pts.len() {
            let max = pts[k];
            let m_next = if k + 1 < pts.len() { pts[k + 1] } else { max };
            up += t.pair_term(max, m_prev, m_next);
            m_prev = m_next;
            k += 2;
        }
        2.0 * up - t.total()
    }

    /// Moves the field to `h` and returns M [A/m]. A non-finite `h` holds the state.
    #[inline]
    pub fn step(&self, s: &mut PreisachState, h: f32) -> f32 {
        if h.is_finite() {
            self.advance(s, h);
        }
        self.output(s)
    }

    /// Moves the state's input to the finite `h`; returns the lowest turning point it changed.
    #[inline]
    fn advance(&self, s: &mut PreisachState, h: f32) -> usize {
        let lowest = s.apply(crate::math::within(h, self.table.h_max), self.table.h_max);
        s.h = h;
        lowest
    }

    /// The field that gives magnetization `m` from state `s`, applied to `s`. The output is
    /// monotone in the field from any state, so a safeguarded secant search: from the present
    /// input and a step along the last solve's slope (else a probe), secant steps kept inside
    /// the bracket found so far, a halving of it whenever a step is not shorter than half the
    /// one before the last (Brent's rule), to 10⁻⁵ M_s or 2⁻²³ of the range ±H_max (widened by
    /// 4 h_r with a reversible part, which goes on rising past H_max), in at most
    /// 72 evaluations; then the best field evaluated. A target beyond what the branch
    /// reaches gives the range's end.
    pub fn field_for(&self, s: &mut PreisachState, m: f32) -> f32 {
        self.field_for_with(s, &mut InverseCache::default(), m)
    }

    /// The inverse's cache for `s` with its pair sums filled (their cost, one pass over the
    /// staircase, is paid here rather than in the first solve: from the demagnetised state,
    /// 46 Everett look-ups).
    pub fn inverse_cache(&self, s: &PreisachState) -> InverseCache {
        let mut cache = InverseCache::default();
        let n = s.len as usize;
        if n > 0 {
            cache.up_to(&self.table, &s.turning, (n - 1) / 2);
        }
        cache
    }

    /// [`Self::field_for`] with the state's pair sums kept between calls (`sums` must have
    /// followed `s` since both were new): each evaluation costs two Everett look-ups, not the
    /// whole staircase (`trial_output`).
    pub fn field_for_with(&self, s: &mut PreisachState, sums: &mut InverseCache, m: f32) -> f32 {
        let (h, _) = self.solve_field(s, sums, m);
        sums.changed_from(self.advance(s, h));
        h
    }

    /// [`Self::field_for_with`]'s field, `s` left as it is: the inverse compensator applies
    /// the field its current limit lets through ([`Self::move_with`]).
    pub(crate) fn solve_with(&self, s: &PreisachState, sums: &mut InverseCache, m: f32) -> f32 {
        self.solve_field(s, sums, m).0
    }

    /// M after a step from `s` to the finite field `h`, evaluated as the solve's trials are (two
    /// Everett look-ups with the pair `sums`, not the whole staircase); `s` stays.
    pub(crate) fn output_after_with(&self, s: &PreisachState, sums: &mut InverseCache, h: f32) -> f32 {
        self.trial_output(s, sums, h).0
    }

    /// Moves `s`, and the `sums` that follow it, to the finite field `h`.
    pub(crate) fn move_with(&self, s: &mut PreisachState, sums: &mut InverseCache, h: f32) {
        sums.changed_from(self.advance(s, h));
    }

    /// The field and how many evaluations found it.
    fn solve_field(&self, s: &PreisachState, sums: &mut InverseCache, m: f32) -> (f32, usize) {
        let range = if self.reversible_ms > 0.0 {
            self.table.h_max + 4.0 / self.inv_reversible_field
        } else {
            self.table.h_max
        };
        let kept = sums.slope;
        let mut evaluations = 0;
        let mut eval = |h: f32| {
            evaluations += 1;
            self.trial_output(s, sums, h).0 - m
        };
        let tol_m = 1e-5 * self.table.total;
        let tol_h = range * (1.0 / 8_388_608.0);
        // The bracket [lo, hi] and whether each end was evaluated (f < 0 at lo, > 0 at hi).
        let (mut lo, mut hi, mut lo_seen, mut hi_seen) = (-range, range, false, false);
        let x0 = if s.h.is_finite() { crate::math::within(s.h, range) } else { 0.0 };
        let (mut x, mut f) = (x0, eval(x0));
        let f0 = f;
        // Reversing (the target lies against the present branch): the new branch starts flat,
        // M − M(x0) ≈ 2 E(x, x0) ∝ (x − x0)² (003 §3), so the secant runs on the signed square
        // root of that change, which is close to linear in x; along the branch, on M itself.
        let rising = s.len % 2 == 1;
        let reversing = (f0 < 0.0) != rising;
        let root_f0 = crate::math::sqrt(f0.abs()).copysign(-f0);
        let straighten = |f: f32| {
            if reversing {
                let d = f - f0;
                crate::math::sqrt(d.abs()).copysign(d) - root_f0
            } else {
                f
            }
        };
        let mut y = straighten(f);
        // The first step along the last solve's slope, else a probe of 10⁻³ of the range.
        let mut next = if kept > 0.0 && kept.is_finite() && !reversing {
            x - f / kept
        } else {
            x - f.signum() * 1e-3 * range
        };
        let (mut x_prev, mut y_prev);
        let (mut best_x, mut best_f) = (x, f);
        // Safeguards (a secant alone can creep from one side for ever): once the target is
        // bracketed, a halving whenever a step would not be shorter than half the step before
        // the last (Brent's rule); before, the end the target lies towards after four steps on
        // one side.
        let mut steps = [f32::INFINITY; 2];
        let mut one_sided = 0;
        let h = 'search: {
            for _ in 0..SOLVE_EVALUATIONS {
                if f.abs() <= tol_m {
                    break 'search x;
                }
                if f < 0.0 {
                    (lo, lo_seen) = (x, true);
                } else {
                    (hi, hi_seen) = (x, true);
                }
                if hi - lo <= tol_h {
                    break 'search 0.5 * (lo + hi);
                }
                let creeping = if lo_seen && hi_seen {
                    (next - x).abs() > 0.5 * steps[0]
                } else {
                    one_sided += 1;
                    one_sided > 4
                };
                if creeping || next <= lo || next >= hi || !next.is_finite() {
                    // Towards the bracket's end the target lies by, when that was never
                    // evaluated (an end the target lies beyond is the answer), else its middle.
                    next = if f < 0.0 && !hi_seen {
                        hi
                    } else if f > 0.0 && !lo_seen {
                        lo
                    } else {
                        0.5 * (lo + hi)
                    };
                }
                steps = [steps[1], (next - x).abs()];
                (x_prev, y_prev) = (x, y);
                x = next;
                f = eval(x);
                y = straighten(f);
                if f.abs() < best_f.abs() {
                    (best_x, best_f) = (x, f);
                }
                if (x == range && f < 0.0) || (x == -range && f > 0.0) {
                    break 'search x;
                }
                let slope = (y - y_prev) / (x - x_prev);
                next = if slope > 0.0 { x - y / slope } else { 0.5 * (lo + hi) };
            }
            best_x
        };
        // The step's own slope dM/dH, for the next solve's first step (kept when it did not move).
        let slope = (f - f0) / (x - x0);
        if slope > 0.0 && slope.is_finite() {
            sums.slope = slope;
        } else if x != x0 {
            sums.slope = 0.0;
        }
        (h, evaluations)
    }

    /// What [`Self::step`] to the finite `h` would return from `s`, without changing `s`, and
    /// whether exactly: not when the step would merge two turning points first (a full memory,
    /// a change of second order, see `merge_closest_pair`); this then counts as if the memory
    /// had room for one more.
    fn trial_output(&self, s: &PreisachState, sums: &mut InverseCache, h: f32) -> (f32, bool) {
        let t = &self.table;
        let h_max = t.h_max;
        let hc = crate::math::within(h, h_max);
        let pts = &s.turning;
        let n = s.len as usize;
        // The staircase `apply` would leave: pts[..len − 1], then hc (the wiping-out rule as in
        // `apply`; the points it compares with are never the ones it changed).
        let mut len = if n == 0 {
            usize::from(hc > -h_max)
        } else {
            let rising = n % 2 == 1;
            if (rising && hc >= pts[n - 1]) || (!rising && hc <= pts[n - 1]) {
                n
            } else {
                n + 1
            }
        };
        let exact = len <= PREISACH_MEMORY;
        if n > 0 {
            loop {
                if len >= 3 {
                    let is_max = len % 2 == 1;
                    let older = pts[len - 3];
                    if (is_max && hc >= older) || (!is_max && hc <= older) {
                        len -= 2;
                        continue;
                    }
                }
                if len == 2 && hc <= -h_max {
                    len = 0;
                }
                break;
            }
        }
        let relay = if len == 0 {
            2.0 * 0.0 - t.total()
        } else {
            let q = (len - 1) / 2;
            let m_prev = if q == 0 { -h_max } else { pts[2 * q - 1] };
            // The last pair: a maximum at hc (E(hc, hc) = 0 comes back at once), or one closed by hc.
            let last =
                if len % 2 == 1 { t.pair_term(hc, m_prev, hc) } else { t.pair_term(pts[2 * q], m_prev, hc) };
            2.0 * (sums.up_to(t, pts, q) + last) - t.total()
        };
        let reversible = if self.reversible_ms > 0.0 {
            self.reversible_ms * crate::math::tanh(h * self.inv_reversible_field)
        } else {
            0.0
        };
        (self.relay_share * relay + reversible, exact)
    }
}

#[cfg(test)]
mod tests;
