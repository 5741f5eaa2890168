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

use crate::signal::mean;
use candidate::all_must_improve_up_to;
use candidate::choose_among_tied;
use candidate::cut_words;
use findings::baseline_findings;
use findings::file_trends;
use findings::what_is_left;
use scoring::channel_scores;
use scoring::displacement_scores;
use scoring::Channel;
use scoring::Measured;
use scoring::StaticGain;
use signatures::signals;
use signatures::signature_words;
use signatures::Signals;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use model_core::effects::{Candidacy, MagnetizationLaw, Stage};
use model_core::{Effect, ModelSpec};
use rayon::prelude::*;
use serde::Serialize;

use crate::fit::{evaluate, FitOptions, FitResult};
use crate::simulated::Simulation;
use crate::simulation::simulate;

mod alternatives;
mod candidate;
mod findings;
mod judge;
mod scoring;
mod searches;
mod signatures;
use crate::error::InRecording;
use crate::progress;
use crate::recording::Recording;
use crate::signal::reversals;
pub(crate) use crate::spectral::effective_samples;
pub use alternatives::{check_ja_variants, other_law_structure, LawScore, VariantScore};
use candidate::BIC_STRONG;
pub use candidate::{required_wins, Candidate, CHI2_1_95, DECISIVE_CUT, MIN_CUT};
pub use scoring::burn_in;

/// Search effort of a candidate's fresh fit (from the engineer's start values), beside its
/// refinement from the baseline: half of `gma fit`'s. On the independent rig's grid (docs/validation.md)
/// it named one effect fewer than full effort (26 against 27 of 66), in 0.8× the time of the
/// 8-file diagnosis bench.
pub const FRESH_EFFORT: f64 = 0.5;

/// Fewest samples per fit file for a verdict: the refits have up to about ten parameters, and
/// comparing them needs far more samples than parameters (20 per parameter).
pub const MIN_SAMPLES: usize = 200;

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

/// A refit that is lower on the fit files but higher on every one of at least two validation
/// files (`(before, after)` NRMSE each): what the effect added was fitted to the fit files'
/// model error, not determined by them. A sign pattern, no threshold: one validation file is
/// no pattern.
fn not_pinned_by_the_fit_files(fit_nrmse: (f64, f64), val_files: &[(f64, f64)]) -> bool {
    fit_nrmse.1 < fit_nrmse.0
        && val_files.len() >= 2
        && val_files.iter().all(|(before, after)| after > before)
}

/// Dominant frequency of a drive (zero crossings of its AC part) [Hz] and its rms amplitude.
fn drive_stats(rec: &Recording) -> (f64, f64) {
    let u = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    let rms = (u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / u.len() as f64).sqrt();
    let crossings = u.windows(2).filter(|w| (w[0] - mean) * (w[1] - mean) < 0.0).count();
    (crossings as f64 / 2.0 / rec.duration_s().max(1e-12), rms)
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
    // The channels' signs, judged at the baseline's fit (not the start set's), and a file at
    // another scale than the others (before any effect is named for it).
    let doubts =
        crate::fit::sign_and_scale_doubts(init, &base, fit_files, val_files, opts, &Default::default())?;
    findings.extend(doubts.iter().map(|w| format!("in the fit of `{spec}`: {w}")));
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

#[cfg(test)]
mod tests;
