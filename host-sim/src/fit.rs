//! Identification: one parameter set for a model spec from one or more recordings jointly, a
//! displacement offset per file (closed form: the mean residual), cost = mean over files of
//! NRMSE² (plus the current channel's when the model has an amplifier and the file measured the
//! current, the flux density's when a search coil measured it: [`flux_fit`], and the coil
//! temperature's when the model has coil heating and the file logged `temperature_C`:
//! [`temperature_fit`]). With a
//! hysteretic law each file also starts from its own initial magnetic state
//! ([`InitialState`]), a nuisance parameter like the offset. The free parameters and their
//! bounds come from the effect registry
//! ([`crate::params`]); the search is the workbench's optimiser ([`crate::search`]): a particle
//! swarm on part of the data, then Nelder–Mead and Levenberg–Marquardt from the best points.
//! Deterministic for a given seed.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use model_core::effects::{Param, Signature, ROD_THERMAL_LAG, STRAIN_SCALE};
use model_core::{ActuatorParams, Effect, ModelSpec};

use crate::params::multivalued_ja;
use crate::progress::{self, Progress};
use crate::recording::Recording;
use crate::search::{minimize, Bound, Fidelity, Found, Local, Plan, SearchOptions, Start};
use crate::simulation::{
    estimate_excursion, excursion_range, prepare, starting_from, Drive, MagneticMemo, Prepared,
};
use crate::warning::Warning;

mod bad_samples;
mod constraints;
mod cost;
mod doubts;
mod file_scales;
mod free_params;
mod plausible;
mod start;
pub use bad_samples::{spikes, Spike};
pub use constraints::Constraints;
pub use cost::{evaluate, evaluate_projected, residual_blocks, Evaluation, LAMBDA_RANGE};
use cost::{evaluate_projected_in, projected_cost, projected_residuals, FAILED_COST};
pub use doubts::{
    flux_scale_doubts, strain_scale_doubt, unfitted_effects, unfitted_gain, unresolved_mode,
    unsearchable_mode,
};
pub use file_scales::sign_and_scale_doubts;
pub use free_params::{free_params, identifiable, logs_coil_temperature, FreeParam, Given};
use free_params::{given_by, MODE_DAMPING, MODE_FREQUENCY};
pub use plausible::{check_files, check_physics, data_doubts, sign_doubts};
pub use start::StartScore;

/// Fit settings.
#[derive(Debug, Clone, Copy)]
pub struct FitOptions {
    /// Seed of the swarm's random initialisation.
    pub seed: u64,
    /// Show progress on stderr (a bar on a terminal, else a line every few seconds).
    pub progress: bool,
    /// Effort multiplier (1 = default; the swarm iterations, simplex steps and least-squares
    /// Jacobians scale with it).
    pub effort: f64,
    /// Stop searching at this instant and return the best point found so far.
    pub deadline: Option<Instant>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self { seed: 1, progress: false, effort: 1.0, deadline: None }
    }
}

/// Time left before `deadline` (none: unbounded); zero once it has passed, or once the embedding
/// program asked the searches to stop ([`crate::search::request_stop`]).
pub fn time_left(deadline: Option<Instant>) -> Option<Duration> {
    if crate::search::stop_requested() {
        return Some(Duration::ZERO);
    }
    deadline.map(|d| d.saturating_duration_since(Instant::now()))
}

/// What a fit produced.
#[derive(Debug, Clone)]
pub struct FitResult {
    /// The structure fitted.
    pub spec: ModelSpec,
    /// The identified parameter set (fixed parameters as given).
    pub params: ActuatorParams,
    /// Names and values of the identified parameters.
    pub identified: Vec<(&'static str, f64)>,
    /// Scores on the fit files.
    pub fit: Evaluation,
    /// Model evaluations (one evaluation = every fit file simulated once).
    pub evaluations: usize,
    /// The search stopped at the deadline: the best point so far, not a converged fit.
    pub time_limited: bool,
    /// The continuous parameters identified, with the ranges searched: λ_s first (its
    /// closed-form range) unless fixed, then the searched ones in the fit's order.
    pub free: Vec<FreeParam>,
    /// Parameters held fixed by [`Constraints`], with their values.
    pub fixed: Vec<(&'static str, f64)>,
    /// The first start's score (its identified values clamped into the search ranges), and
    /// whether the fit returned it because the search ended worse.
    pub start: StartScore,
    /// The first start's values that lay outside their search ranges (moved to the nearest end).
    pub start_moved: Vec<Warning>,
}

/// The parameters a fit of `spec` on `files` leaves at their start values because no file
/// constrains them ([`free_params::not_fitted`]), for the parameter file to mark.
pub fn not_fitted(spec: ModelSpec, files: &[Recording]) -> Result<Vec<&'static str>> {
    Ok(free_params::not_fitted(spec, given_by(spec, files)?))
}

/// The displacement fit's search: one swarm on the first part of each file, then from the two
/// best of the swarm's result and the start points a 5 % simplex on the first half of long
/// files (the landscape's shape, cheaply) and Levenberg–Marquardt on everything (the cost is a
/// smooth sum of squares near a minimum, where it needs tens of evaluations, not hundreds).
const PLAN: Plan = Plan {
    particles: (8, 3),
    swarm_iters: 12.0,
    swarms: 1,
    simplex_iters_per_dim: 40.0,
    local_searches: 2,
    finalists: 2,
    local: &[Local::Simplex(0.05, Fidelity::Coarse), Local::LeastSquares(Fidelity::Full)],
    tolerance: (1e-6, 1e-18),
};

/// The polish after the search (hysteretic laws): Levenberg–Marquardt on all data, no swarm,
/// from both of its starts (the states estimated anew often polish lower from a higher start cost).
const POLISH: Plan = Plan {
    swarms: 0,
    local_searches: 2,
    finalists: 2,
    local: &[Local::LeastSquares(Fidelity::Full)],
    ..PLAN
};

/// [`refine`]'s search: the polish's, from the start alone (with a hysteretic law, the better of
/// its estimated initial states and the demagnetised one).
const REFINE: Plan = Plan { local_searches: 1, finalists: 1, ..POLISH };

/// The lower-cost of two search results, with the evaluations of both.
fn lower_of<C>(a: Found<C>, b: Found<C>) -> Found<C> {
    let evaluations = a.evaluations + b.evaluations;
    let lower = if b.cost < a.cost { b } else { a };
    Found { evaluations, ..lower }
}

/// Identifies `spec` on `files`, starting from (and keeping the fixed parameters of) `init`.
pub fn fit(
    spec: ModelSpec,
    init: &ActuatorParams,
    files: &[Recording],
    opts: FitOptions,
) -> Result<FitResult> {
    fit_from(spec, &[*init], files, opts)
}

/// As [`fit`], with several start points (the first one's fixed parameters are kept); the swarm
/// and the two best starts seed the local search.
pub fn fit_from(
    spec: ModelSpec,
    starts: &[ActuatorParams],
    files: &[Recording],
    opts: FitOptions,
) -> Result<FitResult> {
    fit_constrained(spec, starts, files, opts, &Constraints::default())
}

/// The local search alone from `start` (no swarm, no simplex: Levenberg–Marquardt, then with a
/// hysteretic law the initial states estimated again and the polish, as in [`fit`]): for a start
/// already near an optimum of a nested structure, e.g. a baseline's with one effect added. With
/// `mech` free and a mode in the data, a second Levenberg–Marquardt run starts from `start` with
/// that mode (as in [`fit`]): a baseline without mechanics has no mode of its own to offer.
pub fn refine(
    spec: ModelSpec,
    start: &ActuatorParams,
    files: &[Recording],
    opts: FitOptions,
) -> Result<FitResult> {
    fit_planned(spec, &[*start], files, opts, &Constraints::default(), &REFINE, false)
}

/// As [`fit_from`], with parameters held fixed (at the first start's values) and search ranges
/// narrowed by `constraints` (`gma fit --fix/--bound`); without constraints the same fit.
pub fn fit_constrained(
    spec: ModelSpec,
    starts: &[ActuatorParams],
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
) -> Result<FitResult> {
    // A reduced-effort search (diagnose's fresh refits) goes without the restarts.
    fit_planned(spec, starts, files, opts, constraints, &PLAN, opts.effort >= 1.0)
}

/// The displacement fit with the search `plan` ([`PLAN`] for `gma fit`), and with
/// `weak_ends` the local searches of [`weak_end_restarts`] after it.
///
/// The rod's thermal lag (searched when a file logs the coil's temperature) nests the model
/// whose rod follows the coil: the fit first holds it at its start value (0, none, unless the
/// parameter file gives one), then frees it in a local search from that optimum (the lag itself
/// from mid-range when it was 0), and keeps the held result when the freed one ends worse, so the
/// larger model never ends in a worse basin than the one it contains (searched together from the
/// start, the complete structure on the independent rig ended at 1.44 % fit NRMSE where the
/// nested one reaches 0.55 %).
fn fit_planned(
    spec: ModelSpec,
    starts: &[ActuatorParams],
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
    plan: &Plan,
    weak_ends: bool,
) -> Result<FitResult> {
    let searched = |constraints: &Constraints| {
        let best = fit_searched(spec, starts, files, opts, constraints, plan)?;
        if weak_ends {
            weak_end_restarts(spec, best, files, opts, constraints)
        } else {
            Ok(best)
        }
    };
    let rod_lag_free = spec.has(Effect::ThermalDrift)
        && logs_coil_temperature(files)
        && !constraints.is_fixed(ROD_THERMAL_LAG.key);
    if !rod_lag_free {
        return searched(constraints);
    }
    let mut held = constraints.clone();
    held.fixed.push(ROD_THERMAL_LAG.key);
    let nested = searched(&held)?;
    let mut freed = fit_searched(spec, &[nested.params], files, opts, constraints, &REFINE)?;
    let evaluations = nested.evaluations + freed.evaluations;
    let time_limited = nested.time_limited || freed.time_limited;
    // The freed search starts the lag inside its range, not at the nested optimum's (a start of
    // 0, no lag, is off the log scale), so it can end above the start values the nested fit
    // kept: then the nested result stands, and a fit never ends worse than its start.
    // Nor above the nested optimum it started from: the larger model contains that one.
    if freed.fit.cost() > nested.fit.cost()
        || nested.start.nrmse.is_some_and(|start| freed.fit.mean_nrmse() > start)
    {
        // Its lag was held by this fit, not by --fix: `fixed` lists the user's alone.
        let fixed = nested.fixed.iter().copied().filter(|(name, _)| constraints.is_fixed(name)).collect();
        return Ok(FitResult { evaluations, time_limited, fixed, ..nested });
    }
    (freed.evaluations, freed.time_limited) = (evaluations, time_limited);
    // The start the user gave, not the nested optimum the local search began from: its score,
    // with `kept` false (this set is not it), and its values moved into their ranges, and the
    // lag's own when it was not the "no lag" 0 the nested fit held.
    freed.start = StartScore { kept: false, ..nested.start };
    let lag_moved = freed.start_moved.into_iter().filter(
        |w| matches!(w, Warning::StartMoved { param, given, .. } if *param == ROD_THERMAL_LAG.key && *given != 0.0),
    );
    freed.start_moved = nested.start_moved.into_iter().chain(lag_moved).collect();
    Ok(freed)
}

/// Local searches from the optimum `best` with one lag at the weak end of its range (the
/// amplifier's, the eddy currents', the sensor delay's, the aftereffect's: its first parameter at
/// its lower bound), one at a time; the lowest cost is kept. Lags in series trade against each
/// other (an eddy lag and a delay describe a rod's field diffusion about equally), and a search
/// that gave the wrong one the phase stays there: on the independent rig the complete structure
/// ended at a 1.00 % fit cost where the same structure started without its eddy lag reaches
/// 0.73 %. The amplifier's lag is left where the current is measured: the current pins it.
fn weak_end_restarts(
    spec: ModelSpec,
    mut best: FitResult,
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
) -> Result<FitResult> {
    let current_measured = files.iter().all(|r| r.current_a.is_some());
    let lags: Vec<&'static Param> = spec
        .effects()
        .filter(|&e| !(e == Effect::AmplifierDynamics && current_measured))
        .filter(|e| matches!(e.info().signature, Signature::Lag | Signature::Creep))
        .filter_map(|e| e.info().params.first())
        .filter(|p| !constraints.is_fixed(p.key))
        .collect();
    if lags.is_empty() {
        return Ok(best);
    }
    let phase = progress::Phase::start(
        opts.progress,
        &format!("fitting {spec}: again from each lag at the weak end of its range"),
        lags.len() as u64,
    );
    let quiet = FitOptions { progress: false, ..opts };
    let center = best.params;
    for lag in lags {
        if time_left(opts.deadline).is_some_and(|t| t.is_zero()) {
            best.time_limited = true;
            break;
        }
        let weak = constraints.narrow(FreeParam::of(lag).bound).lo;
        let mut start = center;
        (lag.set)(&mut start, weak);
        let r = fit_searched(spec, &[start], files, quiet, constraints, &REFINE)?;
        let evaluations = best.evaluations + r.evaluations;
        let time_limited = best.time_limited || r.time_limited;
        let from = best.fit.cost().sqrt();
        // Cost and mean NRMSE can disagree (several files, extra channels): a retry must not
        // end above the start's NRMSE either, and once taken the start set is no longer it.
        let within_start = best.start.nrmse.is_none_or(|start| r.fit.mean_nrmse() <= start);
        if r.fit.cost() < best.fit.cost() && within_start {
            best =
                FitResult { evaluations, time_limited, start: StartScore { kept: false, ..best.start }, ..r };
        } else {
            (best.evaluations, best.time_limited) = (evaluations, time_limited);
        }
        phase.step(&format!(
            "fitting {spec}: {} at {}: {:.3} % → {:.3} % (rms fit cost)",
            lag.key,
            weak,
            from * 100.0,
            best.fit.cost().sqrt() * 100.0
        ));
    }
    phase.finish();
    Ok(best)
}

/// One search of [`fit_planned`].
fn fit_searched(
    spec: ModelSpec,
    starts: &[ActuatorParams],
    files: &[Recording],
    opts: FitOptions,
    constraints: &Constraints,
    plan: &Plan,
) -> Result<FitResult> {
    if files.is_empty() {
        bail!("no files to fit");
    }
    if starts.is_empty() {
        bail!("no start parameters");
    }
    // The whole files, each with a memo of its recent magnetic-stage runs (the least-squares
    // Jacobians' mechanical columns reuse them; the swarm's and simplex's heads move every
    // parameter at once and go without).
    let memos: Vec<MagneticMemo> = files.iter().map(|_| MagneticMemo::default()).collect();
    let full: Vec<Prepared> = prepare(spec, files)?
        .into_iter()
        .zip(&memos)
        .map(|(p, memo)| Prepared { memo: Some(memo), ..p })
        .collect();
    // With a hysteretic law each file's pre-history excursion is a parameter too: held at 0
    // (demagnetised) by the swarm, which then explores the physics alone (searching the states
    // there too made it lose the physics), refined by the local search; estimated anew, per file,
    // wherever a set is scored afterwards.
    let memory = spec.has_magnetic_memory();
    let n_excursions = if memory { files.len() } else { 0 };
    let excursion_bound = excursion_range(spec, &starts[0]);
    let command_driven = full.iter().any(|p| p.drive != Drive::Current);
    // λ_s is solved in closed form at every evaluation (see `evaluate_projected`).
    let c = constraints;
    let lambda_fixed = c.is_fixed(STRAIN_SCALE.key);
    let mut lambda_param = FreeParam::of(&STRAIN_SCALE);
    lambda_param.bound = c.narrow(Bound { lo: LAMBDA_RANGE.0, hi: LAMBDA_RANGE.1, ..lambda_param.bound });
    let lambda_range = (!lambda_fixed).then_some((lambda_param.bound.lo, lambda_param.bound.hi));
    let free: Vec<FreeParam> = free_params(spec, Given::by(files, command_driven))
        .into_iter()
        .filter(|f| f.name() != STRAIN_SCALE.key && !c.is_fixed(f.name()))
        .map(|f| FreeParam { bound: c.narrow(f.bound), ..f })
        .collect();
    let d = free.len();
    let dims = d + n_excursions;
    check_determined(spec, files, (d, dims), lambda_range.is_some(), memory)?;
    // A lightly damped mechanical mode is a narrow valley the swarm can miss: each start also
    // with the mode the data's frequency response shows, where it shows one (see `resonance`),
    // the best of them refined by a local search of its own.
    let seen_mode = free
        .iter()
        .any(|f| f.name() == MODE_FREQUENCY || f.name() == MODE_DAMPING)
        .then(|| crate::resonance::seen_mode(files))
        .flatten();
    let planned = planned_evaluations(plan, opts.effort, (d, dims), seen_mode.is_some(), memory);
    let bar = Progress::new(&format!("fitting {spec}"), planned, opts.progress);
    let evals = AtomicUsize::new(0);

    // The swarm needs only the landscape's shape: the first part of each file (at least 4000
    // samples or a quarter); the coarse simplex the first half of long files (at least 8000).
    let heads: Vec<Recording> = files.iter().map(|r| r.head(4000.max(r.len() / 4))).collect();
    let halves: Vec<Recording> = files.iter().map(|r| r.head(8000.max(r.len() / 2))).collect();
    let swarm_data: Vec<Prepared> = full.iter().zip(&heads).map(|(p, h)| p.head_of(h)).collect();
    let coarse_data: Vec<Prepared> = full.iter().zip(&halves).map(|(p, h)| p.head_of(h)).collect();
    let data = |fidelity| match fidelity {
        Fidelity::Swarm => &swarm_data[..],
        Fidelity::Coarse => &coarse_data[..],
        Fidelity::Full => &full[..],
    };
    let with_values = |base: &ActuatorParams, values: &[f64]| {
        let mut p = *base;
        for (f, &v) in free.iter().zip(values) {
            (f.set)(&mut p, v);
        }
        p
    };
    // A point with α·M_s/(3a) ≥ 1 is refused like one the model cannot run.
    let cost = |base: &ActuatorParams, values: &[f64], fidelity: Fidelity| {
        let p = with_values(base, values);
        if multivalued_ja(spec, &p).is_some() {
            return FAILED_COST;
        }
        projected_cost(spec, &p, &starting_from(data(fidelity), &values[d..]), lambda_range)
    };
    let residuals = |base: &ActuatorParams, values: &[f64], fidelity: Fidelity| {
        let p = with_values(base, values);
        if multivalued_ja(spec, &p).is_some() {
            return None;
        }
        projected_residuals(spec, &p, &starting_from(data(fidelity), &values[d..]), lambda_range)
    };
    let starts = with_seen_mode(starts, &free, seen_mode.as_ref());
    let start_moved = starts_moved(&free, &starts[0].0);
    let bases = start_points(spec, &starts, &free, &full, memory.then_some(excursion_bound))?;
    let bounds: Vec<Bound> = free
        .iter()
        .map(|f| f.bound)
        .chain((0..n_excursions).map(|_| Bound {
            swarm_holds: Some(0.0),
            ..Bound::lin("initial excursion", -excursion_bound, excursion_bound)
        }))
        .collect();
    let opts_search = SearchOptions { seed: opts.seed, effort: opts.effort, deadline: opts.deadline };
    let mut found =
        minimize(&bounds, &cost, Some(&residuals), &bases[0].context, &bases, plan, opts_search, &bar)?;
    if memory && !found.time_limited {
        // The states estimated again at the point found, and one more least-squares run from there.
        let at = with_values(&found.context, &found.best);
        let mut values = found.best[..d].to_vec();
        for prep in &full {
            values.push(estimate_excursion(spec, &at, prep)?);
        }
        let again = [Start::new(found.best.clone(), found.context), Start::new(values, found.context)];
        let polished =
            minimize(&bounds, &cost, Some(&residuals), &found.context, &again, &POLISH, opts_search, &bar)?;
        found = lower_of(found, polished);
    }
    let mut params = with_values(&found.context, &found.best);
    let found_start = starting_from(&full, &found.best[d..]);
    bar.finish_and_clear();
    params = with_lambda(spec, params, &found_start, lambda_range)?;
    // The first start, as the search began from it: scored on all files (NRMSE as reported).
    let (start_score, kept) = score_start(spec, bases[0].context, (&full, files), lambda_range, &mut params);
    let (fit, lambda) = checked_result(spec, &params, files)?;
    let mut identified: Vec<(&'static str, f64)> =
        if lambda_fixed { Vec::new() } else { vec![(STRAIN_SCALE.key, lambda)] };
    identified.extend(free.iter().map(|f| (f.name(), (f.get)(&params))));
    let fixed = identifiable(spec, files)?
        .into_iter()
        .filter(|f| c.is_fixed(f.name()))
        .map(|f| (f.name(), (f.get)(&params)))
        .collect();
    let free = (!lambda_fixed).then_some(lambda_param).into_iter().chain(free).collect();
    Ok(FitResult {
        spec,
        params,
        identified,
        fit,
        evaluations: evals.load(Ordering::Relaxed) + found.evaluations,
        time_limited: found.time_limited,
        free,
        fixed,
        start: match start_score {
            Ok((e, _)) => {
                StartScore { nrmse: Some(e).filter(|e| e.is_finite()), kept, refused: None, seen_mode }
            }
            Err(why) => StartScore { nrmse: None, kept: false, refused: Some(why), seen_mode },
        },
        start_moved,
    })
}

/// Refuses a fit through no more samples than unknowns, which any model passes: the "fit" would
/// report values and a tiny error that the data do not determine. The unknowns: `d` free
/// parameters and `dims` searched dimensions in all, λ_s when `lambda`, each file's offset.
fn check_determined(
    spec: ModelSpec,
    files: &[Recording],
    (d, dims): (usize, usize),
    lambda: bool,
    memory: bool,
) -> Result<()> {
    let samples: usize = files.iter().map(|r| r.len()).sum();
    let unknowns = dims + usize::from(lambda) + files.len();
    if samples <= unknowns {
        bail!(
            "{samples} samples in all ({}) for {unknowns} unknowns of `{spec}` ({d} free parameters{}, {} per file): \
             a fit through no more samples than unknowns is not determined by them; record more samples (thousands: \
             a drive cycle at the rig's rate), raise --max-samples or drop --trim-start if they cut the files, or \
             hold parameters with --fix",
            files.iter().map(|r| format!("{}: {}", r.name, r.len())).collect::<Vec<_>>().join(", "),
            if lambda { ", λ_s" } else { "" },
            if memory { "an initial magnetic state and an offset" } else { "an offset" },
        );
    }
    Ok(())
}

/// The progress bar's length: the swarm, then per seed the plan's simplex and least-squares runs
/// (and one more least-squares run each in the polish, with `memory`), for `d` free parameters
/// and `dims` searched dimensions.
fn planned_evaluations(
    plan: &Plan,
    effort: f64,
    (d, dims): (usize, usize),
    seen_mode: bool,
    memory: bool,
) -> u64 {
    let swarm_iters = ((plan.swarm_iters * effort).round() as u64).max(2);
    let nm_iters = ((plan.simplex_iters_per_dim * dims as f64 * effort).round() as u64).max(20);
    let least_squares = crate::search::least_squares_evaluations(dims, effort);
    let per_seed: u64 = plan
        .local
        .iter()
        .map(|run| match run {
            Local::Simplex(..) => nm_iters,
            Local::LeastSquares(_) => least_squares,
        })
        .sum();
    let seeds = plan.local_searches as u64 + u64::from(seen_mode);
    plan.swarms as u64 * (plan.particles.0 + plan.particles.1 * d) as u64 * (swarm_iters + 1)
        + seeds * per_seed
        + if memory { POLISH.local_searches as u64 * least_squares } else { 0 }
}

/// Each start as given, and (always refined) also at the mechanical mode the data show.
fn with_seen_mode(
    starts: &[ActuatorParams],
    free: &[FreeParam],
    seen_mode: Option<&crate::resonance::SeenMode>,
) -> Vec<(ActuatorParams, bool)> {
    match seen_mode {
        Some(mode) => {
            let at_mode = starts.iter().map(|st| {
                let mut p = *st;
                for f in free {
                    match f.name() {
                        MODE_FREQUENCY => (f.set)(&mut p, mode.natural_frequency_hz),
                        MODE_DAMPING => (f.set)(&mut p, mode.damping_ratio),
                        _ => {}
                    }
                }
                (p, true)
            });
            starts.iter().map(|&st| (st, false)).chain(at_mode).collect()
        }
        None => starts.iter().map(|&st| (st, false)).collect(),
    }
}

/// The user's start values outside the ranges, said rather than clamped in silence.
fn starts_moved(free: &[FreeParam], start: &ActuatorParams) -> Vec<Warning> {
    free.iter()
        .filter_map(|f| {
            let given = (f.get)(start);
            let used = f.from_unit(f.to_unit(given));
            ((given - used).abs() > 1e-6 * given.abs().max(f64::MIN_POSITIVE)).then_some(
                Warning::StartMoved { param: f.name(), given, used, lo: f.bound.lo, hi: f.bound.hi },
            )
        })
        .collect()
}

/// Each start also as the model's own rest state (every file demagnetised): an estimate made at
/// poor start values can be further from the truth than that.
fn with_rest_states(
    bases: Vec<Start<ActuatorParams>>,
    d: usize,
    n_excursions: usize,
) -> Vec<Start<ActuatorParams>> {
    let rest = bases.iter().map(|b| Start {
        values: b.values[..d].iter().copied().chain(std::iter::repeat_n(0.0, n_excursions)).collect(),
        context: b.context,
        always_refined: b.always_refined,
        simplex_holds: b.simplex_holds.clone(),
    });
    bases.iter().cloned().chain(rest).collect()
}

/// The search's start points: the fixed parameters come from the first start; each start's
/// identified values are clamped into the bounds, and with a hysteretic law (`excursion_bound`)
/// each file's initial state is estimated there, and each start is also tried at the rest state.
fn start_points(
    spec: ModelSpec,
    starts: &[(ActuatorParams, bool)],
    free: &[FreeParam],
    full: &[Prepared],
    excursion_bound: Option<f64>,
) -> Result<Vec<Start<ActuatorParams>>> {
    let mode_indices: Vec<usize> = free
        .iter()
        .enumerate()
        .filter(|(_, f)| f.name() == MODE_FREQUENCY || f.name() == MODE_DAMPING)
        .map(|(k, _)| k)
        .collect();
    // Start points: the fixed parameters come from the first; each start's identified values
    // are clamped into the bounds.
    let bases: Vec<Start<ActuatorParams>> = starts
        .iter()
        .map(|&(st, always_refined)| {
            let mut b = starts[0].0;
            for f in free {
                (f.set)(&mut b, f.from_unit(f.to_unit((f.get)(&st))));
            }
            let excursions: Vec<f64> = if let Some(excursion_bound) = excursion_bound {
                full.iter()
                    .map(|prep| {
                        Ok(estimate_excursion(spec, &b, prep)?.clamp(-excursion_bound, excursion_bound))
                    })
                    .collect::<Result<_>>()?
            } else {
                Vec::new()
            };
            let values = free.iter().map(|f| (f.get)(&b)).chain(excursions).collect();
            // At the seen mode the simplex leaves the mode where the data put it.
            let simplex_holds = if always_refined { mode_indices.clone() } else { Vec::new() };
            Ok(Start { values, context: b, always_refined, simplex_holds })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(match excursion_bound {
        Some(_) => with_rest_states(bases, free.len(), full.len()),
        None => bases,
    })
}

/// `p` with λ_s solved in closed form on `data` (within `lambda_range`; as given when held).
fn with_lambda(
    spec: ModelSpec,
    mut p: ActuatorParams,
    data: &[Prepared],
    lambda_range: Option<(f64, f64)>,
) -> Result<ActuatorParams> {
    let lambda = match lambda_range {
        Some(range) => evaluate_projected_in(spec, &p, data, range)?.1,
        None => p.magnetostriction.lambda_s as f64,
    };
    p.magnetostriction.lambda_s = lambda as f32;
    Ok(p)
}

/// The first start scored on all files (or why it cannot be used), and whether the fit keeps it:
/// `params`, the search's result, is replaced by it when the search ended worse.
fn score_start(
    spec: ModelSpec,
    start_params: ActuatorParams,
    (full, files): (&[Prepared], &[Recording]),
    lambda_range: Option<(f64, f64)>,
    params: &mut ActuatorParams,
) -> (std::result::Result<(f64, ActuatorParams), String>, bool) {
    let start_score = match multivalued_ja(spec, &start_params) {
        Some(why) => Err(why),
        None => with_lambda(spec, start_params, full, lambda_range)
            .and_then(|p| Ok((evaluate(spec, &p, files)?.mean_nrmse(), p)))
            .map_err(|e| format!("the model cannot be run there: {e}")),
    };
    let mut kept = false;
    if let Ok((start_nrmse, start_set)) = &start_score {
        let found_nrmse = evaluate(spec, params, files).map(|e| e.mean_nrmse()).unwrap_or(f64::NAN);
        if start_nrmse.is_finite() && (found_nrmse.is_nan() || found_nrmse > *start_nrmse) {
            kept = true;
            *params = *start_set;
        }
    }
    (start_score, kept)
}

/// The fit's result scored on all files, and its λ_s; never NaN or an invalid set: the fit is
/// said to have failed instead.
fn checked_result(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Recording],
) -> Result<(Evaluation, f64)> {
    if let Some(why) = multivalued_ja(spec, params) {
        bail!("the fit is refused: {why}; --fix or --bound `ja.alpha`/`ja.a_a_per_m` so that α·M_s/(3a) < 1");
    }
    let lambda = params.magnetostriction.lambda_s as f64;
    // Never hand back NaN or an invalid set: say the fit failed instead.
    model_core::Actuator::new(spec, params).map_err(|e| {
        anyhow::anyhow!(
            "the fit ended on an invalid parameter set ({e}; λ_s = {lambda:e}): the model cannot follow \
             these recordings (check the drive and displacement columns and their units)"
        )
    })?;
    let fit = evaluate(spec, params, files)?;
    if !fit.mean_nrmse().is_finite() {
        bail!("the fit found no parameter set whose simulation stays finite on these recordings");
    }
    Ok((fit, lambda))
}

#[cfg(test)]
mod tests;
