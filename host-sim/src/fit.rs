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
use model_core::{Actuator, ActuatorParams, Effect, ModelSpec};
use rayon::prelude::*;

use crate::channels::FLUX_SCALE_RANGE;
use crate::params::multivalued_ja;
use crate::progress::{self, Progress};
use crate::recording::Recording;
use crate::score::{nrmse, score, score_with_models, FileScore};
use crate::search::{minimize, Bound, Fidelity, Found, Local, Plan, SearchOptions, Start};
use crate::simulated::Simulation;
use crate::simulation::{
    at_rate_of, estimate_excursion, excursion_range, model_input, prepare, run_models, simulate,
    starting_from, Drive, MagneticMemo, Prepared,
};
use crate::warning::Warning;

mod bad_samples;
mod free_params;
mod plausible;
mod start;
pub use bad_samples::{spikes, Spike};
pub use free_params::{free_params, logs_coil_temperature, FreeParam, Given};
pub use plausible::{check_files, check_physics, data_doubts, started_mid_run};
pub use start::StartScore;

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
            let channels =
                [Some(f.nrmse), f.nrmse_current, f.flux.map(|b| b.nrmse), f.temperature.map(|t| t.nrmse)];
            for e in channels.into_iter().flatten() {
                sum += e * e;
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

/// [`evaluate_projected`]'s cost (λ_s solved within `lambda`, or kept when `None`: `--fix`), or a
/// large finite number where the model cannot be run.
fn projected_cost(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
    lambda: Option<(f64, f64)>,
) -> f64 {
    let c = match lambda {
        Some(range) => evaluate_projected_in(spec, params, files, range).map(|e| e.0.cost()),
        None => evaluate_prepared(spec, params, files).map(|e| e.cost()),
    }
    .unwrap_or(FAILED_COST);
    if c.is_finite() {
        c
    } else {
        FAILED_COST
    }
}

/// The cost of a parameter set the model cannot run (far above any NRMSE²).
const FAILED_COST: f64 = 1e3;

/// Evaluates `params` with the strain scale λ_s chosen by linear least squares (variable
/// projection): the displacement is λ_s·g + t + offset, with g the magnetostrictive part and t the
/// thermal elongation, so λ_s and the per-file offsets have a closed form. This removes the
/// strongest scale ambiguity of the magnetization models (λ_s against M's scale) from the
/// nonlinear search. Returns the scores and that λ_s.
pub fn evaluate_projected(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
) -> Result<(Evaluation, f64)> {
    evaluate_projected_in(spec, params, files, LAMBDA_RANGE)
}

/// The range the closed-form λ_s is clamped to (without `--bound`).
pub const LAMBDA_RANGE: (f64, f64) = (1e-8, 1.0);

/// A λ_s the fit identified outside the physical range (the registry's for it, narrower than
/// [`LAMBDA_RANGE`], which only keeps the solve finite) is said: the strain scale is where a
/// displacement in the wrong unit lands. Nothing when λ_s was held (`--fix`).
pub fn strain_scale_doubt(params: &ActuatorParams, constraints: &Constraints) -> Option<Warning> {
    let lambda_s = params.magnetostriction.lambda_s as f64;
    let (lo, hi) = (STRAIN_SCALE.lo, STRAIN_SCALE.hi);
    (!constraints.is_fixed(STRAIN_SCALE.key) && !(lo..=hi).contains(&lambda_s))
        .then_some(Warning::StrainScaleUnlikely { lambda_s, lo, hi })
}

/// A mechanical mode that none of `files` can show (above each one's Nyquist frequency) is said:
/// the mechanics is then a static gain, and a time column in ms read as seconds lands there.
pub fn unresolved_mode<'a>(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Option<Warning> {
    if !spec.has(Effect::MechanicalDynamics) {
        return None;
    }
    mode_above_nyquist(params.mech.natural_frequency_hz as f64, false, files)
}

/// As [`unresolved_mode`] for the lowest mode the search tries: none can show in `files`, so
/// `diagnose` cannot judge mechanical dynamics there.
pub fn unsearchable_mode<'a>(files: impl IntoIterator<Item = &'a Recording>) -> Option<Warning> {
    let lowest = Effect::MechanicalDynamics.info().params.iter().find(|p| p.key == MODE_FREQUENCY)?.lo;
    mode_above_nyquist(lowest, true, files)
}

fn mode_above_nyquist<'a>(
    natural_frequency_hz: f64,
    lowest_searched: bool,
    files: impl IntoIterator<Item = &'a Recording>,
) -> Option<Warning> {
    let step_s = files.into_iter().map(Recording::dt_s).filter(|dt| *dt > 0.0).reduce(f64::min)?;
    let nyquist_hz = 0.5 / step_s;
    (natural_frequency_hz > nyquist_hz).then_some(Warning::ModeAboveNyquist {
        natural_frequency_hz,
        nyquist_hz,
        step_s,
        lowest_searched,
    })
}

/// [`evaluate_projected`] with λ_s clamped to `lambda_range`.
fn evaluate_projected_in(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
    lambda_range: (f64, f64),
) -> Result<(Evaluation, f64)> {
    let (sims, lambda) = projected_runs(spec, params, files, lambda_range)?;
    let scores = files.iter().zip(&sims).map(|(prep, sim)| score(spec, prep.rec, sim)).collect();
    Ok((Evaluation { files: scores }, lambda))
}

/// The runs of `params` on `files` with the displacement rescaled to the closed-form λ_s (clamped
/// to `lambda_range`), and that λ_s.
fn projected_runs(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
    lambda_range: (f64, f64),
) -> Result<(Vec<Simulation>, f64)> {
    let lambda_ref = params.magnetostriction.lambda_s as f64;
    let thermal = spec.has(Effect::ThermalDrift);
    // Per file: (g, t, simulation) with y = λ g + t.
    let parts: Vec<(Vec<f64>, Vec<f64>, Simulation)> = run_models(spec, params, files, false)?
        .into_par_iter()
        .zip(files)
        .map(|(sim_a, prep)| {
            let rec = prep.rec;
            if thermal {
                let t = thermal_share(spec, params, prep, &sim_a)?;
                let g = sim_a.displacement_um.iter().zip(&t).map(|(y, t)| (y - t) / lambda_ref).collect();
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
    for (prep, (g, t, _)) in files.iter().zip(&parts) {
        let y = prep.rec.displacement_um.as_deref().unwrap_or_default();
        let (lo, hi) = y.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        let w = 1.0 / (y.len() as f64 * (hi - lo).max(1e-12).powi(2));
        let target: Vec<f64> = y.iter().zip(t).map(|(a, b)| a - b).collect();
        for (a, b) in centred(&target).zip(centred(g)) {
            num += w * a * b;
            den += w * b * b;
        }
    }
    let lambda = if den > 0.0 { (num / den).clamp(lambda_range.0, lambda_range.1) } else { lambda_ref };
    let sims = parts
        .into_iter()
        .map(|(g, t, mut sim)| {
            sim.displacement_um = g.iter().zip(&t).map(|(g, t)| lambda * g + t).collect();
            sim
        })
        .collect();
    Ok((sims, lambda))
}

/// The residuals of the fit's cost at `params` (λ_s solved within `lambda`, or kept when `None`),
/// all blocks in one vector scaled so that its sum of squares is the cost; `None` where the model
/// cannot be run or leaves a non-finite residual.
fn projected_residuals(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
    lambda: Option<(f64, f64)>,
) -> Option<Vec<f64>> {
    let sims = match lambda {
        Some(range) => projected_runs(spec, params, files, range).ok()?.0,
        None => run_models(spec, params, files, false).ok()?,
    };
    let blocks: Vec<Vec<f64>> =
        files.iter().zip(&sims).flat_map(|(prep, sim)| blocks_of(spec, prep.rec, sim)).map(|b| b.1).collect();
    let w = 1.0 / (blocks.len().max(1) as f64).sqrt();
    let r: Vec<f64> = blocks.into_iter().flatten().map(|x| w * x).collect();
    r.iter().all(|x| x.is_finite()).then_some(r)
}

/// The coil-heating share [µm] of `sim`'s displacement (a run of `spec` at `params` on `prep`):
/// the thermal elongation through the mechanics and delay, driven by the currents the run
/// reported ([`Actuator::thermal_tail_step`]). Sample k's output follows the steps before it,
/// whose currents are the run's samples 1..=k.
fn thermal_share(
    spec: ModelSpec,
    params: &ActuatorParams,
    prep: &Prepared,
    sim: &Simulation,
) -> Result<Vec<f64>> {
    let p = at_rate_of(spec, params, prep)?;
    let model = Actuator::new(spec, &p).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut s = model.thermal_tail_rest();
    let mut t = Vec::with_capacity(sim.current_a.len());
    t.push(0.0);
    t.extend(sim.current_a.iter().skip(1).map(|&i| model.thermal_tail_step(&mut s, i as f32) as f64 * 1e6));
    Ok(t)
}

/// Scores `params` as they are (λ_s included; offsets in closed form) on prepared files.
fn evaluate_prepared(spec: ModelSpec, params: &ActuatorParams, files: &[Prepared]) -> Result<Evaluation> {
    let sims = run_models(spec, params, files, false)?;
    Ok(Evaluation {
        files: files.par_iter().zip(&sims).map(|(prep, sim)| score(spec, prep.rec, sim)).collect(),
    })
}

/// The residuals the fit's cost is made of, one block per file and channel (displacement with
/// its offset re-solved, then the current, the flux density and the temperature where [`score`]
/// scores them), each with the number of unknowns solved in closed form for it (displacement 1:
/// the offset; flux density 2: scale and zero; temperature 1: the ambient) and scaled by 1/(range·√n) so that the sum of squares over a
/// block is its NRMSE²: the cost ([`Evaluation::cost`]) is the mean of the blocks' sums of
/// squares.
pub fn residual_blocks(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Prepared],
) -> Result<Vec<(usize, Vec<f64>)>> {
    let sims = run_models(spec, params, files, false)?;
    let per_file: Vec<Vec<(usize, Vec<f64>)>> =
        files.par_iter().zip(&sims).map(|(prep, sim)| blocks_of(spec, prep.rec, sim)).collect();
    Ok(per_file.into_iter().flatten().collect())
}

/// [`residual_blocks`] of one file's run.
fn blocks_of(spec: ModelSpec, rec: &Recording, sim: &Simulation) -> Vec<(usize, Vec<f64>)> {
    fn scaled(measured: &[f64], model: impl Iterator<Item = f64>) -> Vec<f64> {
        let (lo, hi) = measured.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        let w = 1.0 / ((hi - lo).max(1e-12) * (measured.len() as f64).sqrt());
        measured.iter().zip(model).map(|(a, b)| w * (a - b)).collect()
    }
    let (s, models) = score_with_models(spec, rec, sim);
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    let mut blocks = vec![(1, scaled(meas, sim.displacement_um.iter().map(|y| y + s.offset_um)))];
    if s.nrmse_current.is_some() {
        let i = rec.current_a.as_deref().unwrap_or_default();
        blocks.push((0, scaled(i, sim.current_a.iter().copied())));
    }
    if let (Some(b), Some(model)) = (rec.flux_density_t.as_deref(), models.flux) {
        blocks.push((2, scaled(b, model.into_iter())));
    }
    if let (Some(t), Some(model)) = (rec.temperature_c.as_deref(), models.temperature) {
        blocks.push((1, scaled(t, model.into_iter())));
    }
    blocks
}

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

/// `gma fit --fix/--bound`: parameters held at their start value, and narrowed search ranges.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Constraints {
    /// Held at their start value: not searched, not reported as identified.
    pub fixed: Vec<&'static str>,
    /// Narrowed ranges (name, lo, hi), within the registry's.
    pub bounds: Vec<(&'static str, f64, f64)>,
}

/// Every parameter `spec` identifies on these files (λ_s first), with the registry's ranges.
pub fn identifiable(spec: ModelSpec, files: &[Recording]) -> Result<Vec<FreeParam>> {
    Ok(free_params(spec, given_by(spec, files)?))
}

/// What `files` give a fit of `spec`.
fn given_by(spec: ModelSpec, files: &[Recording]) -> Result<Given> {
    let command_driven = prepare(spec, files)?.iter().any(|p| p.drive != Drive::Current);
    Ok(Given::by(files, command_driven))
}

/// The parameters a fit of `spec` on `files` leaves at their start values because no file
/// constrains them ([`free_params::not_fitted`]), for the parameter file to mark.
pub fn not_fitted(spec: ModelSpec, files: &[Recording]) -> Result<Vec<&'static str>> {
    Ok(free_params::not_fitted(spec, given_by(spec, files)?))
}

/// A command-driven recording among `files` that `params` drive through an amplifier gain their
/// file (`source`) marks as not fitted.
pub fn unfitted_gain(
    spec: ModelSpec,
    params: &ActuatorParams,
    source: &crate::params::ParamSource,
    files: &[Recording],
) -> Option<Warning> {
    if !source.parameters_not_fitted.contains(&model_core::effects::AMPLIFIER_GAIN.key) {
        return None;
    }
    let rec = files.iter().find(|r| model_input(spec, r).is_ok_and(|d| d != Drive::Current))?;
    Some(Warning::UnfittedGain {
        file: rec.name.clone(),
        params: source.parameters_source.clone(),
        gain: params.amp.gain_a_per_v as f64,
    })
}

/// The recordings whose search-coil magnetization scale ended at an end of
/// [`FLUX_SCALE_RANGE`] (scored as `scores`, in order).
pub fn flux_scale_doubts(files: &[Recording], scores: &[FileScore]) -> Vec<Warning> {
    let (lo, hi) = FLUX_SCALE_RANGE;
    files
        .iter()
        .zip(scores)
        .filter_map(|(rec, s)| {
            let scale = s.flux?.scale;
            (scale <= lo || scale >= hi).then(|| Warning::FluxScaleAtBound { file: rec.name.clone(), scale })
        })
        .collect()
}

impl Constraints {
    /// Parses `--fix NAME[=VALUE]` and `--bound NAME=LO:HI` for `spec` on `files`; a fixed
    /// VALUE is written into `init`. Refuses (naming the option) unknown names, a name given
    /// twice, values outside the registry's range, and ranges that are empty or leave it: a
    /// bound only narrows.
    pub fn parse(
        spec: ModelSpec,
        files: &[Recording],
        fix: &[String],
        bound: &[String],
        init: &mut ActuatorParams,
    ) -> Result<Self> {
        let known = identifiable(spec, files)?;
        let names = || known.iter().map(|f| format!("`{}`", f.name())).collect::<Vec<_>>().join(", ");
        let find = |opt: &str, name: &str| -> Result<FreeParam> {
            let name = name.trim();
            known.iter().find(|f| f.name() == name).copied().ok_or_else(|| {
                anyhow::anyhow!(
                    "{opt} {}: model `{spec}` identifies no such parameter on these files (it identifies {})",
                    crate::files::echo(name),
                    names()
                )
            })
        };
        let number = |opt: &str, what: &str, text: &str| -> Result<f64> {
            text.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                anyhow::anyhow!("{opt} {what}: `{}` is not a number", crate::files::echo(text.trim()))
            })
        };
        let mut c = Constraints::default();
        let mut seen: Vec<&'static str> = Vec::new();
        let mut once = |opt: &str, name: &'static str| -> Result<()> {
            if seen.contains(&name) {
                bail!("{opt} {name}: `{name}` is already fixed or bounded (give each parameter one --fix or --bound)");
            }
            seen.push(name);
            Ok(())
        };
        for arg in fix {
            let (name, value) = match arg.split_once('=') {
                Some((n, v)) => (n, Some(v)),
                None => (arg.as_str(), None),
            };
            let f = find("--fix", name)?;
            once("--fix", f.name())?;
            if let Some(text) = value {
                let v = number("--fix", f.name(), text)?;
                let b = f.bound;
                if !(b.lo..=b.hi).contains(&v) {
                    bail!("--fix {}={v}: outside its range [{}, {}]", f.name(), b.lo, b.hi);
                }
                (f.set)(init, v);
                // Inside its own range, but it may not fit the file's other values.
                if let Err(e) = Actuator::new(spec, init) {
                    bail!("--fix {}={v}: with the start set's other values: {e}", f.name());
                }
            }
            c.fixed.push(f.name());
        }
        for arg in bound {
            let Some((name, range)) = arg.split_once('=') else {
                bail!("--bound {}: expected NAME=LO:HI", crate::files::echo(arg));
            };
            let f = find("--bound", name)?;
            once("--bound", f.name())?;
            let Some((lo, hi)) = range.split_once(':') else {
                bail!("--bound {}: expected NAME=LO:HI, got `{}`", f.name(), crate::files::echo(range));
            };
            let (lo, hi) = (number("--bound", f.name(), lo)?, number("--bound", f.name(), hi)?);
            let b = f.bound;
            if lo >= hi {
                bail!(
                    "--bound {}={lo}:{hi}: empty range (LO must be below HI; to hold a value use --fix)",
                    f.name()
                );
            }
            if lo < b.lo || hi > b.hi {
                bail!(
                    "--bound {}={lo}:{hi}: leaves the parameter's range [{}, {}] (a bound can only narrow it)",
                    f.name(),
                    b.lo,
                    b.hi
                );
            }
            // The start is moved into the range: it may not fit the file's other values there.
            let mut moved = *init;
            let narrowed = Bound { lo, hi, ..b };
            let used = narrowed.from_unit(narrowed.to_unit((f.get)(init)));
            (f.set)(&mut moved, used);
            if let Err(e) = Actuator::new(spec, &moved) {
                bail!("--bound {}={lo}:{hi}: the start value moved into it, {used:.4e}, with the start set's other values: {e}", f.name());
            }
            c.bounds.push((f.name(), lo, hi));
        }
        Ok(c)
    }

    /// Whether `name` is held fixed.
    pub fn is_fixed(&self, name: &str) -> bool {
        self.fixed.contains(&name)
    }

    /// `b` narrowed by a `--bound` on its parameter.
    pub fn narrow(&self, b: Bound) -> Bound {
        match self.bounds.iter().find(|(n, _, _)| *n == b.name) {
            Some(&(_, lo, hi)) => Bound { lo, hi, ..b },
            None => b,
        }
    }
}

/// The mechanical mode's parameters, which a mode seen in the data starts (see `resonance`).
const MODE_FREQUENCY: &str = "mech.natural_frequency_hz";
const MODE_DAMPING: &str = "mech.damping_ratio";

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
    // Through no more samples than unknowns any model passes: the "fit" would report values and
    // a tiny error that the data do not determine. λ_s and each file's offset are unknowns too.
    let samples: usize = files.iter().map(|r| r.len()).sum();
    let unknowns = dims + usize::from(lambda_range.is_some()) + files.len();
    if samples <= unknowns {
        bail!(
            "{samples} samples in all ({}) for {unknowns} unknowns of `{spec}` ({d} free parameters{}, {} per file): \
             a fit through no more samples than unknowns is not determined by them; record more samples (thousands: \
             a drive cycle at the rig's rate), raise --max-samples or drop --trim-start if they cut the files, or \
             hold parameters with --fix",
            files.iter().map(|r| format!("{}: {}", r.name, r.len())).collect::<Vec<_>>().join(", "),
            if lambda_range.is_some() { ", λ_s" } else { "" },
            if memory { "an initial magnetic state and an offset" } else { "an offset" },
        );
    }
    // The progress bar's length: the swarm, then per seed the plan's simplex and least-squares
    // runs (and one more least-squares run each in the polish).
    let swarm_iters = ((plan.swarm_iters * opts.effort).round() as u64).max(2);
    let nm_iters = ((plan.simplex_iters_per_dim * dims as f64 * opts.effort).round() as u64).max(20);
    let least_squares = crate::search::least_squares_evaluations(dims, opts.effort);
    let per_seed: u64 = plan
        .local
        .iter()
        .map(|run| match run {
            Local::Simplex(..) => nm_iters,
            Local::LeastSquares(_) => least_squares,
        })
        .sum();
    // A lightly damped mechanical mode is a narrow valley the swarm can miss: each start also
    // with the mode the data's frequency response shows, where it shows one (see `resonance`),
    // the best of them refined by a local search of its own.
    let seen_mode = free
        .iter()
        .any(|f| f.name() == MODE_FREQUENCY || f.name() == MODE_DAMPING)
        .then(|| crate::resonance::seen_mode(files))
        .flatten();
    let seeds = plan.local_searches as u64 + u64::from(seen_mode.is_some());
    let planned = plan.swarms as u64 * (plan.particles.0 + plan.particles.1 * d) as u64 * (swarm_iters + 1)
        + seeds * per_seed
        + if memory { POLISH.local_searches as u64 * least_squares } else { 0 };
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
    let starts: Vec<(ActuatorParams, bool)> = match &seen_mode {
        Some(mode) => {
            let at_mode = starts.iter().map(|st| {
                let mut p = *st;
                for f in &free {
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
    };
    let mode_indices: Vec<usize> = free
        .iter()
        .enumerate()
        .filter(|(_, f)| f.name() == MODE_FREQUENCY || f.name() == MODE_DAMPING)
        .map(|(k, _)| k)
        .collect();
    // The user's start values outside the ranges, said rather than clamped in silence.
    let start_moved: Vec<Warning> = free
        .iter()
        .filter_map(|f| {
            let given = (f.get)(&starts[0].0);
            let used = f.from_unit(f.to_unit(given));
            ((given - used).abs() > 1e-6 * given.abs().max(f64::MIN_POSITIVE)).then_some(
                Warning::StartMoved { param: f.name(), given, used, lo: f.bound.lo, hi: f.bound.hi },
            )
        })
        .collect();
    // Start points: the fixed parameters come from the first; each start's identified values
    // are clamped into the bounds.
    let bases: Vec<Start<ActuatorParams>> = starts
        .iter()
        .map(|&(st, always_refined)| {
            let mut b = starts[0].0;
            for f in &free {
                (f.set)(&mut b, f.from_unit(f.to_unit((f.get)(&st))));
            }
            let excursions: Vec<f64> = if memory {
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
    // Each start also as the model's own rest state (every file demagnetised): an estimate made
    // at poor start values can be further from the truth than that.
    let bases: Vec<Start<ActuatorParams>> = if memory {
        let rest = bases.iter().map(|b| Start {
            values: b.values[..d].iter().copied().chain(std::iter::repeat_n(0.0, n_excursions)).collect(),
            context: b.context,
            always_refined: b.always_refined,
            simplex_holds: b.simplex_holds.clone(),
        });
        bases.iter().cloned().chain(rest).collect()
    } else {
        bases
    };
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
    let with_lambda = |mut p: ActuatorParams, data: &[Prepared]| -> Result<ActuatorParams> {
        let lambda = match lambda_range {
            Some(range) => evaluate_projected_in(spec, &p, data, range)?.1,
            None => p.magnetostriction.lambda_s as f64,
        };
        p.magnetostriction.lambda_s = lambda as f32;
        Ok(p)
    };
    params = with_lambda(params, &found_start)?;
    // The first start, as the search began from it: scored on all files (NRMSE as reported).
    let start_params = bases[0].context;
    let start_score = match multivalued_ja(spec, &start_params) {
        Some(why) => Err(why),
        None => with_lambda(start_params, &full)
            .and_then(|p| Ok((evaluate(spec, &p, files)?.mean_nrmse(), p)))
            .map_err(|e| format!("the model cannot be run there: {e}")),
    };
    let mut kept = false;
    if let Ok((start_nrmse, start_set)) = &start_score {
        let found_nrmse = evaluate(spec, &params, files).map(|e| e.mean_nrmse()).unwrap_or(f64::NAN);
        if start_nrmse.is_finite() && (found_nrmse.is_nan() || found_nrmse > *start_nrmse) {
            kept = true;
            params = *start_set;
        }
    }
    if let Some(why) = multivalued_ja(spec, &params) {
        bail!("the fit is refused: {why}; --fix or --bound `ja.alpha`/`ja.a_a_per_m` so that α·M_s/(3a) < 1");
    }
    let lambda = params.magnetostriction.lambda_s as f64;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channels::MU0;
    use crate::score::{flux_fit, temperature_fit};
    use crate::simulation::{field_reach, preisach_plane_advice, run_model, InitialState};

    /// The seen mode is written into the parameters by these names: a registry rename must not
    /// switch it off unnoticed.
    #[test]
    fn the_mode_parameters_are_the_registrys() {
        let names: Vec<&str> =
            free_params(ModelSpec::LINEAR.with(model_core::Effect::MechanicalDynamics), Given::default())
                .iter()
                .map(|f| f.name())
                .collect();
        assert!(names.contains(&MODE_FREQUENCY) && names.contains(&MODE_DAMPING), "{names:?}");
    }

    #[test]
    fn a_preisach_plane_far_wider_than_the_fields_reached_is_said() {
        let mut rec = Recording::with_time("r.csv", 4, 1e-4);
        rec.current_a = Some(vec![0.0, 1.0, -2.0, 0.5]);
        let mut p = ActuatorParams::TERFENOL_DEMO;
        (p.coil.turns_per_m, p.coil.bias_a_per_m) = (10_000.0, 5_000.0);
        // |5 000 + 10 000 i|: the largest field is at i = −2 A.
        assert_eq!(field_reach(&p, std::slice::from_ref(&rec)), Some(15_000.0));
        let preisach = ModelSpec::parse("preisach").expect("spec");
        p.preisach.h_max_a_per_m = 80_000.0;
        match preisach_plane_advice(preisach, &p, std::slice::from_ref(&rec)) {
            Some(Warning::PreisachPlaneWide { advised, .. }) => assert_eq!(advised, 1.25 * 15_000.0),
            other => panic!("{other:?}"),
        }
        assert_eq!(preisach_plane_advice(ModelSpec::parse("ja").expect("spec"), &p, &[rec.clone()]), None);
        p.preisach.h_max_a_per_m = 20_000.0;
        assert_eq!(preisach_plane_advice(preisach, &p, &[rec.clone()]), None);
        // Without a current, the command through the amplifier's gain.
        (rec.current_a, rec.command_v, p.amp.gain_a_per_v) = (None, Some(vec![0.0, 3.0]), 2.0);
        assert_eq!(field_reach(&p, &[rec]), Some(65_000.0));
    }
    use crate::excitation::Excitation;
    use crate::plant::Plant;

    /// Levenberg–Marquardt minimises the sum of squares of [`projected_residuals`], the simplex
    /// and every report [`projected_cost`]: they must be the same number, with the current
    /// channel scored, coil heating split off and λ_s solved or kept, away from the truth.
    #[test]
    fn the_residuals_square_to_the_cost() {
        let spec = ModelSpec::parse("amp+ja+mech+thermal").unwrap();
        let truth = ActuatorParams::TERFENOL_DEMO;
        let rig = Plant::new(spec, truth);
        let files: Vec<Recording> = [(30.0, 1.5, 0), (120.0, 1.0, 1)]
            .iter()
            .map(|&(f, a, seed)| {
                rig.record(
                    &format!("f{seed}"),
                    &Excitation::Sine { freq_hz: f, amplitude: a, bias: 0.2 },
                    0.1,
                    seed,
                )
                .unwrap()
            })
            .collect();
        assert!(files.iter().all(|r| r.current_a.is_some()), "the rig logs the current");
        // A search coil on the second file: its block enters the cost like the others.
        let mut files = files;
        let sim = simulate(spec, &truth, &files[1]).unwrap();
        files[1].flux_density_t = Some(
            sim.field_a_per_m
                .iter()
                .zip(&sim.magnetization_a_per_m)
                .map(|(h, m)| MU0 * (h + 1.1 * m) - 0.4)
                .collect(),
        );
        let prepared = prepare(spec, &files).unwrap();
        let mut off = truth;
        off.ja.a_a_per_m *= 1.3;
        off.mech.natural_frequency_hz *= 0.8;
        for lambda in [Some(LAMBDA_RANGE), None] {
            let cost = projected_cost(spec, &off, &prepared, lambda);
            let r = projected_residuals(spec, &off, &prepared, lambda).expect("the model runs");
            let squares: f64 = r.iter().map(|x| x * x).sum();
            assert!(cost > 1e-6, "the point is off the truth (cost {cost})");
            assert!((squares - cost).abs() <= 1e-9 * cost, "λ_s {lambda:?}: Σr² = {squares}, cost = {cost}");
        }
        let blocks = residual_blocks(spec, &off, &prepared).unwrap();
        assert_eq!(
            blocks.iter().map(|b| b.0).collect::<Vec<_>>(),
            [1, 0, 1, 0, 2],
            "blocks and their unknowns"
        );
    }

    /// A run through the memo is the run without it, bit for bit: after a change of the
    /// mechanical stages only (kept magnetic run reused) and after a change of each magnetic
    /// stage (a new run; reusing the kept one would leave the displacement as it was).
    #[test]
    fn runs_through_the_magnetic_memo_are_the_runs_without_it() {
        let spec = ModelSpec::parse("amp+eddy+ja+mech+thermal+delay+aftereffect").unwrap();
        let truth = ActuatorParams::TERFENOL_DEMO;
        let rec = Plant::new(spec, truth)
            .record("f", &Excitation::Sine { freq_hz: 150.0, amplitude: 1.0, bias: 0.2 }, 0.05, 3)
            .unwrap();
        let memo = MagneticMemo::default();
        let bare = Prepared::new(spec, &rec).unwrap().starting(InitialState::Excursion(4000.0));
        let kept = Prepared { memo: Some(&memo), ..bare };
        let mut mechanical = truth;
        mechanical.mech.natural_frequency_hz *= 0.9;
        mechanical.mech.damping_ratio *= 1.2;
        mechanical.magnetostriction.lambda_s *= 1.1;
        mechanical.thermal.tau_s *= 0.5;
        mechanical.delay_samples = 1.5;
        let magnetic: [fn(&mut ActuatorParams); 5] = [
            |p| p.ja.k_a_per_m *= 1.05,
            |p| p.ja.alpha *= 0.9,
            |p| p.eddy_tau_s *= 2.0,
            |p| p.amp.tau_s *= 2.0,
            |p| p.aftereffect.fraction *= 2.0,
        ];
        let bits = |sim: &Simulation| -> Vec<u64> {
            [&sim.displacement_um, &sim.current_a, &sim.field_a_per_m, &sim.magnetization_a_per_m]
                .iter()
                .flat_map(|v| v.iter().map(|x| x.to_bits()))
                .collect()
        };
        let mut sets = vec![truth, mechanical];
        for change in magnetic {
            let mut p = mechanical;
            change(&mut p);
            sets.push(p);
        }
        let first = bits(&run_model(spec, &truth, &kept, true).unwrap());
        for p in &sets {
            let through = bits(&run_model(spec, p, &kept, true).unwrap());
            let without = bits(&run_model(spec, p, &bare, true).unwrap());
            assert!(through == without, "{p:?}: the memo changed the run");
            assert!(p == &truth || through != first, "{p:?}: the change did not show in the run");
        }
        // The mechanical change reused the kept run; each magnetic one kept a run of its own.
        assert_eq!(memo.kept(), 1 + magnetic.len());
    }

    /// The sensor delay is a time: a parameter set counts it in periods of its own `dt_s`, and a
    /// recording logged at another rate gets the same delay in seconds. Two recordings of one
    /// rig (0.4 ms delay) at 10 kHz and 4 kHz are both explained by the 10 kHz set; read as
    /// samples of each file (0.4 ms at 10 kHz, 1 ms at 4 kHz) the slower one is not.
    #[test]
    fn a_delay_counted_at_the_parameters_rate_holds_at_another_rate() {
        let spec = ModelSpec::parse("ja+delay").unwrap();
        let at = |dt_s: f32, delay_samples: f32| ActuatorParams {
            dt_s,
            delay_samples,
            ..ActuatorParams::TERFENOL_DEMO
        };
        let record = |p: ActuatorParams| {
            let mut rig = Plant::new(spec, p);
            rig.noise_um = 0.0;
            rig.record("d", &Excitation::Sine { freq_hz: 60.0, amplitude: 1.0, bias: 0.2 }, 0.1, 0).unwrap()
        };
        let fast = record(at(1e-4, 4.0));
        let slow = record(at(2.5e-4, 1.6));
        let nrmse = |p: ActuatorParams, rec: &Recording| {
            evaluate(spec, &p, std::slice::from_ref(rec)).unwrap().mean_nrmse()
        };
        let (on_fast, on_slow) = (nrmse(at(1e-4, 4.0), &fast), nrmse(at(1e-4, 4.0), &slow));
        let as_file_samples = nrmse(at(2.5e-4, 4.0), &slow);
        // The 4 kHz file against its own rig's parameters: the model's discretisation error there.
        let own = nrmse(at(2.5e-4, 1.6), &slow);
        assert!(
            on_fast < 2e-3 && (on_slow - own).abs() < 1e-5,
            "one set for both rates: {on_fast}, {on_slow} ({own})"
        );
        assert!(as_file_samples > 5.0 * on_slow.max(1e-3), "4 samples of the 4 kHz file: {as_file_samples}");
        // A delay the faster recording's line cannot hold is refused, naming the file and the times.
        let e = evaluate(spec, &at(2.5e-4, 40.0), std::slice::from_ref(&fast)).unwrap_err().to_string();
        assert!(e.contains("sensor delay") && e.contains("10.000 ms") && e.contains("100.0 samples"), "{e}");
    }

    /// The flux density's scale and zero come out in closed form: exact for a flux the model
    /// explains up to them, the NRMSE of what it does not explain otherwise.
    #[test]
    fn the_flux_fit_solves_the_magnetization_scale_and_the_integrators_zero() {
        let h: Vec<f64> = (0..400).map(|k| 20e3 + 15e3 * (k as f64 * 0.05).sin()).collect();
        let m: Vec<f64> = h.iter().map(|h| 7e5 * (h / 9e3).tanh()).collect();
        let b: Vec<f64> = h.iter().zip(&m).map(|(h, m)| MU0 * (h + 0.85 * m) + 0.12).collect();
        let (f, model) = flux_fit(&b, &h, &m);
        assert!((f.scale - 0.85).abs() < 1e-9 && (f.offset_t - 0.12).abs() < 1e-9, "{f:?}");
        assert!(f.nrmse < 1e-9 && model.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-9));
        // What the model lacks stays in the residual: M three samples late.
        let late: Vec<f64> = (0..400usize).map(|k| m[k.saturating_sub(3)]).collect();
        let (g, _) = flux_fit(&b, &h, &late);
        assert!(g.nrmse > 1e-3, "{g:?}");
        // A flux that does not follow M at all: the scale stops at its range, never negative.
        let upside_down: Vec<f64> = b.iter().map(|v| -v).collect();
        assert_eq!(flux_fit(&upside_down, &h, &m).0.scale, FLUX_SCALE_RANGE.0);
    }

    /// The logged temperature's ambient comes out in closed form; without a rise (a model
    /// without coil heating) the model is that constant and the whole variation is error.
    #[test]
    fn the_temperature_fit_solves_the_ambient() {
        let rise: Vec<f64> = (0..500).map(|k| 0.4 * (1.0 - (-(k as f64) / 300.0).exp())).collect();
        let logged: Vec<f64> = rise.iter().map(|r| 23.5 + r).collect();
        let (f, model) = temperature_fit(&logged, &rise);
        assert!((f.ambient_c - 23.5).abs() < 1e-9 && f.nrmse < 1e-9, "{f:?}");
        assert!(model.iter().zip(&logged).all(|(a, b)| (a - b).abs() < 1e-9));
        let (none, flat) = temperature_fit(&logged, &[]);
        let mean = logged.iter().sum::<f64>() / logged.len() as f64;
        assert!((none.ambient_c - mean).abs() < 1e-9 && flat.iter().all(|t| *t == none.ambient_c));
        assert!(none.nrmse > 0.2, "{none:?}");
    }
}
