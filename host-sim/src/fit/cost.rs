//! The cost a fit minimises: every file run at a parameter set, the strain scale λ_s (and the
//! thermal share) solved in closed form, scored per file; the residual blocks of the
//! least-squares search.

use anyhow::Result;
use model_core::{ActuatorParams, Effect, ModelSpec};
use rayon::prelude::*;

use crate::recording::Recording;
use crate::score::{score, score_with_models, FileScore};
use crate::simulated::Simulation;
use crate::simulation::{at_rate_of, run_models, simulate, Prepared};

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
pub(super) fn projected_cost(
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
pub(super) const FAILED_COST: f64 = 1e3;

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

/// [`evaluate_projected`] with λ_s clamped to `lambda_range`.
pub(super) fn evaluate_projected_in(
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
pub(super) fn projected_residuals(
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
/// reported, stepped as the run steps (`Actuator::thermal_tail_step_ramp`: the current a ramp
/// between the run's samples).
fn thermal_share(
    spec: ModelSpec,
    params: &ActuatorParams,
    prep: &Prepared,
    sim: &Simulation,
) -> Result<Vec<f64>> {
    let p = at_rate_of(spec, params, prep)?;
    let model = crate::simulation::workbench_model(spec, &p).map_err(|e| anyhow::anyhow!("{e}"))?;
    let hold = model_core::FirstOrderHold::new(&model, p.dt_s);
    let mut s = model.thermal_tail_rest();
    let mut t = Vec::with_capacity(sim.current_a.len());
    t.push(0.0);
    t.extend(
        sim.current_a
            .windows(2)
            .map(|i| model.thermal_tail_step_ramp(&mut s, &hold, i[0] as f32, i[1] as f32) as f64 * 1e6),
    );
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
