//! Other forms of the diagnosed structure, refitted and set beside it: the other forms of
//! Jiles–Atherton (`--ja-variants`) and the other hysteresis law (`--laws`: J–A ↔ Preisach).
//! Neither is a missing effect — the structure keeps its effects, only its magnetization law
//! changes form or kind — so neither is a verdict; each gives a finding and a JSON table.
//!
//! Each alternative is fitted from the baseline's values (the dynamics it found carry over) and
//! from the engineer's start values, the better kept, and scored like the candidates (validation
//! files, else fit files, after each burn-in). It is named as fitting better by the candidates'
//! rule: cut ≥ [`MIN_CUT`]×, lower on [`required_wins`] of the scored files, and — for the laws,
//! whose parameter counts differ — a positive ΔBIC with the effective sample size.

use anyhow::{bail, Result};
use model_core::magnetization::JaVariant;
use model_core::{ActuatorParams, Effect, MagnetizationLaw, ModelSpec};
use rayon::prelude::*;
use serde::Serialize;

use super::{
    burn_in, displacement_scores, effective_samples, estimated_states, information_gain, mean, required_wins,
    Diagnosis, Scored, MIN_CUT,
};
use crate::fit::{self, FitOptions};
use crate::progress;
use crate::recording::Recording;

/// One J–A form's score in [`Diagnosis::compare_ja_variants`].
#[derive(Debug, Clone, Serialize)]
pub struct VariantScore {
    /// Its name, as `[ja] variant` takes it.
    pub variant: &'static str,
    /// The form the parameter file gave (its score is the baseline's).
    pub given: bool,
    /// Mean displacement NRMSE on the scored files (validation, else fit), after each burn-in.
    pub nrmse: f64,
    /// Scored files on which it is lower than the given form.
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
    /// Mean displacement NRMSE on the scored files (validation, else fit), after each burn-in.
    pub nrmse: f64,
    /// Scored files on which it is lower than the given law.
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
    /// "validation files" or "fit files".
    on: &'static str,
    alternatives: Vec<Compared>,
    /// Alternatives not refitted: `--time-limit` (or Ctrl-C) came first. Their start values
    /// are no fit, so they are left out, as candidates are.
    not_refitted: Vec<&'static str>,
}

impl Comparison {
    /// The alternatives left out, in words ("" when none).
    fn not_refitted_words(&self) -> String {
        if self.not_refitted.is_empty() {
            return String::new();
        }
        format!("; not refitted (--time-limit reached first), left out: `{}`", self.not_refitted.join("`, `"))
    }

    /// The lowest alternative that passes the rule (ΔBIC > 0 too when `bic`).
    fn better(&self, bic: bool) -> Option<&Compared> {
        self.alternatives
            .iter()
            .filter(|a| {
                self.given_nrmse >= MIN_CUT * a.nrmse
                    && a.files_improved >= required_wins(a.files_scored)
                    && (!bic || a.delta_bic > 0.0)
            })
            .min_by(|a, b| a.nrmse.total_cmp(&b.nrmse))
    }
}

impl Diagnosis {
    /// Refits each alternative (in parallel) and scores it beside the baseline.
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
        let before = displacement_scores(spec, &base.params, score_files, &skip)?;
        let n_eff_files: Vec<f64> = before.iter().map(|s| effective_samples(&s.residual)).collect();
        let n_eff: f64 = n_eff_files.iter().sum();
        let base_free = (base.free.len() + estimated_states(spec, score_files.len())) as f64;
        let phase = progress::Phase::start(
            opts.progress,
            &format!("diagnose: refitting `{spec}` {what}"),
            alternatives.len() as u64,
        );
        type Refit = (Vec<Scored>, bool, usize);
        let refits: Vec<(Alternative, Option<Result<Refit>>)> = alternatives
            .into_par_iter()
            .map(|a| {
                // Past the deadline an alternative is not refitted at all (and said so).
                if fit::time_left(opts.deadline).is_some_and(|t| t.is_zero()) {
                    return (a, None);
                }
                let refit =
                    fit::fit_from(a.spec, &a.starts, fit_files, FitOptions { progress: false, ..opts });
                let scored = refit.and_then(|f| {
                    Ok((
                        displacement_scores(a.spec, &f.params, score_files, &skip)?,
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
        for (a, scored) in refits {
            let Some(scored) = scored else {
                self.time_limited = true;
                not_refitted.push(a.name);
                continue;
            };
            let (after, time_limited, free) = scored?;
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
            on: if val_files.is_empty() { "fit files" } else { "validation files" },
            alternatives: compared,
            not_refitted,
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
        let mut rows = vec![VariantScore {
            variant: given.name(),
            given: true,
            nrmse: c.given_nrmse,
            files_improved: 0,
            files_scored: c.files_scored,
            fits_better: false,
        }];
        rows.extend(c.alternatives.iter().map(|a| VariantScore {
            variant: a.name,
            given: false,
            nrmse: a.nrmse,
            files_improved: a.files_improved,
            files_scored: a.files_scored,
            fits_better: Some(a.name) == better,
        }));
        let on = c.on;
        let listed =
            rows.iter().map(|r| format!("`{}` {:.2} %", r.variant, r.nrmse * 100.0)).collect::<Vec<_>>();
        let not_refitted = c.not_refitted_words();
        self.findings.push(match rows.iter().find(|r| r.fits_better) {
            Some(b) => format!(
                "J–A form: `{}` fits better than the given `{}` ({:.2} % against {:.2} % on the {on}, {:.2}× lower, on {} of {}; \
                 all forms: {}{not_refitted}): set `[ja] variant = \"{}\"`",
                b.variant,
                rows[0].variant,
                b.nrmse * 100.0,
                rows[0].nrmse * 100.0,
                rows[0].nrmse / b.nrmse,
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
                "J–A form: no form fits clearly better than the given `{}` (cut ≥ {MIN_CUT}× on {} of the {on}): \
                 {}{not_refitted}",
                rows[0].variant,
                required_wins(rows[0].files_scored),
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
        let on = c.on;
        let given_row = LawScore {
            law: given,
            model: spec.to_string(),
            given: true,
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
                c.not_refitted_words()
            ));
            self.laws = Some(vec![given_row]);
            return Ok(());
        };
        self.findings.push(if better {
            format!(
                "hysteresis law: `{other}` fits better than the given `{given}` ({:.2} % against {:.2} % on the {on}, \
                 {:.2}× lower, on {} of {}, ΔBIC {:+.1}): try `--model {}`",
                a.nrmse * 100.0,
                c.given_nrmse * 100.0,
                c.given_nrmse / a.nrmse,
                a.files_improved,
                a.files_scored,
                a.delta_bic,
                a.spec
            )
        } else {
            format!(
                "hysteresis law: `{other}` does not fit clearly better than the given `{given}` (cut ≥ {MIN_CUT}× on {} \
                 of the {on} and ΔBIC > 0): `{given}` {:.2} %, `{other}` {:.2} % (lower on {} of {}, ΔBIC {:+.1})",
                required_wins(c.files_scored),
                c.given_nrmse * 100.0,
                a.nrmse * 100.0,
                a.files_improved,
                a.files_scored,
                a.delta_bic
            )
        });
        self.laws = Some(vec![
            given_row,
            LawScore {
                law: other,
                model: a.spec.to_string(),
                given: false,
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
