//! Identification: one parameter set for a model spec from one or more recordings jointly, a
//! displacement offset per file (closed form: the mean residual), cost = mean over files of
//! NRMSE² (plus the current channel's when the model has an amplifier and the file measured the
//! current). Search in the unit cube of the bounded, log-scaled free parameters
//! ([`crate::params`]): a particle swarm (argmin, swarm evaluated in parallel with rayon), then
//! Nelder–Mead (argmin) from the best particle; a sensor delay is an integer searched by scanning.
//! Deterministic for a given seed.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use model_core::{Actuator, ActuatorParams, Effect, ModelSpec};
use rand::SeedableRng;
use rayon::prelude::*;

use crate::params::{free_params, FreeParam, MAX_DELAY_SEARCH};
use crate::progress::Progress;
use crate::recording::Recording;
use crate::search::bounded;

/// How a file drives the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drive {
    /// The measured coil current is the input.
    Current,
    /// The command [V] through an ideal amplifier (gain `amp.gain_a_per_v`).
    CommandIdeal,
    /// The command [V] through the modelled amplifier dynamics.
    CommandDynamic,
}

/// Smallest displacement span worth fitting [µm] (1 pm: below the best capacitive probes).
pub const MIN_DISPLACEMENT_SPAN_UM: f64 = 1e-6;

/// The drive `spec` uses for `rec`, or why it cannot be simulated.
pub fn drive_for(spec: ModelSpec, rec: &Recording) -> Result<Drive> {
    let Some(y) = rec.displacement_um.as_deref() else {
        bail!("{}: no `displacement_um` column: nothing to compare the model with", rec.name);
    };
    let span =
        |v: &[f64]| v.iter().fold(f64::MIN, |a, &b| a.max(b)) - v.iter().fold(f64::MAX, |a, &b| a.min(b));
    if span(y) <= 0.0 {
        bail!(
            "{}: the displacement never changes: there is nothing to fit (sensor unplugged or stuck?)",
            rec.name
        );
    }
    if span(y) < MIN_DISPLACEMENT_SPAN_UM {
        bail!(
            "{}: the displacement spans only {:.3e} µm, below any sensor's resolution ({MIN_DISPLACEMENT_SPAN_UM:e} µm): \
             is `displacement_um` in micrometres?",
            rec.name,
            span(y)
        );
    }
    let drive = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    if span(drive) <= 0.0 {
        bail!(
            "{}: the drive (current_A/command_V) is constant: the model's response cannot be identified",
            rec.name
        );
    }
    if spec.has(Effect::AmplifierDynamics) {
        if rec.command_v.is_none() {
            bail!("{}: the model has amplifier_dynamics, which needs a `command_V` column", rec.name);
        }
        Ok(Drive::CommandDynamic)
    } else if rec.current_a.is_some() {
        Ok(Drive::Current)
    } else {
        Ok(Drive::CommandIdeal)
    }
}

/// A model run over one recording (same length; displacement in µm without offset).
#[derive(Debug, Clone)]
pub struct Simulation {
    /// Model displacement [µm] (add `offset_um` to compare with the file).
    pub displacement_um: Vec<f64>,
    /// Model coil current [A].
    pub current_a: Vec<f64>,
    /// Field in the rod [A/m].
    pub field_a_per_m: Vec<f64>,
    /// Model magnetization [A/m].
    pub magnetization_a_per_m: Vec<f64>,
}

/// Runs `spec` with `params` over `rec`. Simultaneous sampling, as a rig records: row k holds
/// the drive and the displacement at the same instant t_k, so the model output at k is its state
/// after integrating the drive up to t_k.
pub fn simulate(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<Simulation> {
    run_model(spec, params, rec, true)
}

/// [`simulate`]; `all_channels: false` keeps only displacement and current (the fit's inner loop).
fn run_model(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
    all_channels: bool,
) -> Result<Simulation> {
    let drive = drive_for(spec, rec)?;
    let mut p = *params;
    p.dt_s = rec.dt_s() as f32;
    let model = Actuator::new(spec, &p).map_err(|e| anyhow::anyhow!("{e}"))?;
    let n = rec.len();
    // Borrowed from the recording (this runs at every fit evaluation); only the ideal amplifier's
    // scaled command is a new vector.
    let input: std::borrow::Cow<[f64]> = match drive {
        Drive::Current => rec.current_a.as_deref().unwrap_or_default().into(),
        Drive::CommandIdeal => {
            rec.command_v.iter().flatten().map(|u| u * p.amp.gain_a_per_v as f64).collect::<Vec<_>>().into()
        }
        Drive::CommandDynamic => rec.command_v.as_deref().unwrap_or_default().into(),
    };
    let mut s = model.rest_state();
    let mut out = Simulation {
        displacement_um: Vec::with_capacity(n),
        current_a: Vec::with_capacity(n),
        field_a_per_m: Vec::with_capacity(n),
        magnetization_a_per_m: Vec::with_capacity(n),
    };
    let mut y = s.mech.displacement_m as f64; // rest: the delay line holds this value too
    let mut i = if drive == Drive::CommandDynamic { 0.0 } else { input[0] };
    let (mut h, mut m) = (p.coil.bias_a_per_m as f64, f64::NAN);
    for k in 0..n {
        // Simultaneous sampling: the output at t_k, then the step to t_{k+1}.
        out.displacement_um.push(y * 1e6);
        out.current_a.push(i);
        if all_channels {
            out.field_a_per_m.push(h);
            out.magnetization_a_per_m.push(m);
        }
        // The drive between samples k and k+1 is known only at its ends: hold their mean (an
        // O(dt²) hold, where a plain zero-order hold of u_k would lag by half a sample).
        let u = 0.5 * (input[k] + input[(k + 1).min(n - 1)]);
        let o = model.step(&mut s, u as f32).map_err(|e| anyhow::anyhow!("{}: sample {k}: {e}", rec.name))?;
        y = o.displacement_m as f64;
        i = o.current_a as f64;
        h = o.field_a_per_m as f64;
        m = o.magnetization_a_per_m as f64;
    }
    if let Some(first) = out.magnetization_a_per_m.get(1).copied() {
        out.magnetization_a_per_m[0] = first;
    }
    Ok(out)
}

/// How well a model matches one file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FileScore {
    /// NRMSE of the displacement (offset removed).
    pub nrmse: f64,
    /// NRMSE of the current channel, when the model predicts a measured current.
    pub nrmse_current: Option<f64>,
    /// Fitted displacement offset [µm].
    pub offset_um: f64,
}

/// rms(a − b) / (max − min of a).
pub fn nrmse(measured: &[f64], model: &[f64]) -> f64 {
    let (lo, hi) = measured.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let mse = measured.iter().zip(model).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / measured.len() as f64;
    mse.sqrt() / (hi - lo).max(1e-12)
}

/// Scores a simulation against its file.
pub fn score(spec: ModelSpec, rec: &Recording, sim: &Simulation) -> FileScore {
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    let offset = meas.iter().zip(&sim.displacement_um).map(|(a, b)| a - b).sum::<f64>() / meas.len() as f64;
    let shifted: Vec<f64> = sim.displacement_um.iter().map(|y| y + offset).collect();
    let nrmse_current = match (&rec.current_a, spec.has(Effect::AmplifierDynamics)) {
        (Some(i), true) => Some(nrmse(i, &sim.current_a)),
        _ => None,
    };
    FileScore { nrmse: nrmse(meas, &shifted), nrmse_current, offset_um: offset }
}

/// Scores of a parameter set on a set of files, and the cost the fit minimises.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// Per file, in order.
    pub files: Vec<FileScore>,
}

impl Evaluation {
    /// Mean displacement NRMSE over the files (the contract's `nrmse_fit` / `nrmse_val`).
    pub fn mean_nrmse(&self) -> f64 {
        self.files.iter().map(|f| f.nrmse).sum::<f64>() / self.files.len().max(1) as f64
    }

    /// The fit's cost: mean of NRMSE² over files and channels.
    pub fn cost(&self) -> f64 {
        let mut sum = 0.0;
        let mut n = 0.0f64;
        for f in &self.files {
            sum += f.nrmse * f.nrmse;
            n += 1.0;
            if let Some(c) = f.nrmse_current {
                sum += c * c;
                n += 1.0;
            }
        }
        sum / n.max(1.0)
    }
}

/// Evaluates `params` on every file (in parallel).
pub fn evaluate(spec: ModelSpec, params: &ActuatorParams, files: &[Recording]) -> Result<Evaluation> {
    let files: Result<Vec<FileScore>> =
        files.par_iter().map(|rec| Ok(score(spec, rec, &simulate(spec, params, rec)?))).collect();
    Ok(Evaluation { files: files? })
}

/// Evaluates `params` with the strain scale λ_s chosen by linear least squares (variable
/// projection): the displacement is λ_s·g + t + offset, with g the magnetostrictive part and t the
/// thermal elongation, so λ_s and the per-file offsets have a closed form. This removes the
/// strongest scale ambiguity of the magnetization models (λ_s against M's scale) from the
/// nonlinear search. Returns the scores and that λ_s.
pub fn evaluate_projected(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Recording],
) -> Result<(Evaluation, f64)> {
    let lambda_ref = params.magnetostriction.lambda_s as f64;
    let thermal = spec.has(Effect::ThermalDrift);
    // Per file: (g, t, simulation) with y = λ g + t.
    let parts: Vec<(Vec<f64>, Vec<f64>, Simulation)> = files
        .par_iter()
        .map(|rec| {
            let sim_a = run_model(spec, params, rec, false)?;
            if thermal {
                let mut p2 = *params;
                p2.magnetostriction.lambda_s = (2.0 * lambda_ref) as f32;
                let sim_b = run_model(spec, &p2, rec, false)?;
                let g = sim_a
                    .displacement_um
                    .iter()
                    .zip(&sim_b.displacement_um)
                    .map(|(a, b)| (b - a) / lambda_ref)
                    .collect();
                let t = sim_a
                    .displacement_um
                    .iter()
                    .zip(&sim_b.displacement_um)
                    .map(|(a, b)| 2.0 * a - b)
                    .collect();
                Ok((g, t, sim_a))
            } else {
                let g = sim_a.displacement_um.iter().map(|a| a / lambda_ref).collect();
                Ok((g, vec![0.0; rec.len()], sim_a))
            }
        })
        .collect::<Result<_>>()?;
    fn centred(x: &[f64]) -> impl Iterator<Item = f64> + '_ {
        let m = x.iter().sum::<f64>() / x.len() as f64;
        x.iter().map(move |v| v - m)
    }
    let (mut num, mut den) = (0.0, 0.0);
    for (rec, (g, t, _)) in files.iter().zip(&parts) {
        let y = rec.displacement_um.as_deref().unwrap_or_default();
        let (lo, hi) = y.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        let w = 1.0 / (y.len() as f64 * (hi - lo).max(1e-12).powi(2));
        let target: Vec<f64> = y.iter().zip(t).map(|(a, b)| a - b).collect();
        for (a, b) in centred(&target).zip(centred(g)) {
            num += w * a * b;
            den += w * b * b;
        }
    }
    let lambda = if den > 0.0 { (num / den).clamp(1e-8, 1.0) } else { lambda_ref };
    let scores = files
        .iter()
        .zip(parts)
        .map(|(rec, (g, t, mut sim))| {
            sim.displacement_um = g.iter().zip(&t).map(|(g, t)| lambda * g + t).collect();
            score(spec, rec, &sim)
        })
        .collect();
    Ok((Evaluation { files: scores }, lambda))
}

/// Fit settings.
#[derive(Debug, Clone, Copy)]
pub struct FitOptions {
    /// Seed of the swarm's random initialisation.
    pub seed: u64,
    /// Show progress on stderr (a bar on a terminal, else a line every few seconds).
    pub progress: bool,
    /// Effort multiplier (1 = default; the swarm and the simplex iterations scale with it).
    pub effort: f64,
    /// Stop searching at this instant and return the best point found so far.
    pub deadline: Option<Instant>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self { seed: 1, progress: false, effort: 1.0, deadline: None }
    }
}

/// Time left before `deadline` (none: unbounded); zero once it has passed.
pub fn time_left(deadline: Option<Instant>) -> Option<Duration> {
    deadline.map(|d| d.saturating_duration_since(Instant::now()))
}

/// Whether an argmin run ended on its time limit.
fn ended_by_time<I: State>(state: &I) -> bool {
    matches!(state.get_termination_reason(), Some(argmin::core::TerminationReason::Timeout))
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
}

/// The fit problem in the unit cube.
struct Problem<'a> {
    spec: ModelSpec,
    base: ActuatorParams,
    free: &'a [FreeParam],
    files: &'a [Recording],
    evals: &'a AtomicUsize,
    bar: &'a Progress,
}

impl Problem<'_> {
    fn params_at(&self, u: &[f64]) -> ActuatorParams {
        let mut p = self.base;
        for (f, &x) in self.free.iter().zip(u) {
            (f.set)(&mut p, f.from_unit(x));
        }
        p
    }

    fn cost_at(&self, u: &[f64]) -> f64 {
        self.evals.fetch_add(1, Ordering::Relaxed);
        self.bar.inc(1);
        // Outside the cube: the clamped point's cost plus a pull back inside.
        let outside: f64 = u.iter().map(|x| (x - x.clamp(0.0, 1.0)).powi(2)).sum();
        let cost =
            evaluate_projected(self.spec, &self.params_at(u), self.files).map(|e| e.0.cost()).unwrap_or(1e3);
        if cost.is_finite() {
            cost + outside
        } else {
            1e3
        }
    }
}

impl CostFunction for Problem<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.cost_at(u))
    }
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
    if files.is_empty() {
        bail!("no files to fit");
    }
    if starts.is_empty() {
        bail!("no start parameters");
    }
    let mut command_driven = false;
    for rec in files {
        command_driven |= drive_for(spec, rec)? != Drive::Current;
    }
    // λ_s is solved in closed form at every evaluation (see `evaluate_projected`).
    let free: Vec<FreeParam> = free_params(spec, command_driven)
        .into_iter()
        .filter(|f| f.name() != "magnetostriction.lambda_s")
        .collect();
    let d = free.len();
    let particles = 8 + 3 * d;
    let swarm_iters = ((12.0 * opts.effort).round() as u64).max(2);
    let nm_iters = ((40.0 * d as f64 * opts.effort).round() as u64).max(20);
    let delay_scan = spec.has(Effect::SensorDelay);
    let planned = particles as u64 * (swarm_iters + 1)
        + nm_iters * 8
        + if delay_scan { (starts.len() as u64 + 1) * 17 } else { 0 };
    let bar = Progress::new(&format!("fitting {spec}"), planned, opts.progress);
    let timed_out = AtomicBool::new(false);
    let evals = AtomicUsize::new(0);
    let problem = |base: ActuatorParams| Problem { spec, base, free: &free, files, evals: &evals, bar: &bar };

    // Sensor delay: scan the integer with everything else fixed.
    let scan_delay = |p: &mut ActuatorParams| {
        if !delay_scan {
            return;
        }
        let costs: Vec<(u16, f64)> = (0..=MAX_DELAY_SEARCH)
            .into_par_iter()
            .map(|dly| {
                let mut q = *p;
                q.delay_samples = dly;
                evals.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
                (dly, evaluate_projected(spec, &q, files).map(|e| e.0.cost()).unwrap_or(f64::INFINITY))
            })
            .collect();
        p.delay_samples = costs.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|c| c.0).unwrap_or(0);
    };
    // Start points: the fixed parameters come from the first; each start's identified values are
    // clamped into the bounds and its delay scanned.
    let bases: Vec<ActuatorParams> = starts
        .iter()
        .map(|st| {
            let mut b = starts[0];
            for f in &free {
                (f.set)(&mut b, f.from_unit(f.to_unit((f.get)(st))));
            }
            b.delay_samples = st.delay_samples;
            scan_delay(&mut b);
            b
        })
        .collect();
    let unit = |b: &ActuatorParams| -> Vec<f64> { free.iter().map(|f| f.to_unit((f.get)(b))).collect() };

    // Global: particle swarm over the unit cube, on the first part of each file (at least 4000
    // samples or a quarter): the swarm only needs the landscape's shape; the local search below
    // uses every sample.
    let heads: Vec<Recording> = files.iter().map(|r| r.head(4000.max(r.len() / 4))).collect();
    let pso = ParticleSwarm::new((vec![0.0; d], vec![1.0; d]), particles)
        .with_rng_generator(rand::rngs::StdRng::seed_from_u64(opts.seed));
    let swarm_problem =
        Problem { spec, base: bases[0], free: &free, files: &heads, evals: &evals, bar: &bar };
    let res = bounded(Executor::new(swarm_problem, pso), opts.deadline)
        .configure(|s| s.max_iters(swarm_iters))
        .run()
        .map_err(|e| anyhow::anyhow!("particle swarm: {e}"))?;
    timed_out.fetch_or(ended_by_time(res.state()), Ordering::Relaxed);
    let mut seeds: Vec<(ActuatorParams, Vec<f64>, f64)> =
        bases.iter().map(|b| (*b, unit(b), problem(*b).cost_at(&unit(b)))).collect();
    if let Some(p) = res.state().get_best_param() {
        let cost = problem(bases[0]).cost_at(&p.position);
        seeds.push((bases[0], p.position.clone(), cost));
    }
    seeds.sort_by(|a, b| a.2.total_cmp(&b.2));
    seeds.truncate(2);

    // Local: Nelder–Mead from the two best seeds (in parallel), each run twice: a simplex of 5 %
    // of each range, then a fresh 1 % simplex at its result (restarts undo collapsed simplices).
    // The first, coarse simplex runs on the first half of long files (at least 8000 samples),
    // the second on everything.
    let halves: Vec<Recording> = files.iter().map(|r| r.head(8000.max(r.len() / 2))).collect();
    let local =
        |(base, start, _): &(ActuatorParams, Vec<f64>, f64)| -> Result<(ActuatorParams, Vec<f64>, f64)> {
            let mut best = start.clone();
            for (step, data) in [(0.05, &halves[..]), (0.01, files)] {
                if time_left(opts.deadline).is_some_and(|t| t.is_zero()) {
                    timed_out.store(true, Ordering::Relaxed);
                    break;
                }
                let problem = |base: ActuatorParams| Problem {
                    spec,
                    base,
                    free: &free,
                    files: data,
                    evals: &evals,
                    bar: &bar,
                };
                let mut simplex = vec![best.clone()];
                for i in 0..d {
                    let mut v = best.clone();
                    v[i] = if v[i] > 0.5 { v[i] - step } else { v[i] + step };
                    simplex.push(v);
                }
                // Converged when the simplex's costs agree to a millionth of the cost itself.
                let tol = (1e-6 * problem(*base).cost_at(&best)).max(1e-18);
                let nm =
                    NelderMead::new(simplex).with_sd_tolerance(tol).map_err(|e| anyhow::anyhow!("{e}"))?;
                let res = bounded(Executor::new(problem(*base), nm), opts.deadline)
                    .configure(|s| s.max_iters(nm_iters))
                    .run()
                    .map_err(|e| anyhow::anyhow!("Nelder–Mead: {e}"))?;
                timed_out.fetch_or(ended_by_time(res.state()), Ordering::Relaxed);
                best = res.state().get_best_param().cloned().unwrap_or(best);
            }
            let c = problem(*base).cost_at(&best);
            Ok((*base, best, c))
        };
    let refined: Vec<(ActuatorParams, Vec<f64>, f64)> = seeds.par_iter().map(local).collect::<Result<_>>()?;
    let (base, best, _) = refined.into_iter().min_by(|a, b| a.2.total_cmp(&b.2)).expect("at least one seed");
    let mut params = problem(base).params_at(&best);
    scan_delay(&mut params);
    bar.finish_and_clear();
    let (_, lambda) = evaluate_projected(spec, &params, files)?;
    params.magnetostriction.lambda_s = lambda as f32;
    // Never hand back NaN or an invalid set: say the fit failed instead.
    model_core::Actuator::new(spec, &params).map_err(|e| {
        anyhow::anyhow!(
            "the fit ended on an invalid parameter set ({e}; λ_s = {lambda:e}): the model cannot follow \
             these recordings (check the drive and displacement columns and their units)"
        )
    })?;
    let fit = evaluate(spec, &params, files)?;
    if !fit.mean_nrmse().is_finite() {
        bail!("the fit found no parameter set whose simulation stays finite on these recordings");
    }
    let mut identified: Vec<(&'static str, f64)> = vec![("magnetostriction.lambda_s", lambda)];
    identified.extend(free.iter().map(|f| (f.name(), (f.get)(&params))));
    if delay_scan {
        identified.push(("delay_samples", params.delay_samples as f64));
    }
    Ok(FitResult {
        spec,
        params,
        identified,
        fit,
        evaluations: evals.load(Ordering::Relaxed),
        time_limited: timed_out.load(Ordering::Relaxed),
    })
}
