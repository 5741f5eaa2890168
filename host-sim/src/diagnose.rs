//! Diagnosis: fit the given structure, look at what it leaves unexplained, name the missing
//! physics, and prove it by refitting.
//!
//! 1. **Evidence** (a score test, per candidate effect): each missing effect, switched on
//!    weakly, changes the model output by a characteristic signature computed from the fitted
//!    model's own signals — a lag (eddy currents, amplifier, sensor delay) adds −τ·dy/dt;
//!    resonance adds −ÿ/ω_n²; hysteresis adds a branch-dependent term ∝ sign(dH/dt);
//!    saturation a cubic term in the field excursion; creep lowpass(y) − y; coil heating the
//!    accumulated ∫i² dt. The share of residual variance each signature explains (R², pooled
//!    over the files) is its evidence score. Lags share a first-order signature, so the evidence
//!    alone cannot tell eddy currents, amplifier and delay apart: the refit does.
//! 2. **Trends across files**: error against excitation frequency, amplitude and record length.
//! 3. **Refit**: the structure plus each candidate, identified again (afresh from the start
//!    values and refined from the baseline's optimum, the better kept), scored on the
//!    validation files (fit files when there are none), each file after its burn-in ([`burn_in`]:
//!    the first drive cycle, because the rig's initial magnetic state is unknown).
//! 4. **Decision** (evidence that holds when no model is exact; see [`Candidate::passes`]): a
//!    candidate passes when its refit cuts the scored error ≥ [`MIN_CUT`]×, is lower on enough
//!    of the scored files it shows in for a one-sided sign test at 5 % ([`required_wins`]: all of
//!    them below five files; a file it does not show in, where switching it off moves the refit's
//!    prediction less than the measurement noise, does not vote), gains on the scored files (validation when given: there extra parameters cannot
//!    buy a gain) by BIC with the *effective* sample size of the baseline residual
//!    (N_eff = N(1 − ρ)/(1 + ρ): a residual full of model-form error is worth few
//!    independent samples), and, scored on the fit files only, its signature is significant
//!    (N_eff·R² > χ²₁(95 %)) or its cut decisive. Each
//!    candidate is judged on the measured channel nearest where it acts: with `current_A` and
//!    `command_V` measured, amplifier dynamics on the current (command → current: static gain
//!    against the refit's amplifier); with a search coil's `flux_density_T`, the rod's field,
//!    magnetization and creep on the flux density; with `temperature_C`, coil heating on the
//!    temperature; the rest on the displacement. Passing candidates
//!    on one channel that the best does not beat on every file are not told apart: the data choose
//!    among them (signature R², then ΔBIC) and the diagnosis says which and why. A residual still
//!    structured after the final structure is reported with its size.

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use model_core::effects::{Candidacy, MagnetizationLaw, Signature, Stage};
use model_core::{Effect, ModelSpec};
use rayon::prelude::*;
use serde::Serialize;

use crate::fit::{self, evaluate, FitOptions, FitResult};
use crate::simulated::Simulation;
use crate::simulation::simulate;

mod alternatives;
mod judge;
mod searches;
use crate::error::InRecording;
use crate::progress;
use crate::recording::Recording;
use crate::signal::{correlation, reversal_positions, reversals};
pub(crate) use crate::spectral::effective_samples;
use crate::warning::Warning;
pub use alternatives::{check_ja_variants, other_law_structure, LawScore, VariantScore};

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
const SIGN_TEST_ALPHA: f64 = 0.05;
/// A BIC difference below this is not strong evidence for one model over another (Kass &
/// Raftery 1995: 6 is "strong", posterior odds about 20 : 1).
const BIC_STRONG: f64 = 6.0;

/// Search effort of a candidate's fresh fit (from the engineer's start values), beside its
/// refinement from the baseline: half of `gma fit`'s. On the independent rig's grid (docs/validation.md)
/// it named one effect fewer than full effort (26 against 27 of 66), in 0.8× the time of the
/// 8-file diagnosis bench.
pub const FRESH_EFFORT: f64 = 0.5;

/// Fewest samples per fit file for a verdict: the refits have up to about ten parameters, and
/// comparing them needs far more samples than parameters (20 per parameter).
pub const MIN_SAMPLES: usize = 200;

/// Whether two candidates' signature R² differ by more than an R²'s significance at the smaller
/// of their effective sample sizes (χ²₁ at 5 % over N_eff): below it the difference is noise.
fn r2_differ(a: &Candidate, b: &Candidate) -> bool {
    (a.evidence_r2 - b.evidence_r2).abs() > CHI2_1_95 / a.n_eff.min(b.n_eff).max(1.0)
}

/// Which of the candidates the data cannot tell apart is the verdict, and whether its signature
/// decided: the one whose signature R² exceeds every other's by more than an R²'s significance
/// ([`r2_differ`]), else the one with the largest ΔBIC. Both are properties of the set, not of
/// its order (a pairwise "R² if they differ, else ΔBIC" is not transitive, and picking with it
/// depended on the order the candidates arrived in); equal ΔBIC, only from identical refits,
/// falls to the effect's name.
fn choose_among_tied(tied: &[&Candidate]) -> (usize, bool) {
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
fn error_cut(before: f64, after: f64) -> f64 {
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
fn cut_words(cut: f64) -> String {
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
fn all_must_improve_up_to() -> usize {
    (1..64).take_while(|&n| required_wins(n) == n).last().unwrap_or(0)
}

/// Files a candidate must improve out of `n`: the fewest wins a one-sided sign test accepts at
/// [`SIGN_TEST_ALPHA`]; below five files no count is significant, so all must improve.
pub fn required_wins(n: usize) -> usize {
    // P(at least m wins of n | fair coin).
    let tail = |m: usize| -> f64 { (m..=n).map(|k| binomial(n, k)).sum::<f64>() / 2f64.powi(n as i32) };
    (0..=n).find(|&m| tail(m) <= SIGN_TEST_ALPHA).unwrap_or(n)
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// The whole diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// The structure as given.
    pub model: String,
    /// Its fit NRMSE (mean over fit files).
    pub nrmse_fit: f64,
    /// Its validation NRMSE, when validation files were given.
    pub nrmse_val: Option<f64>,
    /// Candidates, most likely first.
    pub candidates: Vec<Candidate>,
    /// The missing effect, or null.
    pub verdict: Option<Effect>,
    /// Effects the evidence could not separate from the verdict.
    pub undistinguished: Vec<Effect>,
    /// Candidates `--time-limit` left untested: with any, no verdict means undecided, not
    /// "nothing is missing".
    pub not_refitted: Vec<Effect>,
    /// Candidates whose refit `--time-limit` stopped before it converged (listed among the
    /// candidates with their best figures so far): with any, no verdict means undecided too.
    pub cut_short: Vec<Effect>,
    /// Residual whiteness, trends across files: findings in words.
    pub findings: Vec<String>,
    /// The fit of the given structure.
    #[serde(skip)]
    pub baseline: Option<FitResult>,
    /// `--time-limit` cut the work short: the baseline or some refits are the best found so
    /// far, and candidates not refitted in time are left out.
    #[serde(rename = "time_limit_reached")]
    pub time_limited: bool,
    /// `--ja-variants`: the given structure refitted in every J–A form, the given one first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ja_variants: Option<Vec<VariantScore>>,
    /// `--laws`: the given structure refitted with each other hysteresis law, the given first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub laws: Option<Vec<LawScore>>,
}

/// The share of residual variance a signature must explain to be significant at 95 % with
/// `n_eff` independent samples, in words; with too few samples no share can be, and that is said
/// instead of a threshold above 100 %.
fn significance_words(n_eff: f64) -> String {
    let threshold = 100.0 * CHI2_1_95 / n_eff.max(1.0);
    if threshold < 100.0 {
        format!("significant above {threshold:.1} % at N_eff = {n_eff:.0}")
    } else {
        format!(
            "not testable: the residual is so correlated that its {n_eff:.0} effective independent sample{} cannot \
             show significance",
            if n_eff.round() == 1.0 { "" } else { "s" }
        )
    }
}

/// The diagnosis in words (`--json` gives the same as one object): [`Diagnosis::headline`], then
/// [`Diagnosis::details`].
impl std::fmt::Display for Diagnosis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}\n{}", self.headline(), self.details())
    }
}

impl Diagnosis {
    /// The line a person reads first: the verdict (the missing effect and the model to try), or
    /// what no verdict means.
    pub fn headline(&self) -> String {
        match self.verdict {
            Some(v) => format!(
                "verdict: `{v}` is missing{} — try `--model {}`",
                if self.undistinguished.is_empty() {
                    String::new()
                } else {
                    format!(
                        ", or `{}` (the data do not tell them apart, below)",
                        self.undistinguished.iter().map(|e| e.name()).collect::<Vec<_>>().join("`, `")
                    )
                },
                // The canonical text of the model with it, as every other line names models.
                ModelSpec::parse(&self.model).map(|s| s.with(v).to_string()).unwrap_or_else(|_| format!(
                    "{}+{}",
                    self.model,
                    v.alias().unwrap_or(v.name())
                ))
            ),
            None => format!("verdict: {}", self.no_verdict()),
        }
    }

    /// What follows the headline: the given model's figures, the findings (doubts about the data
    /// first) and the candidates.
    pub fn details(&self) -> String {
        let mut lines = vec![format!(
            "model `{}`: fit NRMSE {:.3} % (whole files, as `gma fit`){}",
            self.model,
            self.nrmse_fit * 100.0,
            self.nrmse_val
                .map(|v| format!(
                    ", validation {:.3} % (after each file's burn-in, as every score below)",
                    v * 100.0
                ))
                .unwrap_or_default()
        )];
        lines.extend(self.findings.iter().map(|finding| format!("  - {finding}")));
        if !self.candidates.is_empty() {
            // The order `decide` gives; the score (R² and cut combined, for scripts) is not it.
            lines.push(
                "  candidates (most likely first: the verdict, then those that pass every test, then by cut; \
                 score = ½ R² + ½ the relative error drop):"
                    .into(),
            );
        }
        lines.extend(self.candidates.iter().map(|c| {
            format!(
                "    {:22} cut {:>5}  score {:.2}  {:.2} % → {:.2} %  {}",
                c.effect,
                format!("{:.2}×", c.cut()).replace("inf×", "∞"),
                c.score,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0,
                c.evidence
            )
        }));
        lines.join("\n")
    }
}

impl Diagnosis {
    /// What no verdict means, in words: nothing missing, or undecided when the time limit left
    /// candidates untested or stopped their refits.
    pub fn no_verdict(&self) -> String {
        if self.not_refitted.is_empty() && self.cut_short.is_empty() {
            return "nothing significant is missing".into();
        }
        let names = |l: &[Effect]| l.iter().map(|e| e.name()).collect::<Vec<_>>().join("`, `");
        let mut what = Vec::new();
        if !self.not_refitted.is_empty() {
            what.push(format!("left `{}` untested", names(&self.not_refitted)));
        }
        if !self.cut_short.is_empty() {
            what.push(format!("stopped the refit of `{}` before it converged", names(&self.cut_short)));
        }
        let done = self.candidates.len().saturating_sub(self.cut_short.len());
        format!(
            "undecided — the time limit {}{}; raise the time limit (`--time-limit`, Python's `time_limit_s`)",
            what.join(" and "),
            match done {
                0 => String::new(),
                1 => ", and the one refitted in full is not missing".into(),
                n => format!(", and none of the {n} refitted in full is missing"),
            }
        )
    }
}

/// The effects worth trying on top of `spec` for these files (the registry's candidacy).
pub fn candidates_for(spec: ModelSpec, files: &[Recording]) -> Vec<Effect> {
    let all_have_command = files.iter().all(|f| f.command_v.is_some());
    Effect::ALL
        .into_iter()
        .filter(|&e| !spec.has(e))
        .filter(|&e| match e.info().candidacy {
            Candidacy::Always => true,
            Candidacy::NeedsCommand => all_have_command,
            Candidacy::RefinesLaw => e.info().law.is_some_and(|l| l.refines(spec.law())),
            Candidacy::Never => false,
        })
        .collect()
}

/// Signals of one file under the baseline model, for the signatures.
struct Signals {
    residual: Vec<f64>,
    rate: Vec<f64>,
    accel: Vec<f64>,
    branch: Vec<f64>,
    cubic: Vec<f64>,
    creep: Vec<f64>,
    heat: Vec<f64>,
}

impl Signals {
    /// The signals without their first `n` samples (the burn-in).
    fn skip(mut self, n: usize) -> Self {
        for v in [
            &mut self.residual,
            &mut self.rate,
            &mut self.accel,
            &mut self.branch,
            &mut self.cubic,
            &mut self.creep,
            &mut self.heat,
        ] {
            v.drain(..n.min(v.len()));
        }
        self
    }
}

fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a).max(1) as f64 * dt)
        })
        .collect()
}

fn lowpass(x: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let p = (-dt / tau).exp();
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            y = p * y + (1.0 - p) * v;
            y
        })
        .collect()
}

/// The signatures on the displacement (`flux: false`: the baseline's residual with its offset) or
/// on the search coil's flux density (the model's flux fitted to it, [`crate::score::flux_fit`]).
fn signals(rec: &Recording, sim: &Simulation, offset: f64, flux: bool) -> Signals {
    let dt = rec.dt_s();
    // The model's output on the channel, and the measured one.
    let (y, measured): (Vec<f64>, &[f64]) = if flux {
        let b = rec.flux_density_t.as_deref().unwrap_or_default();
        (crate::score::flux_fit(b, &sim.field_a_per_m, &sim.magnetization_a_per_m).1, b)
    } else {
        let y = sim.displacement_um.iter().map(|y| y + offset).collect();
        (y, rec.displacement_um.as_deref().unwrap_or_default())
    };
    let residual: Vec<f64> = measured.iter().zip(&y).map(|(m, y)| m - y).collect();
    let y = y.as_slice();
    let rate = derivative(y, dt);
    let accel = derivative(&rate, dt);
    let h = &sim.field_a_per_m;
    let dh = derivative(h, dt);
    let hscale = dh.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    // Smooth sign of dH/dt: the branch the rod is on.
    let branch: Vec<f64> = dh.iter().map(|v| (v / (0.05 * hscale)).tanh()).collect();
    let hmean = h.iter().sum::<f64>() / h.len() as f64;
    let cubic: Vec<f64> = h.iter().map(|v| (v - hmean).powi(3)).collect();
    let creep = lowpass(y, dt, 0.05).iter().zip(y).map(|(l, v)| l - v).collect();
    let heat = joule_heat(&sim.current_a, dt);
    Signals { residual, rate, accel, branch, cubic, creep, heat }
}

/// The accumulated coil heating ∫i² dt [A² s] of a current sampled every `dt` s: the
/// coil-heating signature (its resistance aside).
fn joule_heat(current: &[f64], dt: f64) -> Vec<f64> {
    let mut acc = 0.0;
    current
        .iter()
        .map(|i| {
            acc += i * i * dt;
            acc
        })
        .collect()
}

/// R² of the least-squares fit of `r` by `a·f + b` (one regressor and a constant).
fn r2(r: &[f64], f: &[f64]) -> f64 {
    correlation(r, f).powi(2)
}

/// Pooled evidence R² of `effect`'s signature over the files (variance-weighted mean).
fn evidence(effect: Effect, sigs: &[Signals]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for s in sigs {
        let var = s.residual.iter().map(|v| v * v).sum::<f64>();
        let score = match effect.info().signature {
            Signature::Lag => r2(&s.residual, &s.rate),
            Signature::Resonance => r2(&s.residual, &s.accel).max(r2(&s.residual, &s.rate)),
            Signature::Branch => r2(&s.residual, &s.branch),
            Signature::Cubic => r2(&s.residual, &s.cubic),
            Signature::Creep => r2(&s.residual, &s.creep),
            Signature::Heating => r2(&s.residual, &s.heat),
            Signature::None => 0.0,
        };
        num += score * var;
        den += var;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Pooled R² of the coil-heating signature on the logged temperature: the baseline has no
/// heating, so its temperature is a constant and the residual is the temperature's own
/// variation, regressed on the accumulated Joule heat ∫i² dt of the baseline's current.
fn heating_evidence(files: &[Recording], sims: &[Simulation], skip: &[usize]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for ((rec, sim), &k) in files.iter().zip(sims).zip(skip) {
        let t = &rec.temperature_c.as_deref().unwrap_or_default()[k..];
        let heat = joule_heat(&sim.current_a[k..], rec.dt_s());
        let m = mean(t.iter().copied());
        let var = t.iter().map(|v| (v - m) * (v - m)).sum::<f64>();
        num += r2(t, &heat) * var;
        den += var;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// [`signature_words`] for signatures taken on the flux density.
fn flux_signature_words(signature: Signature) -> &'static str {
    match signature {
        Signature::Lag => "the lag signature −dB/dt of the flux density (shared by the rod's lags)",
        Signature::Creep => "the creep signature lowpass(B) − B of the flux density",
        _ => signature_words(signature),
    }
}

fn signature_words(signature: Signature) -> &'static str {
    match signature {
        Signature::Lag => "the lag signature −dy/dt (shared by every lag: rod, amplifier, sensor)",
        Signature::Resonance => "the resonance signature −ÿ (and −dy/dt)",
        Signature::Branch => "the branch sign(dH/dt) (loop opening)",
        Signature::Cubic => "the cubic field excursion (H − H̄)³",
        Signature::Creep => "the creep signature lowpass(y) − y",
        Signature::Heating => "the accumulated coil heating ∫i² dt",
        Signature::None => "—",
    }
}

/// A refit that is lower on the fit files but higher on every one of at least two validation
/// files (`(before, after)` NRMSE each): what the effect added was fitted to the fit files'
/// model error, not determined by them. A sign pattern, no threshold: one validation file is
/// no pattern.
fn not_pinned_by_the_fit_files(fit_nrmse: (f64, f64), val_files: &[(f64, f64)]) -> bool {
    fit_nrmse.1 < fit_nrmse.0
        && val_files.len() >= 2
        && val_files.iter().all(|(before, after)| after > before)
}

/// The recording in which an effect shows (what an engineer adds to the fit files to pin it).
fn where_it_shows(e: Effect) -> &'static str {
    match e {
        Effect::Saturation => "slow loops that reach the knee of the magnetization curve",
        Effect::Hysteresis | Effect::Preisach => "slow loops of several amplitudes, major and minor",
        Effect::EddyCurrent => "broadband drive to kHz (a chirp or multisine), with `current_A` recorded",
        Effect::MechanicalDynamics => "a chirp or multisine across the first resonance",
        Effect::AmplifierDynamics => "`current_A` recorded with a broadband command",
        Effect::MagneticAftereffect => "held steps, each several creep time constants long",
        Effect::ThermalDrift => "minutes at high current, as long as the coil takes to warm",
        Effect::SensorDelay => "broadband drive to kHz, where a delay's phase grows with frequency",
    }
}

/// Dominant frequency of a drive (zero crossings of its AC part) [Hz] and its rms amplitude.
fn drive_stats(rec: &Recording) -> (f64, f64) {
    let u = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    let rms = (u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / u.len() as f64).sqrt();
    let crossings = u.windows(2).filter(|w| (w[0] - mean) * (w[1] - mean) < 0.0).count();
    (crossings as f64 / 2.0 / rec.duration_s().max(1e-12), rms)
}

/// Residual whiteness: share of autocorrelation lags 1–20 outside the 95 % band, pooled.
fn whiteness(residuals: &[&[f64]]) -> f64 {
    let mut outside = 0usize;
    let mut total = 0usize;
    for r in residuals {
        let n = r.len();
        if n < 2 {
            continue;
        }
        let m = r.iter().sum::<f64>() / n as f64;
        let c0: f64 = r.iter().map(|v| (v - m).powi(2)).sum();
        if c0 <= 0.0 {
            continue;
        }
        let band = 1.96 / (n as f64).sqrt();
        for lag in 1..=20.min(n - 1) {
            let c: f64 = (lag..n).map(|k| (r[k] - m) * (r[k - lag] - m)).sum();
            total += 1;
            if (c / c0).abs() > band {
                outside += 1;
            }
        }
    }
    outside as f64 / total.max(1) as f64
}

/// Whether a share of lags outside the 95 % band is more than white noise gives (5 % plus two
/// binomial standard deviations over the lags tested), and that limit.
fn structured_residual(share: f64, files: usize) -> (bool, f64) {
    let lags = (20 * files).max(1) as f64;
    let limit = 0.05 + 2.0 * (0.05 * 0.95 / lags).sqrt();
    (share > limit, limit)
}

/// Samples left out of every score at the start of a file: the rig's initial magnetic state is
/// unknown (a real rod is not demagnetised), so the first full cycle of the drive (up to its
/// second reversal) is a burn-in, at most half the file.
pub fn burn_in(rec: &Recording) -> usize {
    let drive = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    reversal_positions(drive).get(1).copied().unwrap_or(0).min(rec.len() / 2)
}

/// A residual after the burn-in (offset removed) and its NRMSE.
#[derive(Debug, Clone)]
struct Scored {
    residual: Vec<f64>,
    nrmse: f64,
}

fn scored(measured: &[f64], model: &[f64], skip: usize) -> Scored {
    let (m, y) = (&measured[skip..], &model[skip..]);
    let n = m.len().max(1) as f64;
    let offset = m.iter().zip(y).map(|(a, b)| a - b).sum::<f64>() / n;
    let residual: Vec<f64> = m.iter().zip(y).map(|(a, b)| a - b - offset).collect();
    let (lo, hi) = m.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let rms = (residual.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    Scored { residual, nrmse: rms / (hi - lo).max(1e-12) }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// The channel a candidate is scored on.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Channel {
    Displacement,
    Current,
    /// A search coil's flux density: what the field and magnetization stages act on, before the
    /// mechanics, the thermal elongation and the displacement probe.
    FluxDensity,
    /// A logged `temperature_C`: what coil heating acts on before the rod expands.
    Temperature,
}

impl Channel {
    /// The contract's name.
    fn name(self) -> &'static str {
        match self {
            Channel::Displacement => "displacement",
            Channel::Current => "current",
            Channel::FluxDensity => "flux_density",
            Channel::Temperature => "temperature",
        }
    }

    /// The measured channel nearest where `e` acts: the amplifier's on the current, the rod's
    /// field, magnetization and creep on the flux density, coil heating on the temperature, the
    /// rest on the displacement — when every file measured that channel.
    fn judging(e: Effect, measured: Measured) -> Channel {
        match e.info().stage {
            Stage::Amplifier if measured.current => Channel::Current,
            Stage::Thermal if measured.temperature => Channel::Temperature,
            Stage::RodField | Stage::Magnetization | Stage::MagnetizationCreep if measured.flux => {
                Channel::FluxDensity
            }
            _ => Channel::Displacement,
        }
    }
}

/// The channels besides the displacement that every file measured.
#[derive(Clone, Copy)]
struct Measured {
    /// `current_A` and `command_V`: the amplifier is judged command → current.
    current: bool,
    /// `flux_density_T` (a search coil).
    flux: bool,
    /// `temperature_C` (the coil's).
    temperature: bool,
}

/// Whether a file logs a channel's columns.
type Logs = fn(&Recording) -> bool;

/// The channels besides the displacement: their columns, whether a file logs them, and what they
/// judge.
const CHANNELS: [(&str, Logs, &str); 3] = [
    ("current_A and command_V", |r| r.current_a.is_some() && r.command_v.is_some(), "amplifier dynamics"),
    (
        "flux_density_T",
        |r| r.flux_density_t.is_some(),
        "the rod's field, magnetization and creep effects (and the laws and J–A forms compared)",
    ),
    ("temperature_C", |r| r.temperature_c.is_some(), "coil heating"),
];

impl Measured {
    /// Findings for channels some files log and others do not: each judges its effects only
    /// when every file has it, and falls back to the displacement silently otherwise.
    fn partly(fit_files: &[Recording], score_files: &[Recording]) -> Vec<String> {
        let files: Vec<&Recording> = fit_files.iter().chain(score_files).collect();
        CHANNELS
            .iter()
            .filter_map(|(name, logs, what)| {
                let lacking: Vec<&str> = files.iter().filter(|r| !logs(r)).map(|r| r.name.as_str()).collect();
                (!lacking.is_empty() && lacking.len() < files.len()).then(|| {
                    format!(
                        "{name}: logged in some files but not in {}: {what} judged on the displacement (that channel \
                         is used only when every fit and scored file has it)",
                        lacking.join(", ")
                    )
                })
            })
            .collect()
    }

    /// What every fit and scored file logs.
    fn in_every(fit_files: &[Recording], score_files: &[Recording]) -> Self {
        let [current, flux, temperature] =
            CHANNELS.map(|(_, logs, _)| fit_files.iter().chain(score_files).all(logs));
        Measured { current, flux, temperature }
    }
}

/// Per file, the scored residual on `channel` after the file's burn-in `skip`.
fn channel_scores(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    files: &[Recording],
    skip: &[usize],
    channel: Channel,
) -> Result<Vec<Scored>> {
    files
        .par_iter()
        .zip(skip)
        .map(|(rec, &k)| {
            let sim = simulate(spec, params, rec)?;
            Ok(match channel {
                Channel::Displacement => {
                    scored(rec.displacement_um.as_deref().unwrap_or_default(), &sim.displacement_um, k)
                }
                Channel::Current => scored(rec.current_a.as_deref().unwrap_or_default(), &sim.current_a, k),
                Channel::FluxDensity => {
                    // Scale and zero fitted on the scored part, as the offset is.
                    let b = &rec.flux_density_t.as_deref().unwrap_or_default()[k..];
                    let (_, model) =
                        crate::score::flux_fit(b, &sim.field_a_per_m[k..], &sim.magnetization_a_per_m[k..]);
                    scored(b, &model, 0)
                }
                Channel::Temperature => {
                    // The ambient fitted on the scored part, as the offset is.
                    let t = &rec.temperature_c.as_deref().unwrap_or_default()[k..];
                    let rise = sim.temperature_rise_c.get(k..).unwrap_or_default();
                    scored(t, &crate::score::temperature_fit(t, rise).1, 0)
                }
            })
        })
        .collect()
}

fn displacement_scores(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    files: &[Recording],
    skip: &[usize],
) -> Result<Vec<Scored>> {
    channel_scores(spec, params, files, skip, Channel::Displacement)
}

/// Whether an effect shows in a file: the refit's prediction with the effect switched off
/// (residual `off`) differs from the refit's (residual `on`; both measured − model, offsets
/// removed) by more, in rms, than the file's measurement noise. The noise is estimated from the
/// refit's residual by its successive differences (von Neumann; Rice 1984): σ² ≈ Σ (r_k −
/// r_{k−1})² / 2(N − 1), which white noise passes whole and a slow model error hardly at all (a
/// fast one raises the estimate: the test then errs towards not counting the file).
fn effect_shows(off: &[f64], on: &[f64]) -> bool {
    let n = on.len().max(1) as f64;
    let d: Vec<f64> = off.iter().zip(on).map(|(a, b)| a - b).collect();
    let mean_d = d.iter().sum::<f64>() / n;
    let change = d.iter().map(|v| (v - mean_d) * (v - mean_d)).sum::<f64>() / n;
    let noise =
        on.windows(2).map(|w| (w[1] - w[0]) * (w[1] - w[0])).sum::<f64>() / (2.0 * (n - 1.0).max(1.0));
    change > noise
}

/// Parameters fitted on the scored files themselves: a law with a memory starts each file
/// from an estimated pre-history ([`crate::simulation::InitialState::Estimated`], one excursion per file,
/// judged on the file's start), a law without none. A refit that adds a memory gains one
/// such parameter per scored file, and the information criterion counts it.
pub(crate) fn estimated_states(spec: ModelSpec, files: usize) -> usize {
    match spec.law() {
        MagnetizationLaw::JilesAtherton | MagnetizationLaw::Preisach => files,
        MagnetizationLaw::Linear | MagnetizationLaw::Anhysteretic => 0,
    }
}

/// Σ_f N_eff,f ln(MSE_before,f / MSE_after,f): the Gaussian log-likelihood gain of a refit with
/// each file's effective sample size (the baseline's).
/// `n_eff` holds each file's effective samples of the baseline's residual (computed once by the
/// caller, who also needs their sum for the penalty).
fn information_gain(before: &[Scored], after: &[Scored], n_eff: &[f64]) -> f64 {
    before
        .iter()
        .zip(after)
        .zip(n_eff)
        .map(|((b, a), n)| {
            let mse =
                |s: &Scored| s.residual.iter().map(|v| v * v).sum::<f64>() / s.residual.len().max(1) as f64;
            n * (mse(b).max(1e-300) / mse(a).max(1e-300)).ln()
        })
        .sum()
}

/// The baseline of the current channel: i = g·u + b (least squares over the fit files).
struct StaticGain {
    gain: f64,
    offset: f64,
}

impl StaticGain {
    fn fit(files: &[Recording], skip: &[usize]) -> Self {
        let (mut n, mut su, mut si, mut suu, mut sui) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for (rec, &k) in files.iter().zip(skip) {
            let (Some(u), Some(i)) = (rec.command_v.as_deref(), rec.current_a.as_deref()) else { continue };
            for (u, i) in u[k..].iter().zip(&i[k..]) {
                n += 1.0;
                su += u;
                si += i;
                suu += u * u;
                sui += u * i;
            }
        }
        let var = suu - su * su / n.max(1.0);
        let gain = if var > 0.0 { (sui - su * si / n) / var } else { 0.0 };
        StaticGain { gain, offset: (si - gain * su) / n.max(1.0) }
    }

    fn model(&self, rec: &Recording) -> Vec<f64> {
        rec.command_v.as_deref().unwrap_or_default().iter().map(|u| self.gain * u + self.offset).collect()
    }

    fn scores(&self, files: &[Recording], skip: &[usize]) -> Vec<Scored> {
        files
            .iter()
            .zip(skip)
            .map(|(rec, &k)| scored(rec.current_a.as_deref().unwrap_or_default(), &self.model(rec), k))
            .collect()
    }

    /// Pooled R² of the static residual by the lag signature −d(g·u)/dt.
    fn lag_evidence(&self, files: &[Recording], skip: &[usize]) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (rec, &k) in files.iter().zip(skip) {
            let model = self.model(rec);
            let s = scored(rec.current_a.as_deref().unwrap_or_default(), &model, k);
            let rate = derivative(&model, rec.dt_s());
            let var: f64 = s.residual.iter().map(|v| v * v).sum();
            num += r2(&s.residual, &rate[k..]) * var;
            den += var;
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }
}

/// Diagnoses `spec` on `fit_files` (scored on `val_files` when given).
pub fn diagnose(
    spec: ModelSpec,
    init: &model_core::ActuatorParams,
    fit_files: &[Recording],
    val_files: &[Recording],
    opts: FitOptions,
) -> Result<Diagnosis> {
    check_files(fit_files, val_files)?;
    let cands = candidates_for(spec, fit_files);
    let searches::Searches { base, refined, fresh } = searches::search(spec, init, fit_files, &cands, opts)?;
    let mut time_limited = base.time_limited;
    let held_out = !val_files.is_empty();
    let score_files = if held_out { val_files } else { fit_files };
    // Per-file scores of the baseline, for the refits to be compared with. Scores leave out each
    // file's burn-in (the unknown initial magnetic state).
    let fit_skip: Vec<usize> = fit_files.iter().map(burn_in).collect();
    let score_skip: Vec<usize> = score_files.iter().map(burn_in).collect();
    let base_fit_disp = displacement_scores(spec, &base.params, fit_files, &fit_skip)?;
    let base_score_disp = if held_out {
        displacement_scores(spec, &base.params, score_files, &score_skip)?
    } else {
        base_fit_disp.clone()
    };
    let before = mean(base_score_disp.iter().map(|s| s.nrmse));

    // Evidence on the fit files' residuals.
    let evidence_phase =
        progress::Phase::start(opts.progress, "diagnose: residual evidence and trends across files", 0);
    // With a search coil on every file, the stages before the strain are judged on its flux.
    let measured = Measured::in_every(fit_files, score_files);
    let base_sims: Vec<Simulation> =
        fit_files.iter().map(|rec| simulate(spec, &base.params, rec)).collect::<Result<_>>()?;
    let signals_on = |flux: bool| -> Vec<Signals> {
        fit_files
            .iter()
            .zip(&base.fit.files)
            .zip(&base_sims)
            .map(|((rec, sc), sim)| signals(rec, sim, sc.offset_um, flux).skip(burn_in(rec)))
            .collect()
    };
    let sigs = signals_on(false);
    let flux_sigs = if measured.flux { signals_on(true) } else { Vec::new() };
    let mut findings = Measured::partly(fit_files, score_files);
    findings.extend(baseline_findings(spec, &base, &sigs));
    findings.extend(file_trends(spec, &base.params, fit_files, val_files)?);
    evidence_phase.finish();

    let results = refits(spec, &cands, fresh, refined, score_files, opts.progress);
    let (base_fit_flux, base_score_flux) = if measured.flux {
        (
            channel_scores(spec, &base.params, fit_files, &fit_skip, Channel::FluxDensity)?,
            channel_scores(spec, &base.params, score_files, &score_skip, Channel::FluxDensity)?,
        )
    } else {
        (Vec::new(), Vec::new())
    };
    let baseline = judge::Baseline {
        spec,
        base: &base,
        fit_files,
        score_files,
        fit_skip: &fit_skip,
        score_skip: &score_skip,
        held_out,
        measured,
        static_amp: measured.current.then(|| StaticGain::fit(fit_files, &fit_skip)),
        fit_disp: base_fit_disp,
        score_disp: base_score_disp,
        fit_flux: base_fit_flux,
        score_flux: base_score_flux,
        sims: &base_sims,
        sigs: &sigs,
        flux_sigs: &flux_sigs,
    };
    let mut candidates = Vec::new();
    let mut skipped = Vec::new();
    let mut cut_short = Vec::new();
    let (mut failed_refits, mut errored_refits, mut unpinned) = (Vec::new(), Vec::new(), Vec::new());
    for (e, r) in results {
        let Some(r) = r else {
            skipped.push(e);
            continue;
        };
        if let Ok(f) = &r {
            time_limited |= f.time_limited;
            if f.time_limited {
                cut_short.push(e);
            }
        }
        let judged = baseline.judge(e, r)?;
        failed_refits.extend(judged.failed_refit);
        errored_refits.extend(judged.errored_refit);
        unpinned.extend(judged.unpinned);
        candidates.push(judged.candidate);
    }
    findings.extend(unpinned);
    if !failed_refits.is_empty() {
        findings.push(format!(
            "refits that ended worse on the fit files than the structure they extend (rms of the fit cost): {}: the \
             search failed there, so these candidates are not judged fairly",
            failed_refits.join(", ")
        ));
    }
    if !errored_refits.is_empty() {
        findings.push(format!(
            "refits that could not be run: {}: these candidates are not judged (their rows show the baseline's \
             error before and after)",
            errored_refits.join(", ")
        ));
    }
    let (verdict, undistinguished) = decide(&mut candidates, &mut findings);
    findings.extend(what_is_left(&baseline, &candidates, verdict)?);
    if !skipped.is_empty() {
        time_limited = true;
        findings.push(format!(
            "the time limit was reached: `{}` not refitted; the verdict weighs only the candidates refitted in time",
            skipped.iter().map(|e| e.name()).collect::<Vec<_>>().join("`, `")
        ));
    }
    Ok(Diagnosis {
        time_limited,
        model: spec.to_string(),
        nrmse_fit: base.fit.mean_nrmse(),
        nrmse_val: held_out.then_some(before),
        candidates,
        verdict,
        undistinguished,
        not_refitted: skipped,
        cut_short,
        findings,
        baseline: Some(base),
        ja_variants: None,
        laws: None,
    })
}

/// Files a diagnosis can judge: at least one drive cycle (each file is scored after its first,
/// the burn-in) and [`MIN_SAMPLES`] samples.
fn check_files(fit_files: &[Recording], val_files: &[Recording]) -> Result<()> {
    // Validation files too: each is scored after its burn-in, and votes in the sign test as a
    // whole file.
    for rec in fit_files.iter().chain(val_files) {
        let drive = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
        let n = reversals(drive);
        if n < 2 {
            return Err(InRecording::error(
                &rec.name,
                format!(
                    "the drive covers less than one cycle ({n} reversal{} in {:.1} ms): a diagnosis compares \
                     both branches of the loop and scores each file after its first cycle, so record at least \
                     one full period of the excitation",
                    if n == 1 { "" } else { "s" },
                    rec.duration_s() * 1e3
                ),
            ));
        }
        if rec.len() < MIN_SAMPLES {
            return Err(InRecording::error(
                &rec.name,
                format!(
                    "{} samples; a diagnosis compares models with up to about ten parameters and needs at \
                     least {MIN_SAMPLES} samples per file",
                    rec.len()
                ),
            ));
        }
    }
    Ok(())
}

/// What the baseline's fit says by itself: whether its residual is white, and the parameters it
/// bent to the end of their range.
fn baseline_findings(spec: ModelSpec, base: &FitResult, sigs: &[Signals]) -> Vec<String> {
    let mut findings = Vec::new();
    // λ_s far outside the materials' range is most often a displacement in another unit, said
    // first (a doubt about the data outweighs the residual's statistics) and as `gma fit` says it.
    if let Some(w) = fit::strain_scale_doubt(&base.params, &fit::Constraints::default()) {
        findings.push(format!("in the fit of `{spec}`: {w}"));
    }
    let white = whiteness(&sigs.iter().map(|s| s.residual.as_slice()).collect::<Vec<_>>());
    let (not_white, white_limit) = structured_residual(white, sigs.len());
    findings.push(if not_white {
        format!(
            "residual is not white: {:.0} % of autocorrelation lags 1–20 lie outside the 95 % band, white noise leaves at \
             most {:.0} % (something systematic is left)",
            white * 100.0,
            white_limit * 100.0
        )
    } else {
        format!("residual is close to white: {:.0} % of lags 1–20 outside the 95 % band", white * 100.0)
    });
    // The other parameters the fit left at a range's end, in one finding: a structure that
    // lacks an effect often bends a parameter that far to stand in for it.
    let at_edge: Vec<String> = base
        .free
        .iter()
        .filter(|f| f.name() != model_core::effects::STRAIN_SCALE.key)
        .filter_map(|f| {
            let value = (f.get)(&base.params);
            f.bound.at_edge(value).then(|| {
                Warning::AtEdge { param: f.name(), value, lo: f.bound.lo, hi: f.bound.hi }.to_string()
            })
        })
        .collect();
    if !at_edge.is_empty() {
        findings.push(format!(
            "in the fit of `{spec}`, {}: a structure that lacks an effect often bends a parameter to the end \
             of its range to stand in for it (refitted with that effect, the parameter moves off the end); a \
             parameter the data do not need ends there too",
            at_edge.join("; ")
        ));
    }
    findings
}

/// The baseline's error across all files against excitation frequency, drive amplitude and
/// record length: a finding where it follows one of them.
fn file_trends(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    fit_files: &[Recording],
    val_files: &[Recording],
) -> Result<Vec<String>> {
    let mut per_file: Vec<(f64, f64, f64, f64)> = Vec::new(); // freq, amplitude, duration, nrmse
    let all_files: Vec<&Recording> = fit_files.iter().chain(val_files).collect();
    let all_scores = evaluate(spec, params, &all_files.iter().map(|r| (*r).clone()).collect::<Vec<_>>())?;
    for (rec, sc) in all_files.iter().zip(&all_scores.files) {
        let (f, a) = drive_stats(rec);
        per_file.push((f, a, rec.duration_s(), sc.nrmse));
    }
    // The extreme files along each quantity, the error at each, and the quantity's values there.
    let trend = |key: fn(&(f64, f64, f64, f64)) -> f64, what: &'static str, unit: &'static str| {
        let mut order: Vec<usize> = (0..per_file.len()).collect();
        order.sort_by(|&a, &b| key(&per_file[a]).total_cmp(&key(&per_file[b])));
        let (lo, hi) = (*order.first()?, *order.last()?);
        let (a, b) = (&per_file[lo], &per_file[hi]);
        if key(b) <= 1.5 * key(a) {
            return None;
        }
        let ratio = b.3 / a.3.max(1e-12);
        (!(0.67..=1.5).contains(&ratio)).then_some(Trend { lo, hi, what, unit, from: key(a), to: key(b) })
    };
    // The amplitude is the current's where a file has one, else the command's.
    let drive_unit = match (
        all_files.iter().all(|r| r.current_a.is_some()),
        all_files.iter().all(|r| r.current_a.is_none()),
    ) {
        (true, _) => "A (current_A)",
        (_, true) => "V (command_V)",
        _ => "A (current_A) or V (command_V, files without a current)",
    };
    let trends: Vec<Trend> = [
        trend(|r| r.0, "excitation frequency", "Hz"),
        trend(|r| r.1, "drive amplitude (rms)", drive_unit),
        trend(|r| r.2, "record length", "s"),
    ]
    .into_iter()
    .flatten()
    .collect();
    let names: Vec<&str> = all_files.iter().map(|r| r.name.as_str()).collect();
    Ok(trend_findings(&trends, &per_file, &names))
}

/// Per candidate, its refit (the better of its two searches, [`searches::keep_the_better`]), or
/// `None` where the time limit left it out. Each is scored on the scored files for the progress
/// line; a scoring error becomes that candidate's error ("refits that could not be run").
fn refits(
    spec: ModelSpec,
    cands: &[Effect],
    fresh: Vec<searches::Search>,
    refined: Vec<searches::Search>,
    score_files: &[Recording],
    show_progress: bool,
) -> Vec<(Effect, Option<Result<FitResult>>)> {
    let refitting = progress::Phase::start(
        show_progress,
        &format!("diagnose: scoring the refits of `{spec}` plus each of {} candidate effects", cands.len()),
        cands.len() as u64,
    );
    let done = AtomicUsize::new(0);
    let results = cands
        .par_iter()
        .zip(fresh)
        .zip(refined)
        .map(|((&e, fresh), refined)| {
            let (Some(fresh), Some(refined)) = (fresh, refined) else { return (e, None) };
            let r = searches::keep_the_better(fresh, refined)
                .and_then(|f| Ok((evaluate(spec.with(e), &f.params, score_files)?.mean_nrmse(), f)));
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            let note = match &r {
                Ok((after, _)) => {
                    format!(
                        "diagnose: refit {k}/{} done: `+{}`, mean NRMSE of the scored files and channels {:.2} % \
                         (whole files; the candidates' figures leave out each file's burn-in)",
                        cands.len(),
                        e.name(),
                        after * 100.0
                    )
                }
                Err(_) => String::new(),
            };
            refitting.step(&note);
            (e, Some(r.map(|(_, f)| f)))
        })
        .collect();
    refitting.finish();
    results
}

/// The verdict, and the passing candidates the data do not separate from it: `candidates`
/// ordered most likely first (passing first, then by cut and ΔBIC; the verdict chosen among the
/// undistinguished by the data, never by the list order), with what decided it in `findings`.
fn decide(candidates: &mut Vec<Candidate>, findings: &mut Vec<String>) -> (Option<Effect>, Vec<Effect>) {
    // Candidates that pass every test first, then by the size of their cut.
    candidates.sort_by(|a, b| {
        b.passes()
            .cmp(&a.passes())
            .then(b.cut().total_cmp(&a.cut()))
            .then(b.delta_bic.total_cmp(&a.delta_bic))
    });
    let mut verdict = None;
    let mut undistinguished = Vec::new();
    if candidates.first().is_some_and(Candidate::passes) {
        // Passing candidates on the same channel that the best does not beat on every scored file,
        // or not by strong evidence of the information criterion, cannot be told apart by these
        // data. Among them the signature evidence decides where its R² differ by more than the
        // significance of an R² at their N_eff, else the information criterion — never the list
        // order.
        let best = candidates[0].clone();
        let tied: Vec<usize> = (0..candidates.len())
            .filter(|&i| {
                let c = &candidates[i];
                let beaten = best.per_file_after.iter().zip(&c.per_file_after).all(|(b, o)| b < o)
                    && best.delta_bic - c.delta_bic >= BIC_STRONG;
                c.passes() && c.channel == best.channel && (i == 0 || !beaten)
            })
            .collect();
        let tied_candidates: Vec<&Candidate> = tied.iter().map(|&i| &candidates[i]).collect();
        let (k, by_signature) = choose_among_tied(&tied_candidates);
        let chosen = tied[k];
        let tied_effects: Vec<Effect> = tied.iter().map(|&i| candidates[i].effect).collect();
        let pick = candidates.remove(chosen);
        candidates.insert(0, pick);
        verdict = Some(candidates[0].effect);
        undistinguished = tied_effects.into_iter().filter(|&e| Some(e) != verdict).collect();
        if !undistinguished.is_empty() {
            let v = &candidates[0];
            let others: Vec<&Candidate> =
                candidates.iter().filter(|c| undistinguished.contains(&c.effect)).collect();
            let same_signature =
                others.iter().all(|c| c.effect.info().signature == v.effect.info().signature);
            let by_bic = |how: String| {
                let lead = others.iter().map(|c| v.delta_bic - c.delta_bic).fold(f64::INFINITY, f64::min);
                format!(
                    "{how}, so the information criterion decides: ΔBIC {:+.1} against {}{}",
                    v.delta_bic,
                    others.iter().map(|c| format!("{:+.1}", c.delta_bic)).collect::<Vec<_>>().join(", "),
                    if lead < BIC_STRONG {
                        format!(
                            ", a weak preference (a lead under {BIC_STRONG}): treat them as equally likely"
                        )
                    } else {
                        String::new()
                    }
                )
            };
            let why = if same_signature {
                by_bic(format!("they share the signature ({})", signature_words(v.effect.info().signature)))
            } else if !by_signature {
                by_bic(format!(
                    "no signature explains the residual better than every other's by more than an R²'s significance \
                     (R² {:.1} % against {}; significance at N_eff = {:.0}: {:.1} %)",
                    v.evidence_r2 * 100.0,
                    others.iter().map(|c| format!("{:.1} %", c.evidence_r2 * 100.0)).collect::<Vec<_>>().join(", "),
                    v.n_eff,
                    100.0 * CHI2_1_95 / v.n_eff.max(1.0)
                ))
            } else {
                format!(
                    "the signature evidence decides: R² {:.1} % against {}",
                    v.evidence_r2 * 100.0,
                    others
                        .iter()
                        .map(|c| format!("{:.1} %", c.evidence_r2 * 100.0))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            };
            let hint = if v.effect.info().stage == Stage::Amplifier
                || others.iter().any(|c| c.effect.info().stage == Stage::Amplifier)
            {
                " (record `current_A` to tell the amplifier from the rod)"
            } else {
                " (excite more frequencies or record more channels to separate them)"
            };
            findings.push(format!(
                "the data do not separate `{}` from `{}`: every one passes and none is lower on every scored file; {why}{hint}",
                v.effect,
                undistinguished.iter().map(|e| e.name()).collect::<Vec<_>>().join("`, `"),
            ));
        }
        // Passing candidates judged on another channel are not ranked against the verdict by
        // these numbers (cuts on different channels measure different things): said, not dropped.
        let v = &candidates[0];
        let elsewhere: Vec<String> = candidates
            .iter()
            .filter(|c| c.passes() && c.channel != v.channel)
            .map(|c| {
                format!(
                    "`{}` on the {} ({}, ΔBIC {:+.1})",
                    c.effect,
                    c.channel,
                    cut_words(c.cut()),
                    c.delta_bic
                )
            })
            .collect();
        if !elsewhere.is_empty() {
            findings.push(format!(
                "also passing, judged on another channel than the verdict's {}: {}. Cuts on different channels are \
                 not comparable evidence, so the verdict is only the larger cut: add it and diagnose again to see \
                 whether the other is still missing",
                v.channel,
                elsewhere.join(", ")
            ));
        }
    } else if let Some(best) = candidates.iter().max_by(|a, b| a.cut().total_cmp(&b.cut())) {
        findings.push(format!(
            "no candidate passes (cut ≥ {MIN_CUT}×, lower on enough scored files it shows and moves beyond the noise in (all of up to {}: a one-sided sign test at 5 %), ΔBIC > 0{}); the best, `{}`, takes {:.2} % to {:.2} % on {} (lower on {} of {}, on {} of the {} it shows in, on {} of the {} it moves beyond the noise, ΔBIC {:+.1}, R² {:.1} %)",
            all_must_improve_up_to(),
            if best.held_out { String::new() } else { format!(", signature significant or cut ≥ {DECISIVE_CUT}×") },
            best.effect,
            best.nrmse_before * 100.0,
            best.nrmse_after * 100.0,
            best.channel,
            best.files_improved,
            best.files_scored,
            best.files_improved_showing,
            best.files_showing,
            best.files_improved_deciding,
            best.files_deciding,
            best.delta_bic,
            best.evidence_r2 * 100.0
        ));
    }
    (verdict, undistinguished)
}

/// What the final structure (the verdict added, or the given one) still leaves, in findings.
fn what_is_left(
    baseline: &judge::Baseline,
    candidates: &[Candidate],
    verdict: Option<Effect>,
) -> Result<Vec<String>> {
    let judge::Baseline { spec, base, fit_files, score_files, fit_skip, score_skip, held_out, .. } =
        *baseline;
    let before = mean(baseline.score_disp.iter().map(|s| s.nrmse));
    let mut findings = Vec::new();
    let (final_spec, final_params, final_val) = match candidates.first().filter(|c| Some(c.effect) == verdict)
    {
        Some(c) if c.channel == "displacement" => {
            (spec.with(c.effect), c.refit.as_ref().map_or(base.params, |f| f.params), c.nrmse_after)
        }
        // Judged on another channel: what is left is reported on the displacement.
        Some(c) => {
            let p = c.refit.as_ref().map_or(base.params, |f| f.params);
            let val = displacement_scores(spec.with(c.effect), &p, score_files, score_skip)?;
            (spec.with(c.effect), p, mean(val.iter().map(|s| s.nrmse)))
        }
        _ => (spec, base.params, before),
    };
    // A verdict judged on the current (or the flux) can leave the displacement worse for now:
    // the refit spends its freedom on the channel the effect models. Said, never left to be
    // found in the ladder.
    if let Some(c) = candidates.first().filter(|c| Some(c.effect) == verdict && c.channel != "displacement") {
        if final_val > before {
            findings.push(format!(
                "with `{effect}` added the displacement's validation NRMSE rises from {before:.2} % to {after:.2} %: \
                 `{effect}` is judged on the {channel} it models (above), where the refit spent its freedom",
                effect = c.effect,
                before = before * 100.0,
                after = final_val * 100.0,
                channel = c.channel
            ));
        }
    }
    let final_fit = displacement_scores(final_spec, &final_params, fit_files, fit_skip)?;
    let white_final = whiteness(&final_fit.iter().map(|s| s.residual.as_slice()).collect::<Vec<_>>());
    let (structured, band) = structured_residual(white_final, final_fit.len());
    if structured {
        findings.push(match verdict {
            None => format!(
                "{:.2} % unexplained ({} NRMSE), not one of the known effects: the residual is structured ({:.0} % of \
                 autocorrelation lags 1–20 outside the 95 % band, white noise leaves at most {:.0} %) yet no candidate passes",
                final_val * 100.0,
                if held_out { "validation" } else { "fit-file" },
                white_final * 100.0,
                band * 100.0
            ),
            Some(v) => format!(
                "with `{v}` added {:.2} % stays unexplained and structured ({:.0} % of lags outside the band, white noise at \
                 most {:.0} %): diagnose `{}` again; what is left may be none of the known effects",
                final_val * 100.0,
                white_final * 100.0,
                band * 100.0,
                spec.with(v)
            ),
        });
    }
    Ok(findings)
}

/// The files at the two ends of one quantity (frequency, amplitude, length) whose errors differ.
struct Trend {
    lo: usize,
    hi: usize,
    what: &'static str,
    unit: &'static str,
    from: f64,
    to: f64,
}

/// One finding per pair of files: trends read from the same two files are one observation (the
/// files differ in those quantities at once and cannot say which the error follows).
fn trend_findings(trends: &[Trend], per_file: &[(f64, f64, f64, f64)], names: &[&str]) -> Vec<String> {
    let mut out = Vec::new();
    let mut done = vec![false; trends.len()];
    for (i, t) in trends.iter().enumerate() {
        if done[i] {
            continue;
        }
        let same: Vec<&Trend> = trends
            .iter()
            .enumerate()
            .filter(|(_, u)| (u.lo, u.hi) == (t.lo, t.hi) || (u.lo, u.hi) == (t.hi, t.lo))
            .map(|(j, u)| {
                done[j] = true;
                u
            })
            .collect();
        let (a, b) = (per_file[t.lo].3, per_file[t.hi].3);
        if let [only] = same.as_slice() {
            out.push(format!(
                "error {} with {}: {:.2} % at {:.3} {unit} → {:.2} % at {:.3} {unit}",
                if b > a { "grows" } else { "falls" },
                only.what,
                a * 100.0,
                only.from,
                b * 100.0,
                only.to,
                unit = only.unit
            ));
        } else {
            // Each quantity's values in the files' order (from the first file to the second).
            let how: Vec<String> = same
                .iter()
                .map(|u| {
                    let (x, y) = if u.lo == t.lo { (u.from, u.to) } else { (u.to, u.from) };
                    format!("{} {x:.3} → {y:.3} {}", u.what, u.unit)
                })
                .collect();
            out.push(format!(
                "error {:.2} % in {} against {:.2} % in {}, files that differ in {} at once: they cannot say which \
                 the error follows (a file that changes one of them alone can)",
                a * 100.0,
                names[t.lo],
                b * 100.0,
                names[t.hi],
                how.join(", ")
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// No verdict after a time limit that left a candidate untested or stopped its refit is
    /// "undecided", never "nothing is missing" (a refit stopped at once ends near the baseline
    /// and cannot pass: that answer would be the time limit's, not the data's).
    #[test]
    fn no_verdict_is_undecided_when_the_time_limit_cut_a_candidate() {
        let d = |not_refitted: Vec<Effect>, cut_short: Vec<Effect>| Diagnosis {
            model: "ja".into(),
            nrmse_fit: 0.05,
            nrmse_val: None,
            candidates: Vec::new(),
            verdict: None,
            undistinguished: Vec::new(),
            not_refitted,
            cut_short,
            findings: Vec::new(),
            baseline: None,
            time_limited: true,
            ja_variants: None,
            laws: None,
        };
        assert_eq!(d(vec![], vec![]).no_verdict(), "nothing significant is missing");
        let cut = d(vec![], vec![Effect::EddyCurrent]).to_string();
        assert!(
            cut.starts_with("verdict: undecided — the time limit stopped the refit of `eddy_current` before it converged; raise the time limit (`--time-limit`, Python's `time_limit_s`)"),
            "{cut}"
        );
        let both = d(vec![Effect::MechanicalDynamics], vec![Effect::EddyCurrent]).no_verdict();
        assert!(
            both.contains("left `mechanical_dynamics` untested and stopped the refit of `eddy_current`"),
            "{both}"
        );
    }

    /// Plumbing, on the model's own data (it proves the wiring, not the physics: the
    /// independent rig's suite does that): with `temperature_C` logged, coil heating is judged
    /// on the temperature, and named where the model lacks it.
    #[test]
    fn coil_heating_is_judged_on_a_logged_temperature() {
        let dt = 2e-3;
        let heating = ModelSpec::parse("linear+thermal").unwrap();
        let mut p = model_core::ActuatorParams::TERFENOL_DEMO;
        p.dt_s = dt as f32;
        p.thermal.tau_s = 60.0;
        p.thermal.thermal_resistance_c_per_w = 4.0;
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut file = |name: &str, f_hz: f64, amp_a: f64, secs: f64| {
            let n = (secs / dt) as usize;
            let mut rec = Recording::with_time(name, n, dt);
            let w = 2.0 * std::f64::consts::PI * f_hz * dt;
            rec.current_a = Some((0..n).map(|k| 0.3 + amp_a * (w * k as f64).sin()).collect());
            let (sim, _) = crate::simulation::simulate_drive(
                heating,
                &p,
                &rec,
                crate::simulation::InitialState::Demagnetized,
            )
            .unwrap();
            // Uniform noise: 0.01 µm and 0.02 °C rms.
            let mut noisy = |v: f64, rms: f64| v + rng.random_range(-1.0..1.0) * rms * 3f64.sqrt();
            rec.displacement_um = Some(sim.displacement_um.iter().map(|y| noisy(y + 5.0, 0.01)).collect());
            rec.temperature_c = Some(sim.temperature_rise_c.iter().map(|t| noisy(22.0 + t, 0.02)).collect());
            rec
        };
        let fit_files = vec![file("fit", 2.0, 1.0, 12.0)];
        let val_files = vec![file("val", 3.0, 0.8, 10.0)];
        let d = diagnose(ModelSpec::LINEAR, &p, &fit_files, &val_files, FitOptions::default()).unwrap();
        let c = d.candidates.iter().find(|c| c.effect == Effect::ThermalDrift).unwrap();
        assert_eq!(c.channel, "temperature", "{d}");
        assert_eq!(d.verdict, Some(Effect::ThermalDrift), "{d}");
        assert!(c.nrmse_before > 3.0 * c.nrmse_after, "{d}");
        // Without the log it is judged on the displacement, as before.
        let unlogged = |files: &[Recording]| -> Vec<Recording> {
            files.iter().cloned().map(|r| Recording { temperature_c: None, ..r }).collect()
        };
        let d = diagnose(
            ModelSpec::LINEAR,
            &p,
            &unlogged(&fit_files),
            &unlogged(&val_files),
            FitOptions::default(),
        )
        .unwrap();
        let c = d.candidates.iter().find(|c| c.effect == Effect::ThermalDrift).unwrap();
        assert_eq!(c.channel, "displacement", "{d}");
    }

    /// A channel some files log and others not is said, naming the files without it (the
    /// diagnosis then judged on the displacement without a word); none when all or none log it.
    #[test]
    fn a_channel_some_files_lack_is_said_with_those_files() {
        let file = |name: &str, flux: bool| {
            let mut r = Recording::with_time(name, 10, 1e-4);
            r.current_a = Some(vec![0.0; 10]);
            r.flux_density_t = flux.then(|| vec![0.0; 10]);
            r
        };
        let said = Measured::partly(&[file("a", true), file("b", true)], &[file("v", false)]);
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(said[0].starts_with("flux_density_T: logged in some files but not in v:"), "{said:?}");
        assert!(Measured::partly(&[file("a", true)], &[file("v", true)]).is_empty());
        assert!(Measured::partly(&[file("a", false)], &[file("v", false)]).is_empty());
    }

    #[test]
    fn required_wins_is_the_one_sided_sign_test_at_five_percent() {
        // Below five files no count is significant: all must improve.
        for n in 1..=5 {
            assert_eq!(required_wins(n), n, "n = {n}");
        }
        // P(≥ 5 of 6) = 7/64 > 5 %, P(6 of 6) = 1/64; P(≥ 7 of 8) = 9/256 ≤ 5 % < P(≥ 6 of 8).
        assert_eq!(required_wins(6), 6);
        assert_eq!(required_wins(8), 7);
        assert_eq!(required_wins(10), 9);
        // What the "no candidate passes" finding says: all of up to seven files.
        assert_eq!(all_must_improve_up_to(), 7);
    }

    fn candidate(effect: Effect, cut: f64, r2: f64, delta_bic: f64, n_eff: f64) -> Candidate {
        Candidate {
            effect,
            channel: "displacement",
            score: 0.5,
            evidence: String::new(),
            nrmse_before: 0.03,
            nrmse_after: 0.03 / cut,
            evidence_r2: r2,
            files_improved: 4,
            files_scored: 4,
            files_showing: 4,
            files_improved_showing: 4,
            files_deciding: 4,
            files_improved_deciding: 4,
            held_out: true,
            delta_bic,
            n_eff,
            per_file_after: vec![0.03 / cut; 4],
            refit: None,
        }
    }

    /// The verdict among candidates the data cannot tell apart is a property of the set, not of
    /// the order they arrive in: R² within their significance (3.84/N_eff = 0.4 %) leave it to
    /// ΔBIC, whatever order the cuts put them in. (A pairwise "R² if they differ, else ΔBIC"
    /// picked `sensor_delay` in one order and `eddy_current` in another.)
    #[test]
    fn the_choice_among_undistinguished_candidates_does_not_depend_on_their_order() {
        let set = [
            candidate(Effect::EddyCurrent, 2.02, 0.300, 10.0, 1000.0),
            candidate(Effect::MechanicalDynamics, 2.01, 0.297, 30.0, 1000.0),
            candidate(Effect::SensorDelay, 2.00, 0.294, 50.0, 1000.0),
        ];
        for order in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
            let tied: Vec<&Candidate> = order.iter().map(|&i| &set[i]).collect();
            let (k, by_signature) = choose_among_tied(&tied);
            assert_eq!(tied[k].effect, Effect::SensorDelay, "order {order:?}");
            assert!(!by_signature);
        }
        // A signature that explains clearly more than every other's decides, ΔBIC or not.
        let set = [
            candidate(Effect::EddyCurrent, 2.0, 0.60, 10.0, 1000.0),
            candidate(Effect::MechanicalDynamics, 2.0, 0.30, 30.0, 1000.0),
            candidate(Effect::SensorDelay, 2.0, 0.297, 50.0, 1000.0),
        ];
        for order in [[0, 1, 2], [2, 1, 0], [1, 2, 0]] {
            let tied: Vec<&Candidate> = order.iter().map(|&i| &set[i]).collect();
            let (k, by_signature) = choose_among_tied(&tied);
            assert_eq!((tied[k].effect, by_signature), (Effect::EddyCurrent, true), "order {order:?}");
        }
    }

    /// Issue 61: an aftereffect refit lower on 4 of 5 validation files was refused, its fifth
    /// file worse by less than its own noise. Such a file is a tie and does not vote; a fifth
    /// file worse beyond the noise still refuses it.
    #[test]
    fn a_file_that_moves_by_less_than_its_noise_does_not_vote() {
        let mut c = candidate(Effect::MagneticAftereffect, 2.0, 0.3, 120.0, 1000.0);
        (c.files_scored, c.files_showing, c.files_improved_showing) = (5, 5, 4);
        (c.files_deciding, c.files_improved_deciding) = (4, 4);
        assert!(c.passes());
        (c.files_deciding, c.files_improved_deciding) = (5, 4);
        assert!(!c.passes());
        (c.files_deciding, c.files_improved_deciding) = (0, 0);
        assert!(!c.passes(), "a refit that moves no file beyond its noise shows nothing");
    }

    /// An exact refit of a noise-free recording is the strongest evidence there is: it passes
    /// (its cut was read as 1× before, and it could never pass).
    #[test]
    fn an_exact_refit_cuts_the_error_infinitely_and_passes() {
        let mut c = candidate(Effect::Hysteresis, 2.0, 0.5, 100.0, 1000.0);
        c.nrmse_after = 0.0;
        c.per_file_after = vec![0.0; 4];
        assert!(c.cut().is_infinite());
        assert!(c.passes());
        assert_eq!(cut_words(c.cut()), "to zero");
        assert_eq!(error_cut(f64::NAN, 0.01), 1.0);
        assert_eq!(error_cut(0.0, 0.0), 1.0);
        assert_eq!(cut_words(0.5), "2.0× higher");
        assert_eq!(cut_words(1.003), "unchanged");
        assert_eq!(cut_words(1.0 / 1.003), "unchanged");
        assert_eq!(cut_words(1.02), "1.02× lower");
        assert_eq!(cut_words(1.0 / 1.06), "1.06× higher");
        assert_eq!(cut_words(1.12), "1.1× lower");
    }

    /// A law with a memory starts each scored file from a fitted pre-history: one parameter per
    /// file that the information criterion counts when a refit adds the memory.
    #[test]
    fn a_fitted_initial_state_per_file_counts_as_a_parameter() {
        let spec = |s: &str| ModelSpec::parse(s).unwrap();
        assert_eq!(estimated_states(spec("anhysteretic+mech"), 4), 0);
        assert_eq!(estimated_states(spec("ja+mech"), 4), 4);
        assert_eq!(estimated_states(spec("preisach"), 3), 3);
        assert_eq!(estimated_states(spec("linear"), 3), 0);
    }

    /// A file counts for an effect when switching it off moves the prediction by more than the
    /// noise, whatever slow model error the refit leaves there: the successive-difference noise
    /// estimate sees the white part of the residual, not a slow error ten times its size.
    #[test]
    fn an_effect_shows_where_it_moves_the_prediction_above_the_noise() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let n = 4000;
        let slow = |k: usize| (2.0 * std::f64::consts::PI * k as f64 / n as f64).sin();
        let noise: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0) * 0.01 * 3f64.sqrt()).collect();
        // The refit misses a slow error of 10 noise rms and the sensor's noise (rms 0.01).
        let on: Vec<f64> = (0..n).map(|k| 0.1 * slow(k) + noise[k]).collect();
        // Switched off, the effect moves the prediction by 2 or by 0.5 noise rms (plus an offset,
        // which does not count).
        let moved = |size: f64| -> Vec<f64> {
            on.iter().enumerate().map(|(k, r)| r + 0.3 + size * 0.01 * 2f64.sqrt() * slow(3 * k)).collect()
        };
        assert!(effect_shows(&moved(2.0), &on));
        assert!(!effect_shows(&moved(0.5), &on));
    }

    #[test]
    fn a_refit_is_unpinned_only_when_it_gains_on_the_fit_files_and_loses_on_every_validation_file() {
        let worse_everywhere = [(0.014, 0.020), (0.010, 0.067)];
        assert!(not_pinned_by_the_fit_files((0.012, 0.009), &worse_everywhere));
        // No gain on the fit files: a failed or idle refit, not an unpinned one.
        assert!(!not_pinned_by_the_fit_files((0.012, 0.012), &worse_everywhere));
        // One validation file better: no pattern.
        assert!(!not_pinned_by_the_fit_files((0.012, 0.009), &[(0.014, 0.020), (0.010, 0.009)]));
        // One validation file alone is no pattern either.
        assert!(!not_pinned_by_the_fit_files((0.012, 0.009), &[(0.014, 0.020)]));
    }

    fn rec_with(u: Vec<f64>, i: Vec<f64>, dt: f64) -> Recording {
        let mut r = Recording::with_time("t.csv", u.len(), dt);
        r.displacement_um = Some(u.iter().map(|v| v * 10.0).collect());
        r.command_v = Some(u);
        r.current_a = Some(i);
        r
    }

    #[test]
    fn burn_in_is_the_first_drive_cycle() {
        let dt = 1e-4;
        let u: Vec<f64> =
            (0..4000).map(|k| (2.0 * std::f64::consts::PI * 10.0 * k as f64 * dt).sin()).collect();
        let rec = rec_with(u.clone(), u, dt);
        // A 10 Hz sine reverses at 25 and 75 ms; the second reversal is confirmed shortly after.
        let k = burn_in(&rec);
        assert!((750..900).contains(&k), "burn-in {k} samples");
    }

    #[test]
    fn static_gain_sees_an_amplifier_lag_only_when_there_is_one() {
        let dt = 1e-4;
        let u: Vec<f64> = (0..3000)
            .map(|k| {
                let t = k as f64 * dt;
                (2.0 * std::f64::consts::PI * 40.0 * t).sin()
                    + 0.5 * (2.0 * std::f64::consts::PI * 170.0 * t).sin()
            })
            .collect();
        let ideal: Vec<f64> = u.iter().map(|v| 2.0 * v + 0.01).collect();
        let lagged: Vec<f64> = lowpass(&u, dt, 5e-4).iter().map(|v| 2.0 * v).collect();
        let files = [rec_with(u.clone(), ideal, dt)];
        let skip = [burn_in(&files[0])];
        let g = StaticGain::fit(&files, &skip);
        assert!((g.gain - 2.0).abs() < 1e-9 && (g.offset - 0.01).abs() < 1e-9);
        assert!(g.scores(&files, &skip)[0].nrmse < 1e-9);
        let files = [rec_with(u, lagged, dt)];
        let g = StaticGain::fit(&files, &skip);
        assert!(g.scores(&files, &skip)[0].nrmse > 0.01);
        // −d(g·u)/dt is the first-order sketch of the lag: most, not all, of its residual.
        assert!(g.lag_evidence(&files, &skip) > 0.8, "lag evidence {}", g.lag_evidence(&files, &skip));
    }
}
