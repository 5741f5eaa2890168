//! Other forms of the diagnosed structure, refitted and set beside it: the other forms of
//! Jiles–Atherton (`--ja-variants`) and the other hysteresis law (`--laws`: J–A ↔ Preisach).
//! Neither is a missing effect — the structure keeps its effects, only its magnetization law
//! changes form or kind — so neither is a verdict; each gives a finding and a JSON table.
//!
//! Each alternative is fitted from the baseline's values (the dynamics it found carry over) and
//! from the engineer's start values, the better kept, and scored like the candidates of the
//! magnetization stage: validation files, else fit files, after each burn-in, on the flux density
//! when every file logs a search coil's `flux_density_T` (nearest the law), else on the
//! displacement. It is named as fitting better by the candidates' rule: cut ≥ [`MIN_CUT`]× —
//! [`DECISIVE_CUT`]× when only the fit files score it, as for a candidate without a significant
//! signature (an alternative has none, and a law fitted to the files it is scored on gains from
//! any flexibility) — lower on [`required_wins`] of the scored files, and, for the laws, whose
//! parameter counts differ, a positive ΔBIC with the effective sample size.

use anyhow::{bail, Result};
use model_core::magnetization::JaVariant;
use model_core::{ActuatorParams, Effect, MagnetizationLaw, ModelSpec};
use rayon::prelude::*;
use serde::Serialize;

use super::candidate::{error_cut, required_wins, DECISIVE_CUT, MIN_CUT};
use super::scoring::{burn_in, channel_scores, information_gain, Channel, Measured, Scored};
use super::{effective_samples, estimated_states, Diagnosis};
use crate::fit::{self, FitOptions};
use crate::progress;
use crate::recording::Recording;
use crate::signal::mean;

/// One J–A form's score in [`Diagnosis::compare_ja_variants`].
#[derive(Debug, Clone, Serialize)]
pub struct VariantScore {
    /// Its name, as `[ja] variant` takes it.
    pub variant: &'static str,
    /// The form the parameter file gave (its score is the baseline's).
    pub given: bool,
    /// The channel scored: `flux_density` when every file logs it, else `displacement`.
    pub channel: &'static str,
    /// Mean NRMSE on `channel` of the scored files (validation, else fit), after each burn-in.
    pub nrmse: f64,
    /// Scored files on which it is lower than the given form (0 for the given form).
    pub files_improved: usize,
    /// Scored files.
    pub files_scored: usize,
    /// Named as fitting better than the given form (at most one: the lowest that passes).
    pub fits_better: bool,
}

/// One hysteresis law's score in [`Diagnosis::compare_laws`].
#[derive(Debug, Clone, Serialize)]
pub struct LawScore {
    /// The law as model specs name it: `ja` (Jiles–Atherton) or `preisach`.
    pub law: &'static str,
    /// The diagnosed structure with this law.
    pub model: String,
    /// The law the structure was given with (its score is the baseline's).
    pub given: bool,
    /// The channel scored: `flux_density` when every file logs it, else `displacement`.
    pub channel: &'static str,
    /// Mean NRMSE on `channel` of the scored files (validation, else fit), after each burn-in.
    pub nrmse: f64,
    /// Scored files on which it is lower than the given law (0 for the given law).
    pub files_improved: usize,
    /// Scored files.
    pub files_scored: usize,
    /// BIC gain over the given law on the scored files (effective sample size; the laws have
    /// different numbers of parameters); 0 for the given law.
    pub delta_bic: f64,
    /// Named as fitting better than the given law.
    pub fits_better: bool,
}

/// Refuses `--ja-variants` on a structure without a J–A law (the CLI asks before the diagnosis,
/// so the mistake costs no fit).
pub fn check_ja_variants(spec: ModelSpec) -> Result<()> {
    if spec.law() != MagnetizationLaw::JilesAtherton {
        bail!("--ja-variants compares the forms of Jiles–Atherton; `{spec}` has no J–A law (add `ja`)");
    }
    Ok(())
}

/// The structure with the other hysteresis law, and the names of both, or why there is none.
fn other_law(spec: ModelSpec) -> Result<((&'static str, &'static str), ModelSpec)> {
    match spec.law() {
        MagnetizationLaw::JilesAtherton => Ok((
            ("ja", "preisach"),
            spec.without(Effect::Hysteresis).without(Effect::Saturation).with(Effect::Preisach),
        )),
        MagnetizationLaw::Preisach => {
            Ok((("preisach", "ja"), spec.without(Effect::Preisach).with(Effect::Hysteresis)))
        }
        _ => bail!(
            "--laws compares the hysteresis laws (`ja`: Jiles–Atherton, `preisach`); `{spec}` has neither (add one)"
        ),
    }
}

/// The structure `--laws` refits: `spec` with the other hysteresis law (its start values come
/// from the same parameter file, so the CLI checks the file for it before any fit), or why there
/// is none (a structure without a hysteresis law is refused).
pub fn other_law_structure(spec: ModelSpec) -> Result<ModelSpec> {
    other_law(spec).map(|(_, other)| other)
}

/// An alternative structure and where its fit starts.
struct Alternative {
    name: &'static str,
    spec: ModelSpec,
    starts: [ActuatorParams; 2],
}

/// An alternative scored against the given structure.
struct Compared {
    name: &'static str,
    spec: ModelSpec,
    nrmse: f64,
    files_improved: usize,
    files_scored: usize,
    delta_bic: f64,
}

/// The given structure's scores and every alternative's.
struct Comparison {
    given_nrmse: f64,
    files_scored: usize,
    channel: Channel,
    /// The scored files are validation files (held out from every fit).
    held_out: bool,
    alternatives: Vec<Compared>,
    /// Alternatives not refitted: `--time-limit` (or Ctrl-C) came first. Their start values
    /// are no fit, so they are left out, as candidates are.
    not_refitted: Vec<&'static str>,
    /// Alternatives whose refit or scoring failed, with the reason: left out, the rest of the
    /// diagnosis stands.
    errored: Vec<String>,
}

impl Comparison {
    /// The channel scored, in words.
    fn channel_words(&self) -> &'static str {
        match self.channel {
            Channel::FluxDensity => "flux density",
            other => other.name(),
        }
    }

    /// The files scored, in words.
    fn files_words(&self) -> &'static str {
        if self.held_out {
            "validation files"
        } else {
            "fit files"
        }
    }

    /// What was scored, in words: "the displacement of the validation files".
    fn on(&self) -> String {
        format!("{} of the {}", self.channel_words(), self.files_words())
    }

    /// The cut an alternative needs: [`MIN_CUT`] on held-out files; on the fit files, which it
    /// was fitted to, [`DECISIVE_CUT`] (it has no signature to indicate it otherwise).
    fn needed_cut(&self) -> f64 {
        if self.held_out {
            MIN_CUT
        } else {
            DECISIVE_CUT
        }
    }

    /// The alternatives left out, in words ("" when none).
    fn left_out_words(&self) -> String {
        let mut words = String::new();
        if !self.not_refitted.is_empty() {
            words += &format!(
                "; not refitted (the time limit was reached first), left out: `{}`",
                self.not_refitted.join("`, `")
            );
        }
        if !self.errored.is_empty() {
            words += &format!("; could not be refitted, left out: {}", self.errored.join(", "));
        }
        words
    }

    /// The rule, in words: "cut ≥ 1.5× on the displacement, lower on 2 of 2 validation files".
    fn rule_words(&self, bic: bool) -> String {
        format!(
            "cut ≥ {}× on the {}, lower on {} of {} {}{}",
            self.needed_cut(),
            self.channel_words(),
            required_wins(self.files_scored),
            self.files_scored,
            self.files_words(),
            if bic { ", and ΔBIC > 0" } else { "" }
        )
    }

    /// The lowest alternative that passes the rule (ΔBIC > 0 too when `bic`).
    fn better(&self, bic: bool) -> Option<&Compared> {
        self.alternatives
            .iter()
            .filter(|a| {
                error_cut(self.given_nrmse, a.nrmse) >= self.needed_cut()
                    && a.files_improved >= required_wins(a.files_scored)
                    && (!bic || a.delta_bic > 0.0)
            })
            .min_by(|a, b| a.nrmse.total_cmp(&b.nrmse))
    }
}

impl Diagnosis {
    /// Refits each alternative (in parallel) and scores it beside the baseline on the channel
    /// the magnetization stage is judged on.
    fn refit_alternatives(
        &mut self,
        spec: ModelSpec,
        alternatives: Vec<Alternative>,
        fit_files: &[Recording],
        val_files: &[Recording],
        opts: FitOptions,
        what: &str,
    ) -> Result<Comparison> {
        let Some(base) = self.baseline.as_ref() else {
            bail!("this diagnosis carries no baseline fit to compare {what} with");
        };
        let score_files = if val_files.is_empty() { fit_files } else { val_files };
        let skip: Vec<usize> = score_files.iter().map(burn_in).collect();
        let channel = Channel::judging(Effect::Hysteresis, Measured::in_every(fit_files, score_files));
        let before = channel_scores(spec, &base.params, score_files, &skip, channel)?;
        let n_eff_files: Vec<f64> = before.iter().map(|s| effective_samples(&s.residual)).collect();
        let n_eff: f64 = n_eff_files.iter().sum();
        let base_free = (base.free.len() + estimated_states(spec, score_files.len())) as f64;
        let past_deadline = || fit::time_left(opts.deadline).is_some_and(|t| t.is_zero());
        let phase = progress::Phase::start(
            opts.progress && !past_deadline(),
            &format!("diagnose: refitting `{spec}` {what}"),
            alternatives.len() as u64,
        );
        type Refit = (Vec<Scored>, bool, usize);
        let refits: Vec<(Alternative, Option<Result<Refit>>)> = alternatives
            .into_par_iter()
            .map(|a| {
                // Past the deadline an alternative is not refitted at all (and said so).
                if past_deadline() {
                    return (a, None);
                }
                let refit =
                    fit::fit_from(a.spec, &a.starts, fit_files, FitOptions { progress: false, ..opts });
                let scored = refit.and_then(|f| {
                    Ok((
                        channel_scores(a.spec, &f.params, score_files, &skip, channel)?,
                        f.time_limited,
                        f.free.len() + estimated_states(a.spec, score_files.len()),
                    ))
                });
                phase.step(&format!("diagnose: `{}` refitted", a.name));
                (a, Some(scored))
            })
            .collect();
        phase.finish();
        let mut compared = Vec::new();
        let mut not_refitted = Vec::new();
        let mut errored = Vec::new();
        for (a, scored) in refits {
            let Some(scored) = scored else {
                self.time_limited = true;
                not_refitted.push(a.name);
                continue;
            };
            let (after, time_limited, free) = match scored {
                Ok(s) => s,
                Err(why) => {
                    errored.push(format!("`{}` ({why:#})", a.name));
                    continue;
                }
            };
            self.time_limited |= time_limited;
            let delta_bic = information_gain(&before, &after, &n_eff_files)
                - (free as f64 - base_free) * n_eff.max(2.0).ln();
            compared.push(Compared {
                name: a.name,
                spec: a.spec,
                nrmse: mean(after.iter().map(|x| x.nrmse)),
                files_improved: before.iter().zip(&after).filter(|(b, a)| a.nrmse < b.nrmse).count(),
                files_scored: after.len(),
                delta_bic,
            });
        }
        Ok(Comparison {
            given_nrmse: mean(before.iter().map(|x| x.nrmse)),
            files_scored: before.len(),
            channel,
            held_out: !val_files.is_empty(),
            alternatives: compared,
            not_refitted,
            errored,
        })
    }

    /// The given structure (a J–A law) refitted in each other J–A form ([`JaVariant`]). A form
    /// is named as fitting better without the information criterion (the forms have the same
    /// parameters). The result goes to `ja_variants` and a finding.
    pub fn compare_ja_variants(
        &mut self,
        spec: ModelSpec,
        init: &ActuatorParams,
        fit_files: &[Recording],
        val_files: &[Recording],
        opts: FitOptions,
    ) -> Result<()> {
        check_ja_variants(spec)?;
        let Some(base) = self.baseline.as_ref() else {
            bail!("this diagnosis carries no baseline fit to compare the J–A forms with");
        };
        let given = base.params.ja.variant;
        let alternatives: Vec<Alternative> = JaVariant::ALL
            .into_iter()
            .filter(|&v| v != given)
            .map(|v| {
                let (mut from_base, mut from_init) = (base.params, *init);
                from_base.ja.variant = v;
                from_init.ja.variant = v;
                Alternative { name: v.name(), spec, starts: [from_base, from_init] }
            })
            .collect();
        let c = self.refit_alternatives(
            spec,
            alternatives,
            fit_files,
            val_files,
            opts,
            "in the other J–A forms",
        )?;
        let better = c.better(false).map(|b| b.name);
        let channel = c.channel.name();
        let mut rows = vec![VariantScore {
            variant: given.name(),
            given: true,
            channel,
            nrmse: c.given_nrmse,
            files_improved: 0,
            files_scored: c.files_scored,
            fits_better: false,
        }];
        rows.extend(c.alternatives.iter().map(|a| VariantScore {
            variant: a.name,
            given: false,
            channel,
            nrmse: a.nrmse,
            files_improved: a.files_improved,
            files_scored: a.files_scored,
            fits_better: Some(a.name) == better,
        }));
        let on = c.on();
        let listed =
            rows.iter().map(|r| format!("`{}` {:.2} %", r.variant, r.nrmse * 100.0)).collect::<Vec<_>>();
        let not_refitted = c.left_out_words();
        self.findings.push(match rows.iter().find(|r| r.fits_better) {
            Some(b) => format!(
                "J–A form: `{}` fits better than the given `{}` ({:.2} % against {:.2} % on the {on}, {}, on {} of {}; \
                 all forms: {}{not_refitted}): set `[ja] variant = \"{}\"`",
                b.variant,
                rows[0].variant,
                b.nrmse * 100.0,
                rows[0].nrmse * 100.0,
                lower_words(rows[0].nrmse, b.nrmse),
                b.files_improved,
                b.files_scored,
                listed.join(", "),
                b.variant
            ),
            None if c.alternatives.is_empty() => format!(
                "J–A form: no other form was compared with the given `{}` ({:.2} % on the {on}){not_refitted}",
                rows[0].variant,
                rows[0].nrmse * 100.0
            ),
            None => format!(
                "J–A form: no form fits clearly better than the given `{}` ({}): {}{not_refitted}",
                rows[0].variant,
                c.rule_words(false),
                listed.join(", ")
            ),
        });
        self.ja_variants = Some(rows);
        Ok(())
    }

    /// The given structure refitted with the other hysteresis law (Jiles–Atherton ↔ Preisach),
    /// the rest of it kept. The law is named as fitting better when it also gains by BIC (the
    /// laws' parameter counts differ). The result goes to `laws` and a finding.
    pub fn compare_laws(
        &mut self,
        spec: ModelSpec,
        init: &ActuatorParams,
        fit_files: &[Recording],
        val_files: &[Recording],
        opts: FitOptions,
    ) -> Result<()> {
        let ((given, other), other_spec) = other_law(spec)?;
        let Some(base) = self.baseline.as_ref() else {
            bail!("this diagnosis carries no baseline fit to compare the laws with");
        };
        let alternative = Alternative { name: other, spec: other_spec, starts: [base.params, *init] };
        let c = self.refit_alternatives(
            spec,
            vec![alternative],
            fit_files,
            val_files,
            opts,
            "with the other law",
        )?;
        let better = c.better(true).is_some();
        let on = c.on();
        let channel = c.channel.name();
        let given_row = LawScore {
            law: given,
            model: spec.to_string(),
            given: true,
            channel,
            nrmse: c.given_nrmse,
            files_improved: 0,
            files_scored: c.files_scored,
            delta_bic: 0.0,
            fits_better: false,
        };
        let Some(a) = c.alternatives.first() else {
            self.findings.push(format!(
                "hysteresis law: `{other}` was not compared with the given `{given}` ({:.2} % on the {on}){}",
                c.given_nrmse * 100.0,
                c.left_out_words()
            ));
            self.laws = Some(vec![given_row]);
            return Ok(());
        };
        self.findings.push(if better {
            format!(
                "hysteresis law: `{other}` fits better than the given `{given}` ({:.2} % against {:.2} % on the {on}, \
                 {}, on {} of {}, ΔBIC {:+.1}): try `--model {}`",
                a.nrmse * 100.0,
                c.given_nrmse * 100.0,
                lower_words(c.given_nrmse, a.nrmse),
                a.files_improved,
                a.files_scored,
                a.delta_bic,
                a.spec
            )
        } else {
            format!(
                "hysteresis law: `{other}` does not fit clearly better than the given `{given}` ({}): `{given}` {:.2} %, \
                 `{other}` {:.2} % (lower on {} of {}, ΔBIC {:+.1}){}",
                c.rule_words(true),
                c.given_nrmse * 100.0,
                a.nrmse * 100.0,
                a.files_improved,
                a.files_scored,
                a.delta_bic,
                c.left_out_words()
            )
        });
        self.laws = Some(vec![
            given_row,
            LawScore {
                law: other,
                model: a.spec.to_string(),
                given: false,
                channel,
                nrmse: a.nrmse,
                files_improved: a.files_improved,
                files_scored: a.files_scored,
                delta_bic: a.delta_bic,
                fits_better: better,
            },
        ]);
        Ok(())
    }
}

/// How much lower an alternative's error is than the given one's, in words ("2.41× lower"; "to
/// zero" for an exact fit, whose ratio is infinite).
fn lower_words(given: f64, alternative: f64) -> String {
    match error_cut(given, alternative) {
        cut if cut.is_infinite() => "to zero".into(),
        cut => format!("{cut:.2}× lower"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn compared(name: &'static str, nrmse: f64, files_improved: usize, delta_bic: f64) -> Compared {
        Compared {
            name,
            spec: ModelSpec::parse("preisach").unwrap(),
            nrmse,
            files_improved,
            files_scored: 2,
            delta_bic,
        }
    }

    fn comparison(held_out: bool, alternatives: Vec<Compared>) -> Comparison {
        Comparison {
            given_nrmse: 0.04,
            files_scored: 2,
            channel: Channel::Displacement,
            held_out,
            alternatives,
            not_refitted: Vec::new(),
            errored: Vec::new(),
        }
    }

    /// On validation files an alternative 2× lower on both, with ΔBIC > 0, fits better; scored
    /// on the fit files it was fitted to, the same figures are not enough (it has no signature
    /// to indicate it, as a candidate there would need): 3× is.
    #[test]
    fn on_the_fit_files_an_alternative_needs_a_decisive_cut() {
        let two = || vec![compared("preisach", 0.02, 2, 10.0)];
        assert_eq!(comparison(true, two()).better(true).map(|a| a.name), Some("preisach"));
        assert!(comparison(false, two()).better(true).is_none());
        let three = comparison(false, vec![compared("preisach", 0.04 / DECISIVE_CUT, 2, 10.0)]);
        assert_eq!(three.better(true).map(|a| a.name), Some("preisach"));
        // The rest of the rule holds on either: every file lower, and ΔBIC > 0 for the laws.
        assert!(comparison(true, vec![compared("preisach", 0.02, 1, 10.0)]).better(true).is_none());
        assert!(comparison(true, vec![compared("preisach", 0.02, 2, -1.0)]).better(true).is_none());
        assert!(comparison(true, vec![compared("bulk", 0.02, 2, -1.0)]).better(false).is_some());
        // An exact alternative is infinitely lower, and said so.
        assert_eq!(lower_words(0.04, 0.0), "to zero");
        assert_eq!(lower_words(0.04, 0.02), "2.00× lower");
    }

    /// An alternative whose refit cannot run is left out with its reason, and the diagnosis goes
    /// on with the others (it ended the whole run, after every candidate's refit, with no
    /// diagnosis). Here the other structure needs a `command_V` column the file lacks.
    #[test]
    fn an_alternative_that_cannot_be_refitted_is_left_out_with_its_reason() {
        let dt = 1e-4;
        let n = 1200;
        let spec = ModelSpec::parse("ja").unwrap();
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.dt_s = dt as f32;
        let mut rec = Recording::with_time("rig", n, dt);
        let w = 2.0 * std::f64::consts::PI * 50.0 * dt;
        rec.current_a = Some((0..n).map(|k| 1.5 * (w * k as f64).sin()).collect());
        let (sim, _) =
            crate::simulation::simulate_drive(spec, &p, &rec, crate::simulation::InitialState::Demagnetized)
                .unwrap();
        rec.displacement_um = Some(sim.displacement_um);
        let files = [rec];
        let opts = FitOptions { effort: 0.1, ..FitOptions::default() };
        let base = fit::fit(spec, &p, &files, opts).unwrap();
        let mut d = Diagnosis {
            model: spec.to_string(),
            nrmse_fit: base.fit.mean_nrmse(),
            nrmse_val: None,
            candidates: Vec::new(),
            verdict: None,
            undistinguished: Vec::new(),
            not_refitted: Vec::new(),
            cut_short: Vec::new(),
            findings: Vec::new(),
            baseline: Some(base.clone()),
            time_limited: false,
            ja_variants: None,
            laws: None,
        };
        let mut other_form = base.params;
        other_form.ja.variant = JaVariant::Original1986;
        let alternatives = vec![
            Alternative { name: "amp", spec: spec.with(Effect::AmplifierDynamics), starts: [base.params; 2] },
            Alternative { name: "ja1986", spec, starts: [other_form; 2] },
        ];
        let c = d.refit_alternatives(spec, alternatives, &files, &[], opts, "for the test").unwrap();
        assert_eq!(c.alternatives.iter().map(|a| a.name).collect::<Vec<_>>(), ["ja1986"]);
        assert_eq!(c.errored.len(), 1, "{:?}", c.errored);
        let words = c.left_out_words();
        assert!(words.contains("could not be refitted") && words.contains("`amp`"), "{words}");
        assert!(words.contains("needs a `command_V` column"), "{words}");
    }
}
