//! The searches of a diagnosis: the given structure's fit (the baseline) and, per candidate
//! effect, a fresh fit from the engineer's start values and a refinement from the baseline.

use std::sync::Mutex;

use anyhow::Result;
use model_core::{ActuatorParams, Effect, ModelSpec};
use rayon::prelude::*;

use super::FRESH_EFFORT;
use crate::fit::{self, FitOptions, FitResult};
use crate::progress;
use crate::recording::Recording;

/// One candidate's search: `None` when the time limit left it out.
pub(super) type Search = Option<Result<FitResult>>;

/// The baseline and, per candidate (in the order given), its two searches.
pub(super) struct Searches {
    pub base: FitResult,
    /// Refined from the baseline's optimum with the effect's parameters at their start values.
    pub refined: Vec<Search>,
    /// Fitted afresh from the engineer's start values.
    pub fresh: Vec<Search>,
}

/// Each candidate is fitted afresh from the engineer's start values (swarm and all, at
/// [`FRESH_EFFORT`]), and refined from the baseline's optimum with the effect's parameters at
/// their start values: the lower fit cost is its refit ([`keep_the_better`]). Either alone can
/// lose: a baseline that bent its lags to mimic a missing delay starts that refit in a basin of
/// its own, and a fresh search can miss the basin the baseline found. The fresh fits need nothing
/// from the baseline and run beside it and the refinements, on the cores their serial stretches
/// (one seed's simplex) leave idle; each fit's result is the same whichever finishes first. With a
/// time limit the baseline has the cores to itself first: a limit that ends it leaves no refit,
/// and the baseline is then the result.
pub(super) fn search(
    spec: ModelSpec,
    init: &ActuatorParams,
    fit_files: &[Recording],
    cands: &[Effect],
    opts: FitOptions,
) -> Result<Searches> {
    let refit_opts = FitOptions { progress: false, ..opts };
    let fresh_opts = FitOptions { effort: FRESH_EFFORT * refit_opts.effort, ..refit_opts };
    let fresh_beside_baseline = opts.deadline.is_none();
    // Past the deadline a candidate is not refitted at all (and said so).
    let late = || fit::time_left(opts.deadline).is_some_and(|t| t.is_zero());
    progress::phase(
        opts.progress,
        &if fresh_beside_baseline {
            format!(
                "diagnose: fitting the given model `{spec}`; beside it, `{spec}` plus each of {} candidate effects \
                 from the start values",
                cands.len()
            )
        } else {
            format!("diagnose: fitting the given model `{spec}`")
        },
    );
    // The candidates' searches finished (fresh and refined), and the phase that counts them from
    // the baseline's end (before it, the baseline's own progress is shown).
    let searches: Mutex<(u64, Option<progress::Phase>)> = Mutex::new((0, None));
    let searches_lock = || searches.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    let searched = |r: Search| {
        let mut g = searches_lock();
        g.0 += 1;
        if let Some(phase) = &g.1 {
            phase.step("");
        }
        r
    };
    let fresh_searches = || -> Vec<Search> {
        cands
            .par_iter()
            .map(|&e| searched((!late()).then(|| fit::fit(spec.with(e), init, fit_files, fresh_opts))))
            .collect()
    };
    let (base_and_refined, fresh_beside) = rayon::join(
        || -> Result<(FitResult, Vec<Search>, Vec<Search>)> {
            let base = fit::fit(spec, init, fit_files, opts)?;
            {
                let mut g = searches_lock();
                let label = format!(
                    "diagnose: `{spec}` plus each candidate effect, searched afresh and refined from the fit of \
                     `{spec}`"
                );
                let phase = progress::Phase::start(opts.progress, &label, 2 * cands.len() as u64);
                (0..g.0).for_each(|_| phase.step(""));
                g.1 = Some(phase);
            }
            let refine = |&e: &Effect| {
                searched((!late()).then(|| fit::refine(spec.with(e), &base.params, fit_files, refit_opts)))
            };
            let (refined, fresh_after) = rayon::join(
                || cands.par_iter().map(refine).collect(),
                || if fresh_beside_baseline { Vec::new() } else { fresh_searches() },
            );
            Ok((base, refined, fresh_after))
        },
        || if fresh_beside_baseline { fresh_searches() } else { Vec::new() },
    );
    if let Some(phase) = searches_lock().1.take() {
        phase.finish();
    }
    let (base, refined, fresh_after) = base_and_refined?;
    let fresh = if fresh_beside_baseline { fresh_beside } else { fresh_after };
    Ok(Searches { base, refined, fresh })
}

/// A candidate's refit: of its two searches the lower fit cost (the fresh one on a tie),
/// reporting the search as a whole (both runs' evaluations, and a time limit that cut either
/// short); the fresh search's error first where both failed.
pub(super) fn keep_the_better(fresh: Result<FitResult>, refined: Result<FitResult>) -> Result<FitResult> {
    let (fresh, refined) = (fresh?, refined?);
    let (evaluations, time_limited) =
        (refined.evaluations + fresh.evaluations, refined.time_limited || fresh.time_limited);
    let kept = if refined.fit.cost() < fresh.fit.cost() { refined } else { fresh };
    Ok(FitResult { evaluations, time_limited, ..kept })
}
