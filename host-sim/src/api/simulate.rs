//! `gma simulate`: a SIMULATED rig (the plant simulator) under a standard excitation, or a
//! parameter set run on a measured drive (`--drive FILE`), written as a measurement CSV with the
//! contract columns. The command says on stderr that the data are simulated.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use model_core::{ActuatorParams, ModelSpec};
use rand::SeedableRng as _;
use rand_distr::{Distribution as _, Normal};
use serde_json::json;

use super::inputs::{read_recording, ReadArgs};
use crate::excitation::Excitation;
use crate::files::{check_outputs, display, replaces_only, to_stdout, Input, OutputKind};
use crate::params;
use crate::plant::{EddyModel, Plant};
use crate::recording::Recording;
use crate::simulation::Drive;

/// Most samples one run writes (about 1 GB of CSV).
pub const MAX_SAMPLES: f64 = 2.0e7;
/// Lowest excitation frequency [Hz].
const MIN_FREQ_HZ: f64 = 1e-3;
/// Largest amplitude or bias [A or V] (the reader's plausible current is ±1e3 A).
const MAX_DRIVE: f64 = 1e3;
/// Most integration steps per recorded sample.
pub const MAX_OVERSAMPLE: u32 = 64;
/// Largest displacement sensor offset, noise or quantum [µm] (the reader's plausible range is ±1e6 µm).
const MAX_SENSOR_UM: f64 = 1e5;
/// Largest search-coil noise [mT] (a rod's flux density swings by about a tesla).
const MAX_FLUX_NOISE_MT: f64 = 1e3;

/// Excitation waveforms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Waveform {
    /// bias + amplitude · sin(2π f t).
    Sine,
    /// bias ± amplitude, period 1/f (steps).
    Square,
    /// Linear chirp from f/10 to f over the duration.
    Chirp,
    /// Eight tones from f/8 to f (Schroeder phases), peak ≈ amplitude.
    Multisine,
    /// Sine at f whose amplitude ramps from 0 to `--amplitude`.
    Sweep,
}

/// Options of `gma simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Effects present in the simulated actuator, e.g. `ja+mech+eddy` (names: `gma --help`).
    #[arg(long, default_value = "ja+mech")]
    pub model: String,
    /// Parameter file (TOML, as `gma fit --params-out` writes); default: the built-in
    /// Terfenol-D demo set (said so on stderr and in the JSON's `parameters_source`).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Run the model on a measured drive instead of a waveform: the recording's `current_A`
    /// drives it (its `command_V` when the model has `amp`, or when there is no `current_A`:
    /// through the amplifier gain `amp.gain_a_per_v`). The output is on the file's own time
    /// base; the model is the lumped one `gma fit` identifies (eddy currents as a first-order
    /// lag). Excludes the waveform options; the reading options below apply to this file.
    #[arg(long, value_name = "FILE", conflicts_with_all = DRIVE_EXCLUDES)]
    pub drive: Option<PathBuf>,
    /// With `--drive`: the rod's initial magnetic state, as the pre-history field excursion
    /// from the first sample's field and back [A/m] — the value `gma compare --json` reports for the file
    /// (`files[].initial_excursion_a_per_m`), so that the run is the one compare scored. Default:
    /// demagnetised at the first sample's field (hysteretic laws only; other models have no
    /// magnetic memory).
    #[arg(long, value_name = "A_PER_M", requires = "drive", allow_negative_numbers = true)]
    pub initial_excursion: Option<f64>,
    /// Excitation waveform.
    #[arg(long, value_enum, default_value = "sine")]
    pub waveform: Waveform,
    /// Excitation frequency [Hz] (end frequency of a chirp, highest tone of a multisine).
    #[arg(long, default_value_t = 50.0)]
    pub freq_hz: f64,
    /// Amplitude (≥ 0): coil current [A], or command [V] when the model has `amp`.
    #[arg(long, default_value_t = 1.0)]
    pub amplitude: f64,
    /// DC bias added to the excitation [A] or [V].
    #[arg(long, default_value_t = 1.0)]
    pub bias: f64,
    /// Duration [s]; at most 20 million samples at the parameter set's `dt_s` (2000 s at 10 kHz).
    #[arg(long, default_value_t = 0.2)]
    pub duration_s: f64,
    /// Displacement sensor noise, standard deviation [µm].
    #[arg(long, default_value_t = 0.0)]
    pub noise_um: f64,
    /// Displacement quantisation step [µm] (0: none).
    #[arg(long, default_value_t = 0.0)]
    pub quantum_um: f64,
    /// Displacement sensor offset [µm].
    #[arg(long, default_value_t = 0.0)]
    pub offset_um: f64,
    /// Integration steps per recorded sample (the plant runs faster than the recording), 1 to 64.
    #[arg(long, default_value_t = 2)]
    pub oversample: u32,
    /// Eddy currents of the simulated rod (with `eddy`): field diffusion into the rod, whose
    /// low-frequency lag is `eddy_tau_s`, or the models' own first-order lag.
    #[arg(long, value_enum, default_value = "distributed")]
    pub eddy_model: EddyModel,
    /// Leave out the `current_A` column (a rig that logs the command only; needs `amp`).
    #[arg(long)]
    pub no_current: bool,
    /// Add a search coil's `flux_density_T` column: the rod's mean flux density
    /// B = μ0 (H + M) of the simulated rod (the channel `fit`, `compare` and `diagnose` score).
    #[arg(long)]
    pub search_coil: bool,
    /// The search coil's noise, standard deviation [mT] (with `--search-coil`).
    #[arg(long, default_value_t = 0.0, requires = "search_coil")]
    pub flux_noise_mt: f64,
    /// Seed of the noise generator.
    #[arg(long, default_value_t = 1, value_parser = crate::api::inputs::seed)]
    pub seed: u64,
    /// Output CSV (written atomically: temporary file, then rename); `-` writes it to standard
    /// output (not with `--json`, whose object stdout carries).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Replace an existing file at `--out`. Without it an existing file is refused: a simulated
    /// recording has a measurement's columns, so gma cannot tell one it wrote from a rig's.
    #[arg(long)]
    pub overwrite: bool,
    /// Print exactly one JSON object on stdout (what was written and from what).
    #[arg(long)]
    pub json: bool,
    /// How the `--drive` recording is read (see `gma fit --help`).
    #[command(flatten)]
    pub read: ReadArgs,
    /// No "wrote … to FILE" line: set by callers that read the file back and remove it.
    #[arg(skip)]
    pub quiet: bool,
}

/// Largest `--initial-excursion` accepted [A/m] (the loop files' plausible field).
const MAX_EXCURSION_A_PER_M: f64 = 1e8;

/// The options that make the waveform, which `--drive` replaces.
const DRIVE_EXCLUDES: [&str; 7] =
    ["waveform", "freq_hz", "amplitude", "bias", "duration_s", "oversample", "eddy_model"];

/// What [`run`] wrote: the `--json` result (without the provenance and parameter source) and
/// where the parameters came from.
pub struct Simulated {
    /// The JSON result's own fields (`out`, `samples`, `dt_s`, …).
    pub result: serde_json::Value,
    /// Where the parameters came from (a file or the built-in demo set).
    pub source: params::ParamSource,
}

/// Runs the simulation and writes the CSV.
pub fn run(a: &SimulateArgs) -> Result<Simulated> {
    let spec = params::parse_spec(&a.model)?;
    let to_stdout = to_stdout("--out", &a.out, a.json)?;
    if a.drive.is_none() && !a.read.is_default() {
        bail!("--column, --resample, --trim-start and --max-samples apply to the --drive FILE recording");
    }
    let read_opts = a.read.options()?;
    crate::api::inputs::check_max_samples(a.read.max_samples)?;
    let params_input = a.params.as_deref().map(Input::open).transpose()?;
    let drive_input = a.drive.as_deref().map(Input::open).transpose()?;
    let ids: Vec<_> = params_input.iter().chain(&drive_input).map(Input::id).collect();
    check_outputs(&[a.out.as_path()], &ids)?;
    replaces_only(&a.out, OutputKind::Recording { overwrite: a.overwrite }, "--out")?;
    let role = if a.drive.is_some() { "the model's parameters" } else { "the simulated rig's parameters" };
    let (p, source) = params::load_input(params_input, spec, role)?;
    // Effects the set was never fitted with run on their start values: said, as `compare` says it.
    let doubts: Vec<String> = crate::fit::unfitted_effects(spec, &source)
        .map(|w| {
            w.say();
            w.to_string()
        })
        .into_iter()
        .collect();
    for (name, v) in [("--noise-um", a.noise_um), ("--quantum-um", a.quantum_um)] {
        if !(v.is_finite() && (0.0..=MAX_SENSOR_UM).contains(&v)) {
            bail!("{name} must be in [0, {MAX_SENSOR_UM:e}] µm, got {v}");
        }
    }
    if !(a.offset_um.is_finite() && a.offset_um.abs() <= MAX_SENSOR_UM) {
        bail!("--offset-um must be within ±{MAX_SENSOR_UM:e} µm, got {}", a.offset_um);
    }
    if !(a.flux_noise_mt.is_finite() && (0.0..=MAX_FLUX_NOISE_MT).contains(&a.flux_noise_mt)) {
        bail!("--flux-noise-mt must be in [0, {MAX_FLUX_NOISE_MT}] mT, got {}", a.flux_noise_mt);
    }
    if a.no_current && !spec.has(model_core::Effect::AmplifierDynamics) {
        bail!("--no-current needs a model with `amp` (without it the current is the drive)");
    }
    let name = if to_stdout { "<stdout>".to_string() } else { display(&a.out) };
    let (rec, what, drive) = match drive_input {
        Some(input) => {
            let (measured, cut) = read_recording(input, a.read.max_samples, &read_opts)?;
            for w in cut {
                w.say();
            }
            let (rec, drive) = run_on_drive(a, spec, &p, &measured, &name)?;
            let what = format!(
                "model `{spec}` driven by {}'s measured `{}` on its own time base",
                measured.name,
                drive.column()
            );
            (rec, what, Some((measured.name, drive.column())))
        }
        None => {
            let (rec, what) = run_waveform(a, spec, p, &name)?;
            (rec, what, None)
        }
    };
    // Write only what the reader accepts (gma fit must read back every file gma writes).
    rec.check_plausible().context(if drive.is_some() {
        "the model left the plausible range on this drive (check the drive's column and unit)"
    } else {
        "the simulated rig left the plausible range (lower --amplitude or --bias?)"
    })?;
    rec.write(&a.out).with_context(|| format!("writing {name}"))?;
    if !a.quiet {
        let to = if to_stdout { "standard output" } else { &name };
        eprintln!("gma: wrote {} samples of SIMULATED data ({what}) to {to}", rec.len());
    }
    // The sample period as the parameter file states it (1e-4, not its f32 image
    // 9.9999997e-5), or a measured drive's own.
    let (dt_s, duration_s) = match drive {
        None => {
            let dt = stated_dt(p.dt_s);
            (dt, significant((rec.len().max(1) - 1) as f64 * dt, 12))
        }
        Some(_) => (significant(rec.dt_s(), 12), significant(rec.duration_s(), 12)),
    };
    let (drive_file, drive_column) = drive.unzip();
    let mut result = json!({
        "out": name,
        "simulated": true,
        "model": spec.to_string(),
        "samples": rec.len(),
        "duration_s": duration_s,
        "dt_s": dt_s,
        "columns": crate::recording::COLUMNS.iter().filter(|c| rec.column(c).is_some()).collect::<Vec<_>>(),
        "drive_file": drive_file,
        "drive_column": drive_column,
        "seed": a.seed,
        "description": what,
    });
    // Only where there is a doubt: the answer without one stays as it was.
    if !doubts.is_empty() {
        result["warnings"] = json!(doubts);
    }
    Ok(Simulated { result, source })
}

/// `x` to `digits` significant digits (at least 1): a time axis built as k·dt carries rounding
/// in its last bits (a 1e-4 s step reads 9.99999999999994e-5), and a number derived from an f32
/// period more (0.5 / 9.9999997e-5 s = 5000.000126 Hz), which a message should not repeat.
fn significant(x: f64, digits: usize) -> f64 {
    format!("{x:.*e}", digits.max(1) - 1).parse().unwrap_or(x)
}

/// A parameter set's sample period as its file states it: the shortest decimal that reads back
/// to the same f32 (1e-4, not 9.999999747378752e-5).
fn stated_dt(dt_s: f32) -> f64 {
    dt_s.to_string().parse().unwrap_or(dt_s as f64)
}

/// The model run on `measured`'s drive: the file's time and command, the drive current (the
/// measured one, or the model's when the command drives), and the model's displacement through
/// the sensor options.
fn run_on_drive(
    a: &SimulateArgs,
    spec: ModelSpec,
    p: &ActuatorParams,
    measured: &Recording,
    name: &str,
) -> Result<(Recording, Drive)> {
    let initial = match a.initial_excursion {
        None => crate::simulation::InitialState::Demagnetized,
        Some(x) if x.is_finite() && x.abs() <= MAX_EXCURSION_A_PER_M => {
            crate::simulation::InitialState::Excursion(x)
        }
        Some(x) => bail!("--initial-excursion {x}: give a field in A/m within ±{MAX_EXCURSION_A_PER_M:e}"),
    };
    let (sim, drive) = crate::simulation::simulate_drive(spec, p, measured, initial)?;
    let current = match drive {
        Drive::Current => measured.current_a.clone(),
        Drive::CommandIdeal | Drive::CommandDynamic => Some(sim.current_a),
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(a.seed);
    let noise = Normal::new(0.0, a.noise_um).context("--noise-um")?;
    let displacement = sim
        .displacement_um
        .iter()
        .map(|y| {
            let mut y = y + a.offset_um;
            if a.noise_um > 0.0 {
                y += noise.sample(&mut rng);
            }
            if a.quantum_um > 0.0 {
                y = (y / a.quantum_um).round() * a.quantum_um;
            }
            y
        })
        .collect();
    // The search coil's noise has its own stream: the other columns are the same with it or without.
    let mut flux_rng = rand::rngs::StdRng::seed_from_u64(a.seed ^ 0x5EA2_C011);
    let b_noise = Normal::new(0.0, a.flux_noise_mt * 1e-3).context("--flux-noise-mt")?;
    let flux = a.search_coil.then(|| {
        sim.field_a_per_m
            .iter()
            .zip(&sim.magnetization_a_per_m)
            .map(|(h, m)| {
                crate::channels::MU0 * (h + m)
                    + if a.flux_noise_mt > 0.0 { b_noise.sample(&mut flux_rng) } else { 0.0 }
            })
            .collect()
    });
    let rec = Recording {
        name: name.into(),
        time_s: measured.time_s.clone(),
        command_v: measured.command_v.clone(),
        current_a: if a.no_current { None } else { current },
        displacement_um: Some(displacement),
        force_n: None,
        temperature_c: None,
        flux_density_t: flux,
        header: Vec::new(),
    };
    Ok((rec, drive))
}

/// The plant simulator under the waveform options, and what it ran in words.
fn run_waveform(
    a: &SimulateArgs,
    spec: ModelSpec,
    p: ActuatorParams,
    name: &str,
) -> Result<(Recording, String)> {
    // The sample period as the parameter file states it (1e-4, not its f32 image
    // 9.999999747378752e-5), for messages; the checks use the period the plant runs at.
    let (dt, dt_shown) = (p.dt_s as f64, stated_dt(p.dt_s));
    for (name, v) in [("--freq-hz", a.freq_hz), ("--duration-s", a.duration_s)] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} must be a positive number, got {v}");
        }
    }
    if a.freq_hz < MIN_FREQ_HZ {
        bail!("--freq-hz must be at least {MIN_FREQ_HZ} Hz (one cycle in 1000 s), got {}", a.freq_hz);
    }
    if !(a.amplitude.is_finite() && (0.0..=MAX_DRIVE).contains(&a.amplitude)) {
        bail!(
            "--amplitude must be in [0, {MAX_DRIVE:e}] (A, or V with `amp`), got {}: a magnitude (a waveform's sign \
             is its phase)",
            a.amplitude
        );
    }
    if !(a.bias.is_finite() && a.bias.abs() <= MAX_DRIVE) {
        bail!("--bias must be within ±{MAX_DRIVE:e} (A, or V with `amp`), got {}", a.bias);
    }
    if a.freq_hz > 0.5 / dt {
        bail!(
            "--freq-hz {} is above the Nyquist frequency {} Hz of the sample period dt_s = {dt_shown:e} s",
            a.freq_hz,
            significant(0.5 / dt_shown, 6)
        );
    }
    let samples = (a.duration_s / dt).round();
    if samples < 3.0 {
        bail!(
            "--duration-s {} gives {samples} sample{} at dt_s = {dt_shown:e} s; a recording needs at least 3",
            a.duration_s,
            if samples == 1.0 { "" } else { "s" }
        );
    }
    if samples > MAX_SAMPLES {
        bail!(
            "--duration-s {} gives {samples:.3e} samples at dt_s = {dt_shown:e} s; at most {MAX_SAMPLES:e} ({} s) per run",
            a.duration_s,
            significant(MAX_SAMPLES * dt_shown, 6)
        );
    }
    if !(1..=MAX_OVERSAMPLE).contains(&a.oversample) {
        bail!("--oversample must be in [1, {MAX_OVERSAMPLE}], got {}", a.oversample);
    }
    let (f, amp, bias) = (a.freq_hz, a.amplitude, a.bias);
    let exc = match a.waveform {
        Waveform::Sine => Excitation::Sine { freq_hz: f, amplitude: amp, bias },
        Waveform::Square => Excitation::Square { freq_hz: f, amplitude: amp, bias },
        Waveform::Chirp => Excitation::Chirp { f0_hz: f / 10.0, f1_hz: f, amplitude: amp, bias },
        Waveform::Multisine => Excitation::Multisine {
            freqs_hz: (1..=8).map(|k| f * k as f64 / 8.0).collect(),
            amplitude: amp,
            bias,
        },
        Waveform::Sweep => Excitation::AmplitudeSweep { freq_hz: f, from: 0.0, to: amp, bias },
    };
    let mut plant = Plant::new(spec, p);
    plant.noise_um = a.noise_um;
    plant.quantum_um = a.quantum_um;
    plant.offset_um = a.offset_um;
    plant.oversample = a.oversample;
    plant.log_current = !a.no_current;
    plant.eddy = a.eddy_model;
    plant.flux_noise_t = a.search_coil.then_some(a.flux_noise_mt * 1e-3);
    let rec = plant.record(name, &exc, a.duration_s, a.seed)?;
    // The drive is the command [V] when the plant has an amplifier, else the coil current [A].
    let unit = if spec.has(model_core::Effect::AmplifierDynamics) { "V" } else { "A" };
    Ok((rec, format!("plant {}, {}", plant.describe(), exc.describe(unit))))
}
