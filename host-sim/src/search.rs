//! The workbench's one optimiser: bounded global-then-local minimisation for small parameter
//! vectors. A particle swarm (argmin; particles evaluated in parallel with rayon) over the unit
//! cube of the bounds (log scale where a parameter spans decades), then Nelder–Mead (argmin)
//! from the best points found, restarted with a smaller simplex. Deterministic for a seed.
//!
//! Hooks for the displacement fit: the cost can be evaluated on cheaper data subsets
//! ([`Fidelity`]: the swarm and the coarse simplex need only the landscape's shape), the search
//! can start from given points that carry a context (e.g. an integer parameter held fixed), and
//! [`scan`] searches an integer parameter exhaustively.

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
    /// The simplex runs: initial step (unit-cube fraction) and the data each runs on.
    pub simplex: &'static [(f64, Fidelity)],
    /// Converged when the simplex's costs agree to this fraction of the cost (and the floor).
    pub tolerance: (f64, f64),
}

/// A start point and the context its cost is evaluated in.
#[derive(Debug, Clone)]
pub struct Start<C> {
    /// Values (in the parameters' units).
    pub values: Vec<f64>,
    /// What the cost needs besides the values (e.g. an integer parameter held fixed).
    pub context: C,
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
    deadline.is_some_and(|d| Instant::now() >= d)
}

/// Minimises `cost` over `bounds`: `plan.swarms` swarms (in `swarm_context`) and the `starts`
/// give candidates, the best `plan.local_searches` of them (by cost on all data) are refined by
/// the plan's simplex runs in parallel, and the best result is returned.
pub fn minimize<C: Clone + Send + Sync>(
    bounds: &[Bound],
    cost: &Cost<'_, C>,
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
        // Every continuous parameter fixed: nothing to search (argmin's solvers need at least
        // one dimension), so the best of the given contexts as they stand.
        let mut contexts: Vec<&C> = starts.iter().map(|s| &s.context).collect();
        contexts.push(swarm_context);
        let (context, cost) = contexts
            .into_iter()
            .map(|c| (c, unit!(c, Fidelity::Full).eval(&[])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("the swarm context is always there");
        return Ok(Found {
            best: Vec::new(),
            context: context.clone(),
            cost,
            evaluations: evals.load(Ordering::Relaxed),
            time_limited: false,
        });
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
    let swarm_bests: Vec<Vec<f64>> = (0..plan.swarms as u64)
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
        .collect::<Result<_>>()?;

    // Candidates: the starts and the swarms' bests, ranked on all data.
    let to_unit = |v: &[f64]| -> Vec<f64> { bounds.iter().zip(v).map(|(b, &x)| b.to_unit(x)).collect() };
    let mut seeds: Vec<(C, Vec<f64>, f64)> = starts
        .iter()
        .map(|s| {
            let u = to_unit(&s.values);
            let c = unit!(&s.context, Fidelity::Full).eval(&u);
            (s.context.clone(), u, c)
        })
        .collect();
    for u in swarm_bests {
        let c = unit!(swarm_context, Fidelity::Full).eval(&u);
        seeds.push((swarm_context.clone(), u, c));
    }
    seeds.sort_by(|a, b| a.2.total_cmp(&b.2));
    seeds.truncate(plan.local_searches.max(1));

    // Local: the plan's simplex runs from each seed, in parallel; the last run only from the
    // finalists.
    let nm_iters = ((plan.simplex_iters_per_dim * d as f64 * opts.effort).round() as u64).max(20);
    let local = |seed: &(C, Vec<f64>, f64), runs: &[(f64, Fidelity)]| -> Result<(C, Vec<f64>, f64)> {
        let (context, start, _) = seed;
        if runs.is_empty() {
            return Ok(seed.clone()); // its cost on all data is known
        }
        let mut best = start.clone();
        for &(step, fidelity) in runs {
            if passed(opts.deadline) {
                timed_out.store(true, Ordering::Relaxed);
                break;
            }
            let problem = || unit!(context, fidelity);
            let mut simplex = vec![best.clone()];
            for i in 0..d {
                let mut v = best.clone();
                v[i] = if v[i] > 0.5 { v[i] - step } else { v[i] + step };
                simplex.push(v);
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
        let c = unit!(context, Fidelity::Full).eval(&best);
        Ok((context.clone(), best, c))
    };
    let (early, last) = plan.simplex.split_at(plan.simplex.len().saturating_sub(1));
    let mut refined: Vec<(C, Vec<f64>, f64)> =
        seeds.par_iter().map(|s| local(s, early)).collect::<Result<_>>()?;
    refined.sort_by(|a, b| a.2.total_cmp(&b.2));
    refined.truncate(plan.finalists.max(1));
    let refined: Vec<(C, Vec<f64>, f64)> =
        refined.par_iter().map(|s| local(s, last)).collect::<Result<_>>()?;
    let (context, best, cost) =
        refined.into_iter().min_by(|a, b| a.2.total_cmp(&b.2)).expect("at least one seed");
    let values = bounds.iter().zip(&best).map(|(b, &x)| b.from_unit(x)).collect();
    Ok(Found {
        best: values,
        context,
        cost,
        evaluations: evals.load(Ordering::Relaxed),
        time_limited: timed_out.load(Ordering::Relaxed),
    })
}

/// The integer in `lo..=hi` with the lowest `cost` (all evaluated, in parallel; ties go to the
/// smallest).
pub fn scan(lo: i64, hi: i64, cost: &(dyn Fn(i64) -> f64 + Sync)) -> i64 {
    let costs: Vec<(i64, f64)> = (lo..=hi).into_par_iter().map(|k| (k, cost(k))).collect();
    costs.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|c| c.0).unwrap_or(lo)
}
