//! The workbench's one optimiser: bounded global-then-local minimisation for small parameter
//! vectors. A particle swarm (argmin; particles evaluated in parallel with rayon) over the unit
//! cube of the bounds (log scale where a parameter spans decades), then local runs from the best
//! points found: Nelder–Mead (argmin), which needs only the cost, and Levenberg–Marquardt
//! (nalgebra; finite-difference Jacobians with Broyden updates), which needs the residuals and
//! converges far faster where the cost is a smooth sum of squares. Deterministic for a seed.
//!
//! Hooks for the displacement fit: the cost can be evaluated on cheaper data subsets
//! ([`Fidelity`]: the swarm and the coarse simplex need only the landscape's shape), the search
//! can start from given points that carry a context (the parameters held fixed).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Result;
use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand::SeedableRng;
use rayon::prelude::*;

use crate::progress::Progress;

/// One parameter's search range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    /// Name for reports.
    pub name: &'static str,
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// Searched in log scale.
    pub log: bool,
    /// A nuisance the swarm holds at this value (the simplex refines it with the rest): the
    /// global search then explores the physics alone.
    pub swarm_holds: Option<f64>,
}

impl Bound {
    /// A linear range.
    pub fn lin(name: &'static str, lo: f64, hi: f64) -> Self {
        Self { name, lo, hi, log: false, swarm_holds: None }
    }

    /// A logarithmic range (positive bounds).
    pub fn log(name: &'static str, lo: f64, hi: f64) -> Self {
        Self { name, lo, hi, log: true, swarm_holds: None }
    }

    /// Position of `v` in the range, 0 at `lo` and 1 at `hi` (unclamped; NaN when the scale
    /// cannot map it).
    fn unit_raw(&self, v: f64) -> f64 {
        if self.log {
            (v.ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }

    /// Value → [0, 1] (clamped; 0.5 for a value the scale cannot map).
    pub fn to_unit(&self, v: f64) -> f64 {
        let u = self.unit_raw(v);
        if u.is_finite() {
            u.clamp(0.0, 1.0)
        } else {
            0.5
        }
    }

    /// [0, 1] → value (clamped).
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        if self.log {
            (self.lo.ln() + u * (self.hi.ln() - self.lo.ln())).exp()
        } else {
            self.lo + u * (self.hi - self.lo)
        }
    }

    /// Whether `v` sits within 0.5 % of the range's ends.
    pub fn at_edge(&self, v: f64) -> bool {
        !(0.005..=0.995).contains(&self.unit_raw(v))
    }
}

/// Search settings a user chooses.
#[derive(Debug, Clone, Copy)]
pub struct SearchOptions {
    /// Seed of the swarm.
    pub seed: u64,
    /// Effort multiplier (1 = default): swarm iterations and simplex steps scale with it.
    pub effort: f64,
    /// Stop at this instant with the best point so far.
    pub deadline: Option<Instant>,
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self { seed: 1, effort: 1.0, deadline: None }
    }
}

/// Which data the cost is evaluated on: the swarm and the coarse simplex need only the
/// landscape's shape, so a caller may give them a subset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fidelity {
    /// The particle swarm.
    Swarm,
    /// The first, coarse simplex.
    Coarse,
    /// The final simplex and the choice of the best point: all data.
    Full,
}

/// A search's constants.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Particles: `base + per_dimension · d`.
    pub particles: (usize, usize),
    /// Swarm iterations at effort 1.
    pub swarm_iters: f64,
    /// Independent swarms (seeds `seed`, `seed + 1`, …), run in parallel.
    pub swarms: usize,
    /// Simplex iterations per dimension at effort 1.
    pub simplex_iters_per_dim: f64,
    /// The best this many of starts and swarm results are refined, in parallel.
    pub local_searches: usize,
    /// Of those, the best this many (by cost on all data after the earlier runs) go on to the
    /// last simplex run: the most expensive run is spent only where it can win.
    pub finalists: usize,
    /// The local runs, in order, from each seed.
    pub local: &'static [Local],
    /// Converged when the simplex's costs agree to this fraction of the cost (and the floor).
    pub tolerance: (f64, f64),
}

/// One local run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Local {
    /// Nelder–Mead from a simplex of this initial step (unit-cube fraction).
    Simplex(f64, Fidelity),
    /// Levenberg–Marquardt on the residuals (needs [`Residuals`]): where the cost is a smooth sum
    /// of squares it converges in tens of evaluations where the simplex needs hundreds.
    LeastSquares(Fidelity),
}

/// A start point and the context its cost is evaluated in.
#[derive(Debug, Clone)]
pub struct Start<C> {
    /// Values (in the parameters' units).
    pub values: Vec<f64>,
    /// What the cost needs besides the values (the parameters held fixed).
    pub context: C,
    /// Refined by a local search of its own, beside the plan's best other starts and swarm
    /// results, whatever its cost ranks (the best such start only): a start the caller trusts
    /// more than its first cost says, e.g. a narrow mode read off the data beside parameters
    /// not yet fitted, whose shoulder costs more than a broad basin elsewhere.
    pub always_refined: bool,
    /// Coordinates the simplex runs from this start leave where they are: a narrow valley's, e.g.
    /// a lightly damped mode read off the data, which the simplex's first steps (a twentieth of
    /// the unit cube: ×1.35 in a log-scaled frequency) would leave; least squares move them.
    pub simplex_holds: Vec<usize>,
}

impl<C> Start<C> {
    /// A start that competes for the local search by its cost.
    pub fn new(values: Vec<f64>, context: C) -> Self {
        Self { values, context, always_refined: false, simplex_holds: Vec::new() }
    }
}

/// A point a local search runs from: its context, unit-cube coordinates, cost on all data, and
/// the coordinates its simplex runs hold ([`Start::simplex_holds`]).
#[derive(Clone)]
struct Seed<C> {
    context: C,
    unit: Vec<f64>,
    cost: f64,
    simplex_holds: Vec<usize>,
}

/// What a search found.
#[derive(Debug, Clone)]
pub struct Found<C> {
    /// The best values.
    pub best: Vec<f64>,
    /// The context they belong to.
    pub context: C,
    /// Their cost on all data.
    pub cost: f64,
    /// Cost evaluations.
    pub evaluations: usize,
    /// Stopped by the deadline.
    pub time_limited: bool,
}

/// The cost of `values` in `context` on the data of a [`Fidelity`]; it must return a finite
/// number (callers map failures to a large one).
pub type Cost<'a, C> = dyn Fn(&C, &[f64], Fidelity) -> f64 + Sync + 'a;

/// The residuals whose sum of squares is the [`Cost`] (`None` where the model cannot be run).
pub type Residuals<'a, C> = dyn Fn(&C, &[f64], Fidelity) -> Option<Vec<f64>> + Sync + 'a;

/// The problem in the unit cube, for argmin.
struct Unit<'a, C> {
    bounds: &'a [Bound],
    cost: &'a Cost<'a, C>,
    context: &'a C,
    fidelity: Fidelity,
    evals: &'a AtomicUsize,
    progress: &'a Progress,
}

impl<C> Unit<'_, C> {
    fn values(&self, u: &[f64]) -> Vec<f64> {
        self.bounds.iter().zip(u).map(|(b, &x)| b.from_unit(x)).collect()
    }

    /// The cost at the clamped point, plus a pull back inside the cube.
    fn eval(&self, u: &[f64]) -> f64 {
        if stop_requested() {
            // The solvers run out their iterations at no cost; the result is discarded.
            return f64::MAX;
        }
        self.evals.fetch_add(1, Ordering::Relaxed);
        self.progress.inc(1);
        let outside: f64 = u.iter().map(|x| (x - x.clamp(0.0, 1.0)).powi(2)).sum();
        (self.cost)(self.context, &self.values(u), self.fidelity) + outside
    }
}

/// The swarm's view of a [`Unit`]: the dimensions it searches, the held ones appended.
struct SwarmUnit<'a, C> {
    unit: Unit<'a, C>,
    /// Unit-cube values of the held dimensions, in their order after the searched ones.
    held: Vec<f64>,
}

impl<C: Sync> CostFunction for SwarmUnit<'_, C> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.unit.eval(&[&u[..], &self.held[..]].concat()))
    }
}

impl<C: Sync> CostFunction for Unit<'_, C> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.eval(u))
    }
}

/// `ex` bounded by the deadline.
pub fn bounded<O, S: argmin::core::Solver<O, I>, I: State>(
    ex: Executor<O, S, I>,
    deadline: Option<Instant>,
) -> Executor<O, S, I> {
    match deadline {
        Some(d) => ex.timeout(d.saturating_duration_since(Instant::now())),
        None => ex,
    }
}

fn passed(deadline: Option<Instant>) -> bool {
    stop_requested() || deadline.is_some_and(|d| Instant::now() >= d)
}

/// Set by a program that embeds the workbench (the Python package, on Ctrl-C) to end every
/// running search at its next evaluation, as a reached deadline does; the caller then discards
/// what the searches return. Process-wide, as the interrupt is.
static STOP: AtomicBool = AtomicBool::new(false);

/// How many stops were requested: a call that saw this change while it ran was cut short,
/// whoever asked.
static STOPS: AtomicUsize = AtomicUsize::new(0);

/// Asks every running search to stop (`true`), or lets searches run again (`false`).
pub fn request_stop(stop: bool) {
    if stop {
        STOPS.fetch_add(1, Ordering::Relaxed);
    }
    STOP.store(stop, Ordering::Relaxed);
}

/// How many stops have been requested so far.
pub fn stops_requested() -> usize {
    STOPS.load(Ordering::Relaxed)
}

/// Whether [`request_stop`] asked the searches to stop.
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Minimises `cost` over `bounds`: `plan.swarms` swarms (in `swarm_context`) and the `starts`
/// give candidates, the best `plan.local_searches` of them (by cost on all data) are refined by
/// the plan's local runs in parallel, and the best result is returned. `residuals` serve the
/// plan's [`Local::LeastSquares`] runs.
#[allow(clippy::too_many_arguments)]
pub fn minimize<C: Clone + Send + Sync>(
    bounds: &[Bound],
    cost: &Cost<'_, C>,
    residuals: Option<&Residuals<'_, C>>,
    swarm_context: &C,
    starts: &[Start<C>],
    plan: &Plan,
    opts: SearchOptions,
    progress: &Progress,
) -> Result<Found<C>> {
    let d = bounds.len();
    let evals = AtomicUsize::new(0);
    let timed_out = AtomicBool::new(false);
    // A macro, not a closure: each use borrows its context for as long as it needs.
    macro_rules! unit {
        ($context:expr, $fidelity:expr) => {
            Unit { bounds, cost, context: $context, fidelity: $fidelity, evals: &evals, progress }
        };
    }
    if d == 0 {
        return Ok(best_as_given(bounds, cost, swarm_context, starts, progress));
    }
    let note_time = |reason: Option<&argmin::core::TerminationReason>| {
        if matches!(reason, Some(argmin::core::TerminationReason::Timeout)) {
            timed_out.store(true, Ordering::Relaxed);
        }
    };

    // Global: independent swarms over the unit cube of the searched dimensions (the held ones
    // come last: see `swarm_holds`).
    let held: Vec<f64> = bounds.iter().filter_map(|b| b.swarm_holds.map(|v| b.to_unit(v))).collect();
    assert!(
        bounds.iter().skip_while(|b| b.swarm_holds.is_none()).all(|b| b.swarm_holds.is_some()),
        "dimensions the swarm holds come last"
    );
    let d_swarm = d - held.len();
    let particles = plan.particles.0 + plan.particles.1 * d_swarm;
    let iters = ((plan.swarm_iters * opts.effort).round() as u64).max(2);
    // Every dimension the swarm would search held (`--fix` of every law parameter, the initial
    // states left): no swarm (argmin's needs a dimension); the local searches start from the held
    // values and the starts.
    let swarm_bests: Vec<Vec<f64>> = if d_swarm == 0 {
        vec![held.clone()]
    } else {
        (0..plan.swarms as u64)
            .into_par_iter()
            .map(|k| -> Result<Vec<f64>> {
                let pso = ParticleSwarm::new((vec![0.0; d_swarm], vec![1.0; d_swarm]), particles)
                    .with_rng_generator(rand::rngs::StdRng::seed_from_u64(opts.seed.wrapping_add(k)));
                let problem = SwarmUnit { unit: unit!(swarm_context, Fidelity::Swarm), held: held.clone() };
                let res = bounded(Executor::new(problem, pso), opts.deadline)
                    .configure(|s| s.max_iters(iters))
                    .run()
                    .map_err(|e| anyhow::anyhow!("particle swarm: {e}"))?;
                note_time(res.state().get_termination_reason());
                let best = res
                    .state()
                    .get_best_param()
                    .map(|p| p.position.clone())
                    .unwrap_or_else(|| vec![0.5; d_swarm]);
                Ok([best, held.clone()].concat())
            })
            .collect::<Result<_>>()?
    };

    // Candidates: the starts and the swarms' bests, ranked on all data.
    let eval_full = |context: &C, unit: &[f64]| unit!(context, Fidelity::Full).eval(unit);
    let (seeds, regular) = ranked_seeds(bounds, starts, swarm_context, swarm_bests, plan, &eval_full);

    // Local: the plan's runs from each seed, in parallel; the last run only from the finalists.
    let nm_iters = ((plan.simplex_iters_per_dim * d as f64 * opts.effort).round() as u64).max(20);
    let max_jacobians = lm_jacobians(opts.effort);
    let local = |seed: &Seed<C>, runs: &[Local]| -> Result<Seed<C>> {
        let context = &seed.context;
        if runs.is_empty() {
            return Ok(seed.clone()); // its cost on all data is known
        }
        let mut best = seed.unit.clone();
        for &run in runs {
            if passed(opts.deadline) {
                timed_out.store(true, Ordering::Relaxed);
                break;
            }
            let (step, fidelity) = match run {
                Local::Simplex(step, fidelity) => (step, fidelity),
                Local::LeastSquares(fidelity) => {
                    let r = residuals
                        .ok_or_else(|| anyhow::anyhow!("a least-squares run needs the residuals"))?;
                    let count = |n| {
                        evals.fetch_add(n, Ordering::Relaxed);
                        progress.inc(n as u64);
                    };
                    let res = |u: &[f64]| r(context, &unit!(context, fidelity).values(u), fidelity);
                    best = levenberg_marquardt(&res, best, max_jacobians, opts.deadline, &count);
                    continue;
                }
            };
            let problem = || unit!(context, fidelity);
            let mut simplex = vec![best.clone()];
            for i in (0..d).filter(|i| !seed.simplex_holds.contains(i)) {
                let mut v = best.clone();
                v[i] = if v[i] > 0.5 { v[i] - step } else { v[i] + step };
                simplex.push(v);
            }
            if simplex.len() < 2 {
                continue; // every coordinate held
            }
            let tol = (plan.tolerance.0 * problem().eval(&best)).max(plan.tolerance.1);
            let nm = NelderMead::new(simplex).with_sd_tolerance(tol).map_err(|e| anyhow::anyhow!("{e}"))?;
            let res = bounded(Executor::new(problem(), nm), opts.deadline)
                .configure(|s| s.max_iters(nm_iters))
                .run()
                .map_err(|e| anyhow::anyhow!("Nelder–Mead: {e}"))?;
            note_time(res.state().get_termination_reason());
            best = res.state().get_best_param().cloned().unwrap_or(best);
        }
        let cost = unit!(context, Fidelity::Full).eval(&best);
        Ok(Seed { unit: best, cost, ..seed.clone() })
    };
    let (early, last) = plan.local.split_at(plan.local.len().saturating_sub(1));
    let mut refined: Vec<Seed<C>> = seeds.par_iter().map(|s| local(s, early)).collect::<Result<_>>()?;
    // The finalists: the best of the plan's seeds, and the always-refined one whatever it ranks.
    let pinned = refined.split_off(regular);
    let mut refined = by_cost(refined, plan.finalists.max(1));
    refined.extend(pinned);
    let refined: Vec<Seed<C>> = refined.par_iter().map(|s| local(s, last)).collect::<Result<_>>()?;
    let found = refined.into_iter().min_by(|a, b| a.cost.total_cmp(&b.cost)).expect("at least one seed");
    let values = bounds.iter().zip(&found.unit).map(|(b, &x)| b.from_unit(x)).collect();
    Ok(Found {
        best: values,
        context: found.context,
        cost: found.cost,
        evaluations: evals.load(Ordering::Relaxed),
        time_limited: timed_out.load(Ordering::Relaxed),
    })
}

/// Every continuous parameter fixed: nothing to search (argmin's solvers need at least one
/// dimension), so the best of the given contexts as they stand.
fn best_as_given<C: Clone>(
    bounds: &[Bound],
    cost: &Cost<'_, C>,
    swarm_context: &C,
    starts: &[Start<C>],
    progress: &Progress,
) -> Found<C> {
    let evals = AtomicUsize::new(0);
    let mut contexts: Vec<&C> = starts.iter().map(|s| &s.context).collect();
    contexts.push(swarm_context);
    let (context, cost) = contexts
        .into_iter()
        .map(|c| {
            let unit = Unit { bounds, cost, context: c, fidelity: Fidelity::Full, evals: &evals, progress };
            (c, unit.eval(&[]))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("the swarm context is always there");
    Found {
        best: Vec::new(),
        context: context.clone(),
        cost,
        evaluations: evals.load(Ordering::Relaxed),
        time_limited: false,
    }
}

/// The local searches' seeds: the starts and the swarms' bests, ranked on all data by
/// `eval_full`; the plan's best ones first (their count returned beside), then the best
/// always-refined start, which gets a local search of its own, to the end, beside them (it
/// never takes their places: they are refined as without it).
fn ranked_seeds<C: Clone>(
    bounds: &[Bound],
    starts: &[Start<C>],
    swarm_context: &C,
    swarm_bests: Vec<Vec<f64>>,
    plan: &Plan,
    eval_full: &dyn Fn(&C, &[f64]) -> f64,
) -> (Vec<Seed<C>>, usize) {
    let to_unit = |v: &[f64]| -> Vec<f64> { bounds.iter().zip(v).map(|(b, &x)| b.to_unit(x)).collect() };
    let mut seeds: Vec<(Seed<C>, bool)> = starts
        .iter()
        .map(|s| {
            let unit = to_unit(&s.values);
            let cost = eval_full(&s.context, &unit);
            let seed =
                Seed { context: s.context.clone(), unit, cost, simplex_holds: s.simplex_holds.clone() };
            (seed, s.always_refined)
        })
        .collect();
    for unit in swarm_bests {
        let cost = eval_full(swarm_context, &unit);
        seeds.push((Seed { context: swarm_context.clone(), unit, cost, simplex_holds: Vec::new() }, false));
    }
    let (pinned, seeds): (Vec<_>, Vec<_>) = seeds.into_iter().partition(|s| s.1);
    let seeds = by_cost(seeds.into_iter().map(|s| s.0).collect(), plan.local_searches.max(1));
    let regular = seeds.len();
    (seeds.into_iter().chain(by_cost(pinned.into_iter().map(|s| s.0).collect(), 1)).collect(), regular)
}

/// The `keep` cheapest seeds, cheapest first.
fn by_cost<C>(mut v: Vec<Seed<C>>, keep: usize) -> Vec<Seed<C>> {
    v.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    v.truncate(keep);
    v
}

/// Finite-difference Jacobians a Levenberg–Marquardt run may take at effort 1 (each costs a
/// residual evaluation per dimension, in parallel); the steps between them update it cheaply.
const LM_JACOBIANS: usize = 12;
/// Accepted steps between two finite-difference Jacobians (Broyden updates in between).
const LM_REFRESH: usize = 4;

/// The evaluations a least-squares run over `d` dimensions may take at `effort` (for progress
/// bars): its Jacobians and the steps between them.
pub fn least_squares_evaluations(d: usize, effort: f64) -> u64 {
    (lm_jacobians(effort) * (d + LM_REFRESH)) as u64
}

/// Finite-difference Jacobians a least-squares run may take at `effort`.
fn lm_jacobians(effort: f64) -> usize {
    ((LM_JACOBIANS as f64 * effort).round() as usize).max(3)
}

/// Minimises ‖r(u)‖² over the unit cube from `u` by Levenberg–Marquardt: forward-difference
/// Jacobians (the columns in parallel), refreshed every [`LM_REFRESH`] accepted steps and kept up
/// to date in between by Broyden's rank-one update (one evaluation per step instead of one per
/// dimension); Marquardt's scaling by the diagonal of JᵀJ; parameters on a bound that would
/// step out are held there ([`damped_step`]) and the other steps clamped into the cube; the
/// damping adapted to the ratio of actual to predicted decrease (Nielsen). Converged when a step
/// from a fresh Jacobian gains less than 1e-7 of the cost or none decreases it. Returns the best
/// point seen (`u` itself when nothing decreases).
fn levenberg_marquardt(
    r: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    mut u: Vec<f64>,
    max_jacobians: usize,
    deadline: Option<Instant>,
    count: &(dyn Fn(usize) + Sync),
) -> Vec<f64> {
    use nalgebra::{DMatrix, DVector};
    // A forward step (unit cube) well above the f32 models' rounding and wide enough to average
    // over the kinks a sub-stepped hysteresis law leaves in the cost; well below its features.
    const H: f64 = 1e-3;
    let d = u.len();
    count(1);
    let Some(r0) = r(&u) else { return u };
    let mut r0 = DVector::from_vec(r0);
    let mut f0 = r0.norm_squared();
    let n = r0.len();
    let (mut mu, mut nu) = (1e-3, 2.0);
    let mut jac = DMatrix::<f64>::zeros(n, d);
    let (mut jacobians, mut since_fresh) = (0, usize::MAX);
    while jacobians < max_jacobians || since_fresh < LM_REFRESH {
        if passed(deadline) {
            break;
        }
        let fresh = since_fresh >= LM_REFRESH;
        if fresh {
            count(d);
            jacobians += 1;
            since_fresh = 0;
            let cols: Vec<Option<(f64, Vec<f64>)>> = (0..d)
                .into_par_iter()
                .map(|j| {
                    let h = if u[j] + H <= 1.0 { H } else { -H };
                    let mut v = u.clone();
                    v[j] += h;
                    r(&v).map(|rv| (h, rv))
                })
                .collect();
            for (j, col) in cols.iter().enumerate() {
                // A column the model cannot run holds that parameter for this step.
                let mut c = jac.column_mut(j);
                match col {
                    Some((h, rv)) => {
                        c.iter_mut().zip(rv).zip(r0.iter()).for_each(|((c, a), b)| *c = (a - b) / h)
                    }
                    None => c.fill(0.0),
                }
            }
        }
        let (jtj, g) = normal_equations(&jac, &r0);
        let mut accepted = None;
        for _ in 0..8 {
            let Some(step) = damped_step(&jtj, &g, mu, &u) else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let v: Vec<f64> = u.iter().zip(step.iter()).map(|(x, s)| (x + s).clamp(0.0, 1.0)).collect();
            let taken = DVector::from_iterator(d, v.iter().zip(&u).map(|(a, b)| a - b));
            // Predicted decrease of the linear model for the (clamped) step taken.
            let predicted = -(2.0 * g.dot(&taken) + (&jtj * &taken).dot(&taken));
            count(1);
            let trial = r(&v).map(DVector::from_vec);
            let f1 = trial.as_ref().map_or(f64::INFINITY, |t| t.norm_squared());
            if f1 < f0 && predicted > 0.0 {
                let rho = (f0 - f1) / predicted;
                mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                nu = 2.0;
                accepted = Some((v, taken, trial.expect("finite trial"), f1));
                break;
            }
            mu *= nu;
            nu *= 2.0;
        }
        match accepted {
            Some((v, taken, r1, f1)) => {
                let small = f0 - f1 < 1e-7 * f0;
                // Broyden: J += (Δr − J·δ) δᵀ / δᵀδ, so that J maps the step taken exactly.
                let dd = taken.norm_squared();
                if dd > 0.0 {
                    let miss = (&r1 - &r0) - &jac * &taken;
                    jac.ger(1.0 / dd, &miss, &taken, 1.0);
                }
                (u, r0, f0) = (v, r1, f1);
                since_fresh += 1;
                if small {
                    if fresh {
                        break;
                    }
                    since_fresh = LM_REFRESH; // confirm with a fresh Jacobian
                }
            }
            // No decrease: with an updated Jacobian try a fresh one, with a fresh one stop.
            None if fresh => break,
            None => since_fresh = LM_REFRESH,
        }
    }
    u
}

/// JᵀJ and Jᵀr, their entries the column dot products nalgebra's `tr_mul` takes (so the same
/// bits), JᵀJ's upper triangle only, mirrored, and the dots in parallel: with a residual per
/// sample of every file, these products are the run's costliest step outside the model.
fn normal_equations(
    jac: &nalgebra::DMatrix<f64>,
    r: &nalgebra::DVector<f64>,
) -> (nalgebra::DMatrix<f64>, nalgebra::DVector<f64>) {
    let d = jac.ncols();
    // (i, j) for JᵀJ's upper triangle; (i, d) for Jᵀr.
    let pairs: Vec<(usize, usize)> = (0..d).flat_map(|i| (i..=d).map(move |j| (i, j))).collect();
    let dots: Vec<f64> = pairs
        .par_iter()
        .map(|&(i, j)| if j < d { jac.column(i).dot(&jac.column(j)) } else { jac.column(i).dot(r) })
        .collect();
    let mut jtj = nalgebra::DMatrix::zeros(d, d);
    let mut g = nalgebra::DVector::zeros(d);
    for (&(i, j), &v) in pairs.iter().zip(&dots) {
        if j < d {
            jtj[(i, j)] = v;
            jtj[(j, i)] = v;
        } else {
            g[i] = v;
        }
    }
    (jtj, g)
}

/// The Levenberg–Marquardt step (JᵀJ + μ·diag JᵀJ) δ = −g from `u`, with the parameters that sit
/// on a face of the cube and would step out of it held there: the others then take the best step
/// along the face, where clamping the unconstrained step would stall short of it. `None` when the
/// system is singular.
fn damped_step(
    jtj: &nalgebra::DMatrix<f64>,
    g: &nalgebra::DVector<f64>,
    mu: f64,
    u: &[f64],
) -> Option<nalgebra::DVector<f64>> {
    let d = u.len();
    let mut held = vec![false; d];
    loop {
        let mut a = jtj.clone();
        let mut rhs = -g;
        for k in 0..d {
            a[(k, k)] += mu * jtj[(k, k)].max(1e-12);
        }
        for k in (0..d).filter(|&k| held[k]) {
            a.row_mut(k).fill(0.0);
            a.column_mut(k).fill(0.0);
            a[(k, k)] = 1.0;
            rhs[k] = 0.0;
        }
        let step = a.cholesky()?.solve(&rhs);
        let outward = |k: usize| (u[k] <= 0.0 && step[k] < 0.0) || (u[k] >= 1.0 && step[k] > 0.0);
        let newly: Vec<usize> = (0..d).filter(|&k| !held[k] && outward(k)).collect();
        if newly.is_empty() {
            return Some(step);
        }
        newly.into_iter().for_each(|k| held[k] = true);
    }
}

#[cfg(test)]
mod tests;
