//! One candidate effect, refitted and judged: its cut of the scored error, the files it wins on
//! (a sign test), its gain by BIC, and the rules that make it the verdict.

use crate::fit::FitResult;
use model_core::Effect;
use serde::Serialize;

/// A candidate must cut the scored NRMSE at least this much to be the verdict (the issue's
/// smallest useful cut: below it, adding the effect is not worth its parameters to a user).
pub const MIN_CUT: f64 = 1.5;

/// A refit that cuts the error this much is decisive even when its signature, a first-order
/// sketch of the effect, does not correlate with the residual.
pub const DECISIVE_CUT: f64 = 3.0;

/// 95 % quantile of χ² with one degree of freedom: a one-regressor signature is significant
/// when N_eff·R² exceeds it (the score test's statistic).
pub const CHI2_1_95: f64 = 3.841;

/// Probability of a file improving by chance under "the effect does nothing" (a fair coin), and
/// the one-sided significance of the sign test over the scored files.
pub(crate) const SIGN_TEST_ALPHA: f64 = 0.05;

/// A BIC difference below this is not strong evidence for one model over another (Kass &
/// Raftery 1995: 6 is "strong", posterior odds about 20 : 1).
pub(crate) const BIC_STRONG: f64 = 6.0;

/// Whether two candidates' signature R² differ by more than an R²'s significance at the smaller
/// of their effective sample sizes (χ²₁ at 5 % over N_eff): below it the difference is noise.
pub(crate) fn r2_differ(a: &Candidate, b: &Candidate) -> bool {
    (a.evidence_r2 - b.evidence_r2).abs() > CHI2_1_95 / a.n_eff.min(b.n_eff).max(1.0)
}

/// Which of the candidates the data cannot tell apart is the verdict, and whether its signature
/// decided: the one whose signature R² exceeds every other's by more than an R²'s significance
/// ([`r2_differ`]), else the one with the largest ΔBIC. Both are properties of the set, not of
/// its order (a pairwise "R² if they differ, else ΔBIC" is not transitive, and picking with it
/// depended on the order the candidates arrived in); equal ΔBIC, only from identical refits,
/// falls to the effect's name.
pub(crate) fn choose_among_tied(tied: &[&Candidate]) -> (usize, bool) {
    let dominates = |i: usize| {
        tied.iter()
            .enumerate()
            .all(|(j, c)| j == i || (r2_differ(tied[i], c) && tied[i].evidence_r2 > c.evidence_r2))
    };
    if let Some(i) = (0..tied.len()).find(|&i| dominates(i)).filter(|_| tied.len() > 1) {
        return (i, true);
    }
    let best = (0..tied.len())
        .max_by(|&i, &j| {
            tied[i]
                .delta_bic
                .total_cmp(&tied[j].delta_bic)
                .then(tied[j].effect.name().cmp(tied[i].effect.name()))
        })
        .unwrap_or(0);
    (best, false)
}

/// One candidate effect, as the JSON contract lists it.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// The effect (its name in JSON).
    pub effect: Effect,
    /// `displacement` (or `current`).
    pub channel: &'static str,
    /// Combined score in [0, 1]: evidence R² and the refit's error cut.
    pub score: f64,
    /// The evidence in words.
    pub evidence: String,
    /// Validation NRMSE of the given structure.
    pub nrmse_before: f64,
    /// Validation NRMSE with this effect added and refitted.
    pub nrmse_after: f64,
    /// Share of residual variance the effect's signature explains.
    pub evidence_r2: f64,
    /// Scored (validation, else fit) files on which the refit is lower than the baseline.
    pub files_improved: usize,
    /// Scored files.
    pub files_scored: usize,
    /// Scored files on which the effect shows: switching it off in the refit changes the
    /// prediction there by more than the measurement noise (rms, estimated from the refit's
    /// residual). Only these vote in the sign test: on the others a change of error comes from
    /// the other parameters moving, not from the effect. Every scored file for a law refinement
    /// and on the current channel.
    pub files_showing: usize,
    /// Of [`Candidate::files_showing`], those on which the refit is lower than the baseline.
    pub files_improved_showing: usize,
    /// Of [`Candidate::files_showing`], those on which the refit's prediction differs from the
    /// baseline's by more than the noise: the sign test's votes (a file that moves by less than
    /// its own noise is a tie, no evidence either way).
    pub files_deciding: usize,
    /// Of [`Candidate::files_deciding`], those on which the refit is lower: the sign test's wins.
    pub files_improved_deciding: usize,
    /// The scored files are validation files (held out from every fit).
    pub held_out: bool,
    /// BIC gain of the refit on the scored (validation, else fit) files with the effective
    /// sample size (positive: supported): Σ N_eff,f ln(MSE_before,f / MSE_after,f) − Δk ln(Σ N_eff,f).
    pub delta_bic: f64,
    /// Effective number of independent samples in the baseline's fit residual (N/τ per file, τ
    /// its integrated autocorrelation time: [`crate::spectral::effective_samples`]).
    pub n_eff: f64,
    /// The refit's NRMSE per scored file (on `channel`).
    pub per_file_after: Vec<f64>,
    /// Identified parameters of the refit.
    #[serde(skip)]
    pub refit: Option<FitResult>,
}

/// Before/after ratio of an error: infinite when a refit is exact (an exact refit of a
/// noise-free recording is the strongest evidence, not none), 1 when either is not a number or
/// both are zero.
pub(crate) fn error_cut(before: f64, after: f64) -> f64 {
    if !(before.is_finite() && after.is_finite()) || before <= 0.0 {
        1.0
    } else if after > 0.0 {
        before / after
    } else {
        f64::INFINITY
    }
}

/// A cut in words: "2.4× lower", "1.3× higher", "1.02× lower" (two decimals near 1, where one
/// would print "1.0× lower" beside two different errors), "unchanged", "to zero".
pub(crate) fn cut_words(cut: f64) -> String {
    let ratio = if cut >= 1.0 { cut } else { 1.0 / cut };
    let direction = if cut >= 1.0 { "lower" } else { "higher" };
    if cut.is_infinite() {
        "to zero".into()
    } else if ratio < 1.005 {
        "unchanged".into()
    } else if ratio < 1.095 {
        format!("{ratio:.2}× {direction}")
    } else {
        format!("{ratio:.1}× {direction}")
    }
}

impl Candidate {
    /// Before/after ratio of the scored NRMSE.
    pub fn cut(&self) -> f64 {
        error_cut(self.nrmse_before, self.nrmse_after)
    }

    /// The decision rule: the refit cuts the error at least [`MIN_CUT`]×, is lower on enough
    /// of the scored files it shows and decides in ([`required_wins`] of
    /// [`Candidate::files_deciding`]) and has positive ΔBIC with the effective sample size.
    /// Scored on the fit files (no validation files), where any added flexibility gains, its
    /// signature must also be significant (N_eff·R² > χ²₁(95 %)) or its cut decisive; on held-out
    /// files the gain is itself the evidence (the first-order signature is a poor proxy where the
    /// effect acts before a nonlinearity or a resonance, e.g. distributed eddy currents).
    pub fn passes(&self) -> bool {
        let indicated =
            self.held_out || self.n_eff * self.evidence_r2 > CHI2_1_95 || self.cut() >= DECISIVE_CUT;
        self.cut() >= MIN_CUT
            && self.files_deciding > 0
            && self.files_improved_deciding >= required_wins(self.files_deciding)
            && self.delta_bic > 0.0
            && indicated
    }
}

/// The most files of which [`required_wins`] asks every one (7 at 5 %: 7 of 8 suffice).
pub(crate) fn all_must_improve_up_to() -> usize {
    (1..64).take_while(|&n| required_wins(n) == n).last().unwrap_or(0)
}

/// Files a candidate must improve out of `n`: the fewest wins a one-sided sign test accepts at
/// [`SIGN_TEST_ALPHA`]; below five files no count is significant, so all must improve.
pub fn required_wins(n: usize) -> usize {
    // P(at least m wins of n | fair coin).
    let tail = |m: usize| -> f64 { (m..=n).map(|k| binomial(n, k)).sum::<f64>() / 2f64.powi(n as i32) };
    (0..=n).find(|&m| tail(m) <= SIGN_TEST_ALPHA).unwrap_or(n)
}

pub(crate) fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}
