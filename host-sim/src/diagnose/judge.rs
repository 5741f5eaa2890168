//! One candidate judged against the baseline: its refit scored on the channel nearest where the
//! effect acts, file by file, with the evidence in words.

use anyhow::Result;
use model_core::effects::Candidacy;
use model_core::{Effect, ModelSpec};

use super::candidate::{cut_words, error_cut, Candidate};
use super::scoring::{channel_scores, information_gain, Channel, Measured, Scored, StaticGain};
use super::signatures::{
    evidence, flux_signature_words, heating_evidence, signature_words, where_it_shows, Signals,
};
use super::{effective_samples, estimated_states, not_pinned_by_the_fit_files, significance_words};
use crate::fit::FitResult;
use crate::recording::Recording;
use crate::signal::mean;
use crate::simulated::Simulation;

/// How far above the baseline's fit NRMSE (a fraction of it) a refit must end to count as a
/// failed search. The refinement starts from the baseline with the effect's parameters at their
/// start values, not switched off, and stops on its evaluation budget: an effect the data do not
/// need ends a few 1e-5 above the baseline (coil heating in short files: 2.8352 % against
/// 2.8350 %), the same point to within what the search resolves, and no failure.
const FAILED_SEARCH_MARGIN: f64 = 1e-3;

/// The given structure's fit and everything a candidate is judged against.
pub(super) struct Baseline<'a> {
    pub spec: ModelSpec,
    pub base: &'a FitResult,
    pub fit_files: &'a [Recording],
    /// The validation files, else the fit files.
    pub score_files: &'a [Recording],
    /// Each fit file's burn-in ([`super::burn_in`]), left out of its scores.
    pub fit_skip: &'a [usize],
    /// Each scored file's burn-in.
    pub score_skip: &'a [usize],
    /// The scored files are validation files.
    pub held_out: bool,
    pub measured: Measured,
    /// With `current_A` and `command_V` in every file: command → current by a static gain, the
    /// amplifier's baseline on the current.
    pub static_amp: Option<StaticGain>,
    /// The baseline's displacement scores on the fit files and on the scored files.
    pub fit_disp: Vec<Scored>,
    pub score_disp: Vec<Scored>,
    /// Its flux-density scores likewise (empty without a search coil).
    pub fit_flux: Vec<Scored>,
    pub score_flux: Vec<Scored>,
    /// The baseline's runs on the fit files, and the signatures' signals from them.
    pub sims: &'a [Simulation],
    pub sigs: &'a [Signals],
    pub flux_sigs: &'a [Signals],
}

/// A candidate judged, and what its refit said about the search.
pub(super) struct Judged {
    pub candidate: Candidate,
    /// The refit ended above the baseline's fit cost: a failed search.
    pub failed_refit: Option<String>,
    /// The refit could not be run.
    pub errored_refit: Option<String>,
    /// The refit fits the fit files better and every validation file worse.
    pub unpinned: Option<String>,
}

impl Baseline<'_> {
    /// `e` judged by its refit (or its error).
    pub fn judge(&self, e: Effect, refit: Result<FitResult>) -> Result<Judged> {
        let (spec, base) = (self.spec, self.base);
        let (fit_files, score_files) = (self.fit_files, self.score_files);
        let (fit_skip, score_skip) = (self.fit_skip, self.score_skip);
        let s2 = spec.with(e);
        let channel = Channel::judging(e, self.measured);
        let (base_fit_s, base_score_s, r2) = match (&self.static_amp, channel) {
            (Some(amp), Channel::Current) => (
                amp.scores(fit_files, fit_skip),
                amp.scores(score_files, score_skip),
                amp.lag_evidence(fit_files, fit_skip),
            ),
            (_, Channel::FluxDensity) => {
                (self.fit_flux.clone(), self.score_flux.clone(), evidence(e, self.flux_sigs))
            }
            (_, Channel::Temperature) => (
                channel_scores(spec, &base.params, fit_files, fit_skip, channel)?,
                channel_scores(spec, &base.params, score_files, score_skip, channel)?,
                heating_evidence(fit_files, self.sims, fit_skip),
            ),
            _ => (self.fit_disp.clone(), self.score_disp.clone(), evidence(e, self.sigs)),
        };
        let n_eff: f64 = base_fit_s.iter().map(|s| effective_samples(&s.residual)).sum();
        let (refit, errored_refit) = match refit {
            Ok(f) => (Some(f), None),
            Err(why) => (None, Some(format!("`{e}` ({why:#})"))),
        };
        // The refit contains the given structure (the effect switched off or negligible), so a
        // fit cost above the baseline's is a failed search, not evidence against the effect.
        // Compared only where both costs weigh the same channels (not when `amp` adds the current
        // or coil heating the temperature).
        let adds_a_channel = e == Effect::AmplifierDynamics || channel == Channel::Temperature;
        let failed_refit = refit.as_ref().filter(|_| !adds_a_channel).and_then(|f| {
            let (b, a) = (base.fit.cost(), f.fit.cost());
            (a.sqrt() > b.sqrt() * (1.0 + FAILED_SEARCH_MARGIN))
                .then(|| format!("`{e}` ({:.3} % > {:.3} %)", a.sqrt() * 100.0, b.sqrt() * 100.0))
        });
        let after_score_s = match &refit {
            Some(f) => channel_scores(s2, &f.params, score_files, score_skip, channel)?,
            None => base_score_s.clone(),
        };
        let before_c = mean(base_score_s.iter().map(|s| s.nrmse));
        let after_c = mean(after_score_s.iter().map(|s| s.nrmse));
        let files_improved =
            base_score_s.iter().zip(&after_score_s).filter(|(b, a)| a.nrmse < b.nrmse).count();
        // Where the effect shows: the refit's own parameters with the effect switched off (the
        // given structure) against the refit, file by file, measured against the noise. A law
        // refinement cannot be switched off that way (the coarser law's parameters were not
        // fitted), nor can the amplifier on the current (judged against a static gain): there
        // every file votes.
        let law_refinement = e.info().candidacy == Candidacy::RefinesLaw;
        let showing: Vec<bool> = match &refit {
            Some(f) if !law_refinement && channel != Channel::Current => {
                let off = channel_scores(spec, &f.params, score_files, score_skip, channel)?;
                off.iter()
                    .zip(&after_score_s)
                    .map(|(o, a)| super::scoring::effect_shows(&o.residual, &a.residual))
                    .collect()
            }
            _ => vec![true; after_score_s.len()],
        };
        let files_showing = showing.iter().filter(|&&v| v).count();
        // The sign test's votes: files it shows in where the refit's prediction moved from the
        // baseline's by more than the noise (a smaller move, better or worse, is a tie).
        let deciding: Vec<bool> = base_score_s
            .iter()
            .zip(&after_score_s)
            .zip(&showing)
            .filter(|((b, a), &shows)| shows && super::scoring::effect_shows(&b.residual, &a.residual))
            .map(|((b, a), _)| a.nrmse < b.nrmse)
            .collect();
        let files_deciding = deciding.len();
        let files_improved_deciding = deciding.iter().filter(|&&lower| lower).count();
        let files_improved_showing = base_score_s
            .iter()
            .zip(&after_score_s)
            .zip(&showing)
            .filter(|((b, a), &shows)| shows && a.nrmse < b.nrmse)
            .count();
        let unpinned = self.unpinned(e, refit.as_ref(), channel, &base_score_s, &after_score_s);
        let added = refit
            .as_ref()
            .map_or(0, |f| {
                (f.free.len() + estimated_states(s2, score_files.len()))
                    .saturating_sub(base.free.len() + estimated_states(spec, score_files.len()))
            })
            .max(1);
        // Judged on the scored files: with validation files a gain there is one the added
        // parameters could not buy by fitting (the fit files reward any flexibility that absorbs
        // model-form error, and punish a refit that stops doing so).
        let n_eff_files: Vec<f64> = base_score_s.iter().map(|s| effective_samples(&s.residual)).collect();
        let n_eff_scored: f64 = n_eff_files.iter().sum();
        let delta_bic = information_gain(&base_score_s, &after_score_s, &n_eff_files)
            - added as f64 * n_eff_scored.max(2.0).ln();
        let cut = error_cut(before_c, after_c);
        let evidence = format!(
            "{} explains {:.0} % of the residual variance ({}); adding it and \
             refitting takes the {} {channel} NRMSE from {:.2} % to {:.2} % ({}), lower on {files_improved} of {} \
             files ({files_improved_showing} of the {files_showing} it shows in, {files_improved_deciding} of the \
             {files_deciding} it moves beyond the noise); ΔBIC {:+.1}",
            match channel {
                Channel::Current => "the amplifier lag −di/dt of command → current",
                Channel::FluxDensity => flux_signature_words(e.info().signature),
                Channel::Temperature => "the accumulated coil heating ∫i² dt of the temperature",
                Channel::Displacement => signature_words(e.info().signature),
            },
            r2 * 100.0,
            if self.held_out {
                // The signature test applies only on the fit files (docs/cli.md, step 4).
                format!("{}; not required on validation files, where the cut is the evidence", significance_words(n_eff))
            } else {
                significance_words(n_eff)
            },
            if self.held_out { "validation" } else { "fit" },
            before_c * 100.0,
            after_c * 100.0,
            cut_words(cut),
            after_score_s.len(),
            delta_bic,
            channel = channel.name(),
        );
        let score = (0.5 * r2 + 0.5 * (1.0 - after_c / before_c).max(0.0)).clamp(0.0, 1.0);
        let candidate = Candidate {
            effect: e,
            channel: channel.name(),
            score,
            evidence,
            nrmse_before: before_c,
            nrmse_after: after_c,
            evidence_r2: r2,
            files_improved,
            files_scored: after_score_s.len(),
            files_showing,
            files_improved_showing,
            files_deciding,
            files_improved_deciding,
            held_out: self.held_out,
            delta_bic,
            n_eff,
            per_file_after: after_score_s.iter().map(|s| s.nrmse).collect(),
            refit,
        };
        Ok(Judged { candidate, failed_refit, errored_refit, unpinned })
    }

    /// With validation files: the refit fits the fit files better and every validation file
    /// worse, so what it adds is not pinned by the fit files (said, with where the effect shows).
    fn unpinned(
        &self,
        e: Effect,
        refit: Option<&FitResult>,
        channel: Channel,
        base_score_s: &[Scored],
        after_score_s: &[Scored],
    ) -> Option<String> {
        let base = self.base;
        refit.filter(|_| self.held_out && channel == Channel::Displacement).and_then(|f| {
            let fit_nrmse = (base.fit.mean_nrmse(), f.fit.mean_nrmse());
            let scored: Vec<(f64, f64)> =
                base_score_s.iter().zip(after_score_s).map(|(b, a)| (b.nrmse, a.nrmse)).collect();
            not_pinned_by_the_fit_files(fit_nrmse, &scored).then(|| {
                format!(
                    "`{e}` fits the fit files better ({:.2} % → {:.2} %) but every validation file worse ({:.2} % → \
                     {:.2} %): what it adds is fitted to other model error, not determined by these fit files. It \
                     shows in {}: without such a fit file, add one; with one, its form here is not the rig's",
                    fit_nrmse.0 * 100.0,
                    fit_nrmse.1 * 100.0,
                    mean(scored.iter().map(|v| v.0)) * 100.0,
                    mean(scored.iter().map(|v| v.1)) * 100.0,
                    where_it_shows(e)
                )
            })
        })
    }
}
