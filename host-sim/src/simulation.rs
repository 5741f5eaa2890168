//! Running a model over a recording: how each file drives the model (current, command or
//! field), the file's initial magnetic state, its sample period, and the run itself
//! ([`run_model`], two files' runs interleaved on one thread in [`run_models`]). The fit, the
//! uncertainty, the diagnosis and `gma simulate` all run models through here.

use std::sync::Arc;

use anyhow::Result;
use model_core::{ActuatorParams, Effect, MagnetizationLaw, ModelSpec};

use crate::error::InRecording;
use crate::recording::Recording;
use crate::score::score;
use crate::simulated::Simulation;
use crate::warning::Warning;

mod magnetic_memo;
pub mod noisy_drive;
mod runs;
pub use magnetic_memo::MagneticMemo;
pub use runs::{run_model, run_models};

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
        return Err(rec.no_displacement_error());
    };
    let span =
        |v: &[f64]| v.iter().fold(f64::MIN, |a, &b| a.max(b)) - v.iter().fold(f64::MAX, |a, &b| a.min(b));
    if span(y) <= 0.0 {
        return Err(InRecording::error(
            &rec.name,
            "the displacement never changes: there is nothing to fit (sensor unplugged or stuck?)",
        ));
    }
    if span(y) < MIN_DISPLACEMENT_SPAN_UM {
        return Err(InRecording::error(
            &rec.name,
            format!(
                "the displacement spans only {:.3e} µm, below any sensor's resolution ({MIN_DISPLACEMENT_SPAN_UM:e} µm): \
                 is `displacement_um` in micrometres?",
                span(y)
            ),
        ));
    }
    // The column the model is driven by (`command_V` with an amplifier model, though the file
    // has `current_A`), then those it is scored on: a constant one has no span for its NRMSE.
    let drive = model_input(spec, rec)?;
    let input = match drive {
        Drive::Current => rec.current_a.as_deref(),
        Drive::CommandIdeal | Drive::CommandDynamic => rec.command_v.as_deref(),
    };
    if span(input.unwrap_or_default()) <= 0.0 {
        return Err(InRecording::error(
            &rec.name,
            format!(
                "the drive column `{}` never changes: the model's response cannot be identified",
                drive.column()
            ),
        ));
    }
    let scored = [
        ("current_A", rec.current_a.as_deref().filter(|_| drive == Drive::CommandDynamic)),
        ("flux_density_T", rec.flux_density_t.as_deref()),
        ("temperature_C", rec.temperature_c.as_deref().filter(|_| spec.has(Effect::ThermalDrift))),
    ];
    if let Some((column, _)) = scored.iter().find(|(_, v)| v.is_some_and(|v| span(v) <= 0.0)) {
        return Err(InRecording::error(
            &rec.name,
            format!(
                "`{column}` never changes, and the model is scored on it: a constant channel has no span for \
                 its NRMSE (sensor unplugged or stuck?); leave the column out of the file if it carries nothing"
            ),
        ));
    }
    Ok(drive)
}

/// Which of `rec`'s columns drives `spec`: `command_V` through the amplifier dynamics when the
/// model has `amp`; otherwise the measured `current_A`, or, without it, `command_V` through the
/// ideal amplifier (gain `amp.gain_a_per_v`).
pub fn model_input(spec: ModelSpec, rec: &Recording) -> Result<Drive> {
    if spec.has(Effect::AmplifierDynamics) {
        if rec.command_v.is_none() {
            return Err(InRecording::error(
                &rec.name,
                "the model has amplifier_dynamics, which needs a `command_V` column",
            ));
        }
        Ok(Drive::CommandDynamic)
    } else if rec.current_a.is_some() {
        Ok(Drive::Current)
    } else if rec.command_v.is_some() {
        Ok(Drive::CommandIdeal)
    } else {
        Err(InRecording::error(&rec.name, "no drive column: the model needs `current_A` or `command_V`"))
    }
}

impl Drive {
    /// The column that carries this drive.
    pub fn column(self) -> &'static str {
        match self {
            Drive::Current => "current_A",
            Drive::CommandIdeal | Drive::CommandDynamic => "command_V",
        }
    }
}

/// How much finer than the board the workbench integrates a hysteresis law
/// ([`model_core::Actuator::with_finer_hysteresis`]): the board's sub-step of min(a/4, k/2),
/// corrected to second order ([`model_core::Actuator::with_second_order_hysteresis`]). Explicit
/// at that size the law left held 0.8 A steps 38× their noise floor off a continuous-time rig
/// and fast files 4–8×; corrected, 3× and 2× (docs/validation.md#forward-fidelity), at a
/// quarter more time per evaluation. 4× finer explicit steps gave less (4.5× and 2–3×) for 2.2×
/// the time.
pub const HYSTERESIS_REFINEMENT: u32 = 1;

/// The model the workbench runs for `spec` at `params` (the board's, its hysteresis law
/// integrated [`HYSTERESIS_REFINEMENT`] times finer and to second order): one stepping for the
/// fit, `simulate` and the plant.
pub fn workbench_model(
    spec: ModelSpec,
    params: &ActuatorParams,
) -> Result<model_core::Actuator, model_core::ParamError> {
    Ok(model_core::Actuator::new(spec, params)?
        .with_finer_hysteresis(HYSTERESIS_REFINEMENT)
        .with_second_order_hysteresis())
}

/// The rod's magnetic state when a recording starts. A rod on a rig has a history the file does
/// not show; with a hysteretic law it shifts the whole record (minor loops never wipe it out),
/// so it is estimated per file, like the displacement offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InitialState {
    /// At rest at the first drive, the rod demagnetised at its field (no excursion).
    Demagnetized,
    /// At rest at the first drive after a field excursion of this [A/m] from its field and
    /// back ([`model_core::Actuator::rest_state_at`]).
    Excursion(f64),
    /// The excursion that best explains the file's displacement (laws without memory: none).
    Estimated,
}

/// A recording ready to be simulated: its sample period and drive worked out once (a fit
/// evaluates the model thousands of times on the same files).
#[derive(Debug, Clone)]
pub struct Prepared<'a> {
    /// The recording.
    pub rec: &'a Recording,
    /// Its sample period [s] (median step).
    pub dt_s: f64,
    /// How it drives the model.
    pub drive: Drive,
    /// The magnetic state it starts from.
    pub initial: InitialState,
    /// Where the magnetic stages' recent runs on it are kept (within one fit), if anywhere.
    pub memo: Option<&'a MagneticMemo>,
    /// The logged current's white-noise rms [A] (0 for a command drive): its turns within
    /// [`noisy_drive::REVERSAL_IN_NOISE_RMS`] of it are not reversals of the field.
    pub drive_noise_a: f64,
    /// The held current turns back within that noise somewhere (else, without an eddy lag
    /// between, the field does not either and a run needs no branches: decided once per file,
    /// not at every evaluation).
    pub drive_turns_in_noise: bool,
    /// The logged current smoothed to its noise ([`noisy_drive::denoised`]): what drives the
    /// model, the rod having seen the true current; `None` drives it with the logged current
    /// (a command drive, no noise, or no smoothing that helps).
    pub drive_estimate: Option<Arc<[f64]>>,
}

impl<'a> Prepared<'a> {
    /// Checks that `spec` can be simulated on `rec` and works out its period and drive.
    /// The initial state is estimated from the displacement.
    pub fn new(spec: ModelSpec, rec: &'a Recording) -> Result<Self> {
        let drive = drive_for(spec, rec)?;
        Ok(Self::with(rec, drive, InitialState::Estimated))
    }

    /// `rec` driving through `drive` from `initial`, without a memo.
    fn with(rec: &'a Recording, drive: Drive, initial: InitialState) -> Self {
        let (mut drive_noise_a, mut drive_turns_in_noise, mut drive_estimate) = (0.0, false, None);
        if let (Drive::Current, Some(i)) = (drive, &rec.current_a) {
            (drive_noise_a, drive_estimate) = noisy_drive::read(i);
            let path = drive_estimate.as_deref().unwrap_or(i);
            drive_turns_in_noise =
                runs::turns_within(path, noisy_drive::REVERSAL_IN_NOISE_RMS * drive_noise_a);
        }
        Self {
            rec,
            dt_s: rec.dt_s(),
            drive,
            initial,
            memo: None,
            drive_noise_a,
            drive_turns_in_noise,
            drive_estimate,
        }
    }

    /// `head` (the first samples of this recording), with this one's drive (and no memo: the
    /// runs on the whole recording are not the head's).
    pub(crate) fn head_of<'b>(&self, head: &'b Recording) -> Prepared<'b> {
        Prepared { rec: head, dt_s: head.dt_s(), memo: None, ..self.clone() }
    }

    /// This recording started from `initial`.
    pub fn starting(&self, initial: InitialState) -> Self {
        Self { initial, ..self.clone() }
    }
}

/// Prepares every file.
pub fn prepare(spec: ModelSpec, files: &[Recording]) -> Result<Vec<Prepared<'_>>> {
    files.iter().map(|r| Prepared::new(spec, r)).collect()
}

/// Runs `spec` with `params` over `rec`. Simultaneous sampling, as a rig records: row k holds
/// the drive and the displacement at the same instant t_k, so the model output at k is its state
/// after integrating the drive up to t_k.
pub fn simulate(spec: ModelSpec, params: &ActuatorParams, rec: &Recording) -> Result<Simulation> {
    run_model(spec, params, &Prepared::new(spec, rec)?, true)
}

/// Runs `spec` with `params` over the drive of `rec` (which needs no displacement column; the
/// drive column as [`model_input`] picks it), at the file's own sample period.
pub fn simulate_drive(
    spec: ModelSpec,
    params: &ActuatorParams,
    rec: &Recording,
    initial: InitialState,
) -> Result<(Simulation, Drive)> {
    // Nothing measured to estimate a pre-history from: the state given (compare's estimate), or
    // the model's own rest state.
    let prep = Prepared::with(rec, model_input(spec, rec)?, initial);
    // Every channel: `gma simulate` writes the field and magnetization as a search coil's flux.
    Ok((run_model(spec, params, &prep, true)?, prep.drive))
}

/// `params` stepped at `prep`'s sample period. Every stage is stated in seconds or hertz except
/// the sensor delay, which `delay_samples` counts in periods of the parameter set's own `dt_s`:
/// a recording at another rate gets the same delay in seconds, in its own samples (a probe's
/// delay is a time, whatever rate the file was logged at). Periods equal to f32 precision leave
/// the parameter as it is.
pub(crate) fn at_rate_of(
    spec: ModelSpec,
    params: &ActuatorParams,
    prep: &Prepared,
) -> Result<ActuatorParams> {
    let mut p = *params;
    p.dt_s = prep.dt_s as f32;
    let ratio = params.dt_s as f64 / prep.dt_s;
    if spec.has(Effect::SensorDelay) && (ratio - 1.0).abs() > 1e-5 {
        let samples = params.delay_samples as f64 * ratio;
        let line = model_core::chain::MAX_DELAY_SAMPLES as f64;
        if samples >= line {
            return Err(InRecording::error(
                &prep.rec.name,
                format!(
                    "the sensor delay, delay_samples = {} at the parameters' dt_s ({:.4} ms), is {:.3} ms: \
                     {samples:.1} samples of this recording ({:.4} ms per sample); the delay line holds fewer \
                     than {line}",
                    params.delay_samples,
                    params.dt_s as f64 * 1e3,
                    params.delay_samples as f64 * params.dt_s as f64 * 1e3,
                    prep.dt_s * 1e3
                ),
            ));
        }
        p.delay_samples = samples as f32;
    }
    Ok(p)
}

/// The range of pre-history excursions searched [A/m]: ± ten times the J–A field scales
/// (a + k; saturated beyond), ± the Preisach plane's extent.
pub fn excursion_range(spec: ModelSpec, params: &ActuatorParams) -> f64 {
    match spec.law() {
        model_core::MagnetizationLaw::Preisach => params.preisach.h_max_a_per_m as f64,
        _ => 10.0 * (params.ja.a_a_per_m + params.ja.k_a_per_m) as f64,
    }
    .max(1000.0)
}

/// The largest field the recordings drive the rod to [A/m]: |bias + n·i| over every sample, i
/// the measured current, else the command through the amplifier's gain (`None` without either).
pub fn field_reach(params: &ActuatorParams, files: &[Recording]) -> Option<f64> {
    let (n, bias) = (params.coil.turns_per_m as f64, params.coil.bias_a_per_m as f64);
    let gain = params.amp.gain_a_per_v as f64;
    let fields = files.iter().flat_map(|r| match (&r.current_a, &r.command_v) {
        (Some(i), _) => i.iter().map(|&i| bias + n * i).collect::<Vec<_>>(),
        (None, Some(u)) => u.iter().map(|&u| bias + n * gain * u).collect(),
        (None, None) => Vec::new(),
    });
    fields.map(f64::abs).fold(None, |m: Option<f64>, h| Some(m.map_or(h, |m| m.max(h))))
}

/// A Preisach plane wider than this many times the fields reached is said to waste its levels.
const PLANE_WIDE: f64 = 1.5;
/// The plane extent advised: the largest field reached, with a quarter's margin.
pub const PLANE_MARGIN: f64 = 1.25;

/// With the Preisach law, a parameter set whose relay plane (±`h_max_a_per_m`) reaches far beyond
/// the fields the recordings drive the rod to: its 32 levels then resolve 2 H_max/31, most of it
/// where the data never go (on both independent rigs the complete structure validated better
/// with the plane at 1.25× the fields reached than at the demo set's 80 kA/m: 4.14 / 4.20 →
/// 2.80 / 2.87 % and 1.02 → 0.92 %). Displacement fits hold H_max as given (searched, it moved
/// the searches into worse basins on both rigs), so it is said, with the value to set.
pub fn preisach_plane_advice(
    spec: ModelSpec,
    params: &ActuatorParams,
    files: &[Recording],
) -> Option<Warning> {
    if spec.law() != MagnetizationLaw::Preisach {
        return None;
    }
    let reach = field_reach(params, files)?;
    let h_max = params.preisach.h_max_a_per_m as f64;
    (reach > 0.0 && h_max > PLANE_WIDE * reach).then_some(Warning::PreisachPlaneWide {
        h_max,
        reach,
        advised: PLANE_MARGIN * reach,
    })
}

/// `data`, each file starting from its excursion (none given: demagnetised).
pub fn starting_from<'a>(data: &[Prepared<'a>], excursions: &[f64]) -> Vec<Prepared<'a>> {
    data.iter()
        .enumerate()
        .map(|(i, p)| match excursions.get(i) {
            Some(&x) => p.starting(InitialState::Excursion(x)),
            None => p.starting(InitialState::Demagnetized),
        })
        .collect()
}

/// The pre-history excursion that best explains the start of `prep`'s displacement: a grid
/// over [`excursion_range`] that follows the rod's magnetization at the first field (where it
/// changes fast with the excursion, the points lie close: the demagnetised and the anhysteretic
/// states sit in narrow valleys of the excursion), then golden-section refinement between the
/// best point's neighbours.
pub(crate) fn estimate_excursion(spec: ModelSpec, params: &ActuatorParams, prep: &Prepared) -> Result<f64> {
    // Judged from the start of the file, where the state shows most (its first quarter, at
    // least 4000 samples: long records cost no more than that).
    let n = prep.rec.len();
    let head = prep.rec.head(n.min(4000.max(n / 4)));
    let head_prep = prep.head_of(&head);
    let cost = |x: f64| -> Result<f64> {
        let sim = run_model(spec, params, &head_prep.starting(InitialState::Excursion(x)), false)?;
        let e = score(spec, &head, &sim).nrmse;
        Ok(if e.is_finite() { e } else { f64::MAX })
    };
    let range = excursion_range(spec, params);
    let grid = excursion_grid(spec, params, prep, range)?;
    // The bracket shrinks to 0.618^16 ≈ 5e-4 of its width: fine enough for the uncertainty
    // analysis's differences around it.
    const GOLDEN_STEPS: usize = 16;
    let mut best = (f64::MAX, 0);
    for (j, &x) in grid.iter().enumerate() {
        let c = cost(x)?;
        if c < best.0 {
            best = (c, j);
        }
    }
    let (lo, hi) = (grid[best.1.saturating_sub(1)], grid[(best.1 + 1).min(grid.len() - 1)]);
    let best = (best.0, grid[best.1]);
    // Golden section between the best point's neighbours.
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (lo, hi);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut c1, mut c2) = (cost(x1)?, cost(x2)?);
    for _ in 0..GOLDEN_STEPS {
        if c1 < c2 {
            (hi, x2, c2) = (x2, x1, c1);
            x1 = hi - g * (hi - lo);
            c1 = cost(x1)?;
        } else {
            (lo, x1, c1) = (x1, x2, c2);
            x2 = lo + g * (hi - lo);
            c2 = cost(x2)?;
        }
    }
    Ok([(best.0, best.1), (c1, x1), (c2, x2)]
        .into_iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map_or(0.0, |b| b.1))
}

/// Points spanning ±`range` at which the estimate tries the excursion: at least every
/// [`GRID_SPAN`]th of the range, and closer wherever the rod's magnetization at the first
/// field moves by more than [`GRID_MAGNETIZATION`] of its span between them (read off the rest
/// states alone, which cost far less than runs).
fn excursion_grid(spec: ModelSpec, params: &ActuatorParams, prep: &Prepared, range: f64) -> Result<Vec<f64>> {
    const PROBES: usize = 240;
    let p = at_rate_of(spec, params, prep)?;
    let model = workbench_model(spec, &p).map_err(|e| anyhow::anyhow!("{e}"))?;
    let first = runs::first_drive(&p, prep);
    let xs: Vec<f64> = (0..=PROBES).map(|j| -range + 2.0 * range * j as f64 / PROBES as f64).collect();
    let ms: Vec<f64> =
        xs.iter().map(|&x| model.rest_state_at(first, x as f32).m_slow_a_per_m.value() as f64).collect();
    let span = ms.iter().copied().fold(f64::MIN, f64::max) - ms.iter().copied().fold(f64::MAX, f64::min);
    let (dx, dm) = (2.0 * range / GRID_SPAN, span * GRID_MAGNETIZATION);
    let mut grid = vec![xs[0]];
    let mut last = (xs[0], ms[0]);
    for (&x, &m) in xs.iter().zip(&ms).skip(1) {
        if x - last.0 >= dx - 1e-9 * range || (m - last.1).abs() >= dm || x == xs[PROBES] {
            grid.push(x);
            last = (x, m);
        }
    }
    Ok(grid)
}

/// The estimate's grid steps at most this fraction of the excursions' span …
const GRID_SPAN: f64 = 12.0;
/// … and at most this fraction of the magnetization's span at the first field.
const GRID_MAGNETIZATION: f64 = 1.0 / 24.0;
