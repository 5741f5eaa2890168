//! Bounded global-then-local minimisation for small parameter vectors: a particle swarm
//! (argmin; the swarm is evaluated in parallel with rayon) over the unit cube of the bounds
//! (log scale where a parameter spans decades), then Nelder–Mead (argmin) from the swarm's best,
//! restarted once with a smaller simplex. Deterministic for a seed.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand::SeedableRng;

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
}

impl Bound {
    /// A linear range.
    pub fn lin(name: &'static str, lo: f64, hi: f64) -> Self {
        Self { name, lo, hi, log: false }
    }

    /// A logarithmic range (positive bounds).
    pub fn log(name: &'static str, lo: f64, hi: f64) -> Self {
        Self { name, lo, hi, log: true }
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

/// Search settings.
#[derive(Debug, Clone, Copy)]
pub struct SearchOptions {
    /// Seed of the swarm.
    pub seed: u64,
    /// Effort multiplier (1 = default).
    pub effort: f64,
    /// Stop at this instant with the best point so far.
    pub deadline: Option<Instant>,
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self { seed: 1, effort: 1.0, deadline: None }
    }
}

/// What a search found.
#[derive(Debug, Clone)]
pub struct Found {
    /// The best values.
    pub best: Vec<f64>,
    /// Cost evaluations.
    pub evaluations: usize,
    /// Stopped by the deadline.
    pub time_limited: bool,
}

struct Unit<'a> {
    bounds: &'a [Bound],
    cost: &'a (dyn Fn(&[f64]) -> f64 + Sync),
    evals: &'a AtomicUsize,
}

impl Unit<'_> {
    fn values(&self, u: &[f64]) -> Vec<f64> {
        self.bounds.iter().zip(u).map(|(b, &x)| b.from_unit(x)).collect()
    }

    fn eval(&self, u: &[f64]) -> f64 {
        self.evals.fetch_add(1, Ordering::Relaxed);
        let outside: f64 = u.iter().map(|x| (x - x.clamp(0.0, 1.0)).powi(2)).sum();
        let c = (self.cost)(&self.values(u));
        if c.is_finite() {
            c + outside
        } else {
            f64::MAX / 4.0
        }
    }
}

impl CostFunction for Unit<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.eval(u))
    }
}

/// Minimises `cost` over `bounds`: two independent swarm + simplex searches (seeds `seed` and
/// `seed + 1`, run in parallel), the better one kept.
pub fn minimize(bounds: &[Bound], cost: &(dyn Fn(&[f64]) -> f64 + Sync), opts: SearchOptions) -> Found {
    let evals = AtomicUsize::new(0);
    let timed_out = AtomicBool::new(false);
    let second = SearchOptions { seed: opts.seed.wrapping_add(1), ..opts };
    let ((a, ca), (b, cb)) = rayon::join(
        || search_once(bounds, cost, opts, &evals, &timed_out),
        || search_once(bounds, cost, second, &evals, &timed_out),
    );
    let best = if ca <= cb { a } else { b };
    Found {
        best,
        evaluations: evals.load(Ordering::Relaxed),
        time_limited: timed_out.load(Ordering::Relaxed),
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

fn search_once(
    bounds: &[Bound],
    cost: &(dyn Fn(&[f64]) -> f64 + Sync),
    opts: SearchOptions,
    evals: &AtomicUsize,
    timed_out: &AtomicBool,
) -> (Vec<f64>, f64) {
    let d = bounds.len();
    let ended_by_time = |reason: Option<&argmin::core::TerminationReason>| {
        if matches!(reason, Some(argmin::core::TerminationReason::Timeout)) {
            timed_out.store(true, Ordering::Relaxed);
        }
    };
    let unit = || Unit { bounds, cost, evals };
    let particles = 10 + 4 * d;
    let iters = ((25.0 * opts.effort).round() as u64).max(2);
    let pso = ParticleSwarm::new((vec![0.0; d], vec![1.0; d]), particles)
        .with_rng_generator(rand::rngs::StdRng::seed_from_u64(opts.seed));
    let mut best = vec![0.5; d];
    if let Ok(res) =
        bounded(Executor::new(unit(), pso), opts.deadline).configure(|s| s.max_iters(iters)).run()
    {
        ended_by_time(res.state().get_termination_reason());
        if let Some(p) = res.state().get_best_param() {
            best = p.position.clone();
        }
    }
    let nm_iters = ((80.0 * d as f64 * opts.effort).round() as u64).max(20);
    for step in [0.05, 0.01] {
        let mut simplex = vec![best.clone()];
        for i in 0..d {
            let mut v = best.clone();
            v[i] += if v[i] > 0.5 { -step } else { step };
            simplex.push(v);
        }
        let tol = (1e-7 * unit().eval(&best)).max(1e-20);
        let Ok(nm) = NelderMead::new(simplex).with_sd_tolerance(tol) else { break };
        if opts.deadline.is_some_and(|d| Instant::now() >= d) {
            timed_out.store(true, Ordering::Relaxed);
            break;
        }
        if let Ok(res) =
            bounded(Executor::new(unit(), nm), opts.deadline).configure(|s| s.max_iters(nm_iters)).run()
        {
            ended_by_time(res.state().get_termination_reason());
            if let Some(p) = res.state().get_best_param() {
                best = p.clone();
            }
        }
    }
    let c = unit().eval(&best);
    (unit().values(&best), c)
}
