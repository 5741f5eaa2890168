//! The workbench as a library for bindings (the Python package in `host-sim/python`): fit,
//! compare, diagnose and simulate on files or on arrays in memory, with the CLI's checks, errors
//! and result types ([`crate::results`], [`crate::diagnose::Diagnosis`]). Nothing here prints a
//! result; warnings the CLI prints on stderr are printed on stderr here too.

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use model_core::{ActuatorParams, Effect, ModelSpec};

use crate::cli::common::{self, Data, Prepared};
use crate::cli::simulate::{SimulateArgs, Waveform};
use crate::columns::ReadOptions;
use crate::diagnose::Diagnosis;
use crate::files::{names, open_all, Input};
use crate::fit::{self, Drive, FitOptions, Simulation};
use crate::loops::{self, LoopFile};
use crate::plant::EddyModel;
use crate::recording::{self, Recording, COLUMNS};
use crate::results::{CompareSummary, FileScoreRow, FitSummary};

/// Largest deviation of one time step from the median step (fraction), as the CSV reader allows.
const MAX_TIME_JITTER: f64 = 0.01;
/// Steps whose median is the reference step, as in the CSV reader.
const REFERENCE_STEPS: usize = 1024;

/// A bad value in an input array: which recording, which array, which index. The array
/// counterpart of a CSV cell's [`crate::error::Located`] error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArrayError {
    /// The recording's name.
    pub file: String,
    /// The array (a column name such as `current_A`).
    pub array: String,
    /// 0-based index into the array, when one element is at fault.
    pub index: Option<usize>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ArrayError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.index {
            Some(i) => write!(f, "{}: array `{}` index {i}: {}", self.file, self.array, self.message),
            None => write!(f, "{}: array `{}`: {}", self.file, self.array, self.message),
        }
    }
}

impl std::error::Error for ArrayError {}

fn array_error(file: &str, array: &str, index: Option<usize>, message: String) -> anyhow::Error {
    ArrayError { file: file.into(), array: array.into(), index, message }.into()
}

/// Builds a recording from arrays named as the CSV columns (`time_s`, `current_A`, …), refusing
/// what the CSV reader refuses in a file: unknown names, a missing time or drive column, fewer
/// than 3 samples, arrays of unequal length, values that are not finite or implausible, time
/// not strictly increasing or not uniform within 1 %. Errors are [`ArrayError`]s.
pub fn recording_from_arrays(name: &str, arrays: Vec<(String, Vec<f64>)>) -> Result<Recording> {
    let mut cols: [Option<Vec<f64>>; COLUMNS.len()] = Default::default();
    for (array, values) in arrays {
        let Some(k) = COLUMNS.iter().position(|c| *c == array) else {
            return Err(array_error(
                name,
                &array,
                None,
                format!("not a recognised column; recognised are {}", COLUMNS.join(", ")),
            ));
        };
        for (i, &v) in values.iter().enumerate() {
            if !v.is_finite() {
                return Err(array_error(name, &array, Some(i), format!("`{v}` is not a finite number")));
            }
            if let Err(why) = recording::plausible(k, v) {
                return Err(array_error(name, &array, Some(i), format!("{v:e} {why}")));
            }
        }
        cols[k] = Some(values);
    }
    let [time, command_v, current_a, displacement_um, force_n, temperature_c] = cols;
    let Some(time_s) = time else {
        return Err(array_error(name, "time_s", None, "missing: a recording needs a time axis [s]".into()));
    };
    if current_a.is_none() && command_v.is_none() {
        return Err(array_error(
            name,
            "current_A",
            None,
            "missing: a recording needs a drive, `current_A` or `command_V`".into(),
        ));
    }
    if time_s.len() < 3 {
        return Err(array_error(
            name,
            "time_s",
            None,
            format!("{} samples; a recording needs at least 3", time_s.len()),
        ));
    }
    let channels = [
        ("command_V", &command_v),
        ("current_A", &current_a),
        ("displacement_um", &displacement_um),
        ("force_N", &force_n),
        ("temperature_C", &temperature_c),
    ];
    for (array, v) in channels {
        if let Some(v) = v.as_ref().filter(|v| v.len() != time_s.len()) {
            return Err(array_error(
                name,
                array,
                None,
                format!("{} samples, but `time_s` has {}", v.len(), time_s.len()),
            ));
        }
    }
    if let Some(i) = time_s.windows(2).position(|w| w[1] <= w[0]) {
        return Err(array_error(
            name,
            "time_s",
            Some(i + 1),
            format!("{} s does not follow {} s: time must increase strictly", time_s[i + 1], time_s[i]),
        ));
    }
    // The reference step as the CSV reader takes it: the median of the first 1024 steps.
    let mut steps: Vec<f64> = time_s.windows(2).take(REFERENCE_STEPS).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let dt = steps[steps.len() / 2];
    let (lo, hi) = (model_core::DT_MIN_S as f64, model_core::DT_MAX_S as f64);
    if !(lo..=hi).contains(&dt) {
        return Err(array_error(
            name,
            "time_s",
            None,
            format!("sample period {dt:.3e} s is outside [{lo:e}, {hi:e}] s (is time_s in seconds?)"),
        ));
    }
    if let Some(i) = time_s.windows(2).position(|w| ((w[1] - w[0]) - dt).abs() > MAX_TIME_JITTER * dt) {
        let step = time_s[i + 1] - time_s[i];
        return Err(array_error(name, "time_s", Some(i + 1), format!("time step {step:.3e} s differs from the median step {dt:.3e} s by more than 1 % (samples must be uniform in time)")));
    }
    Ok(Recording { name: name.into(), time_s, command_v, current_a, displacement_um, force_n, temperature_c })
}

/// Where a recording comes from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A measurement CSV or a magnetization-loop file (`-`: standard input).
    File(PathBuf),
    /// Arrays already checked by [`recording_from_arrays`].
    Arrays(Recording),
}

/// Where the parameter set comes from.
#[derive(Debug, Clone, Default)]
pub enum ParamsSource {
    /// The built-in Terfenol-D demo set.
    #[default]
    Demo,
    /// A parameter file (TOML as `gma fit --params-out` writes).
    File(PathBuf),
    /// The text of such a file, with a name for messages.
    Text {
        /// Name in messages.
        name: String,
        /// The TOML text.
        text: String,
    },
}

impl ParamsSource {
    /// The parameters, checked for `spec`.
    pub fn load(&self, spec: ModelSpec) -> Result<ActuatorParams> {
        match self {
            ParamsSource::Demo => crate::params::load_input(None, spec),
            ParamsSource::File(path) => crate::params::load_input(Some(Input::open(path)?), spec),
            ParamsSource::Text { name, text } => crate::params::parse(name, text, spec),
        }
    }
}

/// How files are read: the CLI's `--max-samples`, `--column`, `--resample`, `--trim-start`.
#[derive(Debug, Clone)]
pub struct ReadSettings {
    /// Samples (or loop points) kept per file.
    pub max_samples: usize,
    /// `CANONICAL=HEADER[:UNIT]` column maps.
    pub columns: Vec<String>,
    /// `linear` or none.
    pub resample: Option<String>,
    /// Seconds dropped at the start of each recording.
    pub trim_start_s: Option<f64>,
}

impl Default for ReadSettings {
    fn default() -> Self {
        Self {
            max_samples: common::DEFAULT_MAX_SAMPLES,
            columns: Vec::new(),
            resample: None,
            trim_start_s: None,
        }
    }
}

impl ReadSettings {
    fn options(&self) -> Result<ReadOptions> {
        common::check_max_samples(self.max_samples)?;
        ReadOptions::new(&self.columns, self.resample.as_deref(), self.trim_start_s)
    }
}

/// Reads one measurement CSV as the CLI does.
pub fn read_recording(path: PathBuf, read: &ReadSettings) -> Result<Recording> {
    let opts = read.options()?;
    common::read_recording(Input::open(&path)?, read.max_samples, &opts)
}

/// Reads one magnetization-loop file as the CLI does.
pub fn read_loop(path: PathBuf, read: &ReadSettings) -> Result<LoopFile> {
    read.options()?;
    loops::read_input(Input::open(&path)?, read.max_samples)
}

/// Reads fit and validation sources: files as the CLI reads them (recordings or loops, never a
/// mix), arrays in their place among them.
fn read_sources(fit_src: &[Source], val_src: &[Source], read: &ReadSettings) -> Result<Data> {
    let opts = read.options()?;
    let paths = |v: &[Source]| -> Vec<PathBuf> {
        v.iter().filter_map(|s| if let Source::File(p) = s { Some(p.clone()) } else { None }).collect()
    };
    let (fit_paths, val_paths) = (paths(fit_src), paths(val_src));
    if fit_paths.is_empty() && val_paths.is_empty() {
        let arrays = |v: &[Source]| {
            v.iter().filter_map(|s| if let Source::Arrays(r) = s { Some(r.clone()) } else { None }).collect()
        };
        return Ok(Data::Recordings(arrays(fit_src), arrays(val_src)));
    }
    let data = common::read_data(open_all(&fit_paths)?, open_all(&val_paths)?, read.max_samples, &opts)?;
    let has_arrays = fit_src.iter().chain(val_src).any(|s| matches!(s, Source::Arrays(_)));
    match data {
        Data::Loops(..) if has_arrays => bail!(
            "mixing magnetization-loop files and recordings given as arrays in one call: loop files are read from files only"
        ),
        Data::Loops(f, v) => Ok(Data::Loops(f, v)),
        Data::Recordings(f, v) => {
            let merge = |src: &[Source], files: Vec<Recording>| -> Vec<Recording> {
                let mut files = files.into_iter();
                src.iter()
                    .filter_map(|s| match s {
                        Source::File(_) => files.next(),
                        Source::Arrays(r) => Some(r.clone()),
                    })
                    .collect()
            };
            Ok(Data::Recordings(merge(fit_src, f), merge(val_src, v)))
        }
    }
}

/// The search settings: the CLI's `--seed`, `--effort`, `--time-limit`, `--fix`, `--bound`.
#[derive(Debug, Clone)]
pub struct FitSettings {
    /// Seed of the global search.
    pub seed: u64,
    /// Search effort, (0, 20].
    pub effort: f64,
    /// Seconds after which the best result so far is used.
    pub time_limit_s: Option<f64>,
    /// `NAME[=VALUE]` held parameters (displacement fits).
    pub fix: Vec<String>,
    /// `NAME=LO:HI` narrowed ranges (displacement fits).
    pub bound: Vec<String>,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self { seed: 1, effort: 1.0, time_limit_s: None, fix: Vec::new(), bound: Vec::new() }
    }
}

/// What a fitting call needs, checked as the CLI checks it.
fn prepare(
    model: &str,
    fit_src: &[Source],
    val_src: &[Source],
    params: &ParamsSource,
    s: &FitSettings,
    read: &ReadSettings,
) -> Result<Prepared> {
    let spec = crate::params::parse_spec(model)?;
    if fit_src.is_empty() {
        bail!("no recordings or loop files to fit");
    }
    if !(s.effort.is_finite() && s.effort > 0.0 && s.effort <= 20.0) {
        bail!("--effort must be in (0, 20], got {}", s.effort);
    }
    let time_limit = s.time_limit_s.map(common::time_limit).transpose()?;
    let init = params.load(spec)?;
    let data = read_sources(fit_src, val_src, read)?;
    if let Data::Recordings(fit_files, val_files) = &data {
        for r in fit_files.iter().chain(val_files) {
            fit::drive_for(spec, r)?;
        }
    }
    let deadline = time_limit.map(|t| Instant::now() + t);
    Ok(Prepared {
        spec,
        init,
        data,
        opts: FitOptions { seed: s.seed, progress: false, effort: s.effort, deadline },
    })
}

/// A fit's outcome: the CLI's `--json` result and the parameter file `--params-out` writes.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// As `gma fit --json` prints it.
    pub summary: FitSummary,
    /// The identified parameter set, as `--params-out` writes it (TOML).
    pub params_toml: String,
}

/// `gma fit`: one parameter set for all fit sources, scored on the validation sources.
pub fn fit(
    model: &str,
    fit_src: &[Source],
    val_src: &[Source],
    params: &ParamsSource,
    s: &FitSettings,
    read: &ReadSettings,
) -> Result<FitOutcome> {
    let mut p = prepare(model, fit_src, val_src, params, s, read)?;
    let (summary, fitted, warnings) = match &p.data {
        Data::Loops(fit_files, val_files) => {
            if !(s.fix.is_empty() && s.bound.is_empty()) {
                bail!(
                    "--{}: fixing or bounding parameters applies to displacement fits, not to loop files",
                    if s.fix.is_empty() { "bound" } else { "fix" }
                );
            }
            crate::cli::fit::fit_loops(&p, fit_files, val_files)?
        }
        Data::Recordings(fit_files, val_files) => {
            let c = fit::Constraints::parse(p.spec, fit_files, &s.fix, &s.bound, &mut p.init)?;
            crate::cli::fit::fit_recordings(&p, fit_files, val_files, &c)?
        }
    };
    let invalid: Vec<String> = warnings.iter().filter(|w| w.invalidates()).map(|w| w.to_string()).collect();
    if !invalid.is_empty() {
        bail!("the loop fit did not produce a valid model: {}", invalid.join("; "));
    }
    let sources: Vec<PathBuf> = fit_src
        .iter()
        .map(|s| match s {
            Source::File(p) => p.clone(),
            Source::Arrays(r) => PathBuf::from(&r.name),
        })
        .collect();
    let header = format!(
        "gma.fit (Python) --model {} (seed {}) on {}\nfit NRMSE {:.4} %",
        summary.model,
        s.seed,
        names(&sources),
        summary.nrmse_fit * 100.0
    );
    Ok(FitOutcome { params_toml: crate::params::to_toml(&fitted, &header)?, summary })
}

/// `gma diagnose`: fit `model`, analyse what it leaves unexplained, name the missing effect.
pub fn diagnose(
    model: &str,
    fit_src: &[Source],
    val_src: &[Source],
    params: &ParamsSource,
    s: &FitSettings,
    read: &ReadSettings,
) -> Result<Diagnosis> {
    let p = prepare(model, fit_src, val_src, params, s, read)?;
    let Data::Recordings(fit_files, val_files) = &p.data else {
        bail!("diagnose works on displacement recordings; for magnetization loops use `gma fit` and `gma compare`");
    };
    crate::diagnose::diagnose(p.spec, &p.init, fit_files, val_files, p.opts)
}

/// The model's prediction for one compared source.
#[derive(Debug, Clone)]
pub enum Prediction {
    /// A recording: the model run over its drive, displacement with the fitted offset added.
    Recording {
        /// The source's name.
        name: String,
        /// The recording's time axis [s].
        time_s: Vec<f64>,
        /// The model run (`displacement_um` already offset to the measurement).
        sim: Simulation,
    },
    /// A loop file: the model's value of the file's channel along the file's field path.
    Loop {
        /// The source's name.
        name: String,
        /// Field H [A/m] (the file's).
        field_a_per_m: Vec<f64>,
        /// `flux_density` or `magnetization`.
        channel: &'static str,
        /// The model's B [T] or M [A/m].
        value: Vec<f64>,
    },
}

/// `gma compare` without plots: the CLI's `--json` result and the model's predictions.
pub fn compare(
    model: &str,
    params: &ParamsSource,
    sources: &[Source],
    read: &ReadSettings,
) -> Result<(CompareSummary, Vec<Prediction>)> {
    let spec = crate::params::parse_spec(model)?;
    if sources.is_empty() {
        bail!("no recordings or loop files to compare");
    }
    let p = params.load(spec)?;
    let (mut rows, mut predictions, mut total) = (Vec::new(), Vec::new(), 0.0);
    match read_sources(sources, &[], read)? {
        Data::Recordings(recs, _) => {
            for r in &recs {
                fit::drive_for(spec, r)?;
            }
            for rec in &recs {
                let mut sim = fit::simulate(spec, &p, rec)?;
                let sc = fit::score(spec, rec, &sim);
                total += sc.nrmse;
                sim.displacement_um.iter_mut().for_each(|y| *y += sc.offset_um);
                rows.push(FileScoreRow {
                    offset_um: Some(sc.offset_um),
                    ..FileScoreRow::new(&rec.name, None, "displacement", sc.nrmse)
                });
                if let Some(c) = sc.nrmse_current {
                    rows.push(FileScoreRow::new(&rec.name, None, "current", c));
                }
                predictions.push(Prediction::Recording {
                    name: rec.name.clone(),
                    time_s: rec.time_s.clone(),
                    sim,
                });
            }
        }
        Data::Loops(files, _) => {
            let lm = loops::LoopModel::from_spec(spec)?;
            let values = lm.values_of(&p);
            for f in &files {
                let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let m = loops::run(lm, &values, &f.h, h_max)
                    .map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
                let model_value = f.channel_from_m(&m);
                let e = fit::nrmse(&f.value, &model_value);
                total += e;
                rows.push(FileScoreRow {
                    measured: Some(loops::features(&f.h, &f.magnetization())),
                    model: Some(loops::features(&f.h, &m)),
                    ..FileScoreRow::new(&f.name, None, f.channel.name(), e)
                });
                predictions.push(Prediction::Loop {
                    name: f.name.clone(),
                    field_a_per_m: f.h.clone(),
                    channel: f.channel.name(),
                    value: model_value,
                });
            }
        }
    }
    let summary =
        CompareSummary { model: spec.to_string(), nrmse: total / sources.len() as f64, files: rows };
    Ok((summary, predictions))
}

/// The model's response to a drive given as arrays (`time_s` and `current_A`, or `command_V`
/// for a model with `amp` or a rig logging the command only): the same run `compare` makes,
/// without a measurement to score it against.
pub fn model_response(model: &str, params: &ParamsSource, drive: &Recording) -> Result<Simulation> {
    let spec = crate::params::parse_spec(model)?;
    let p = params.load(spec)?;
    let drive_kind = if spec.has(Effect::AmplifierDynamics) {
        if drive.command_v.is_none() {
            bail!("{}: the model has amplifier_dynamics, which needs a `command_V` array", drive.name);
        }
        Drive::CommandDynamic
    } else if drive.current_a.is_some() {
        Drive::Current
    } else {
        Drive::CommandIdeal
    };
    let prep = fit::Prepared { rec: drive, dt_s: drive.dt_s(), drive: drive_kind };
    fit::run_model(spec, &p, &prep, true)
}

/// `gma simulate`'s options (the same names, units and defaults), for a SIMULATED recording.
#[derive(Debug, Clone)]
pub struct RigSettings {
    /// `sine`, `square`, `chirp`, `multisine` or `sweep`.
    pub waveform: String,
    /// Excitation frequency [Hz].
    pub freq_hz: f64,
    /// Amplitude [A], or [V] with `amp`.
    pub amplitude: f64,
    /// DC bias [A] or [V].
    pub bias: f64,
    /// Duration [s].
    pub duration_s: f64,
    /// Displacement sensor noise [µm].
    pub noise_um: f64,
    /// Displacement quantisation step [µm].
    pub quantum_um: f64,
    /// Displacement sensor offset [µm].
    pub offset_um: f64,
    /// Integration steps per sample.
    pub oversample: u32,
    /// `distributed` or `lumped`.
    pub eddy_model: String,
    /// Leave out the current (needs `amp`).
    pub no_current: bool,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Default for RigSettings {
    fn default() -> Self {
        Self {
            waveform: "sine".into(),
            freq_hz: 50.0,
            amplitude: 1.0,
            bias: 1.0,
            duration_s: 0.2,
            noise_um: 0.0,
            quantum_um: 0.0,
            offset_um: 0.0,
            oversample: 2,
            eddy_model: "distributed".into(),
            no_current: false,
            seed: 1,
        }
    }
}

/// The value of a clap enum option from its name, or the CLI's kind of refusal.
fn choice<T: ValueEnum>(option: &str, value: &str) -> Result<T> {
    T::from_str(value, false).map_err(|_| {
        let names: Vec<String> = T::value_variants()
            .iter()
            .filter_map(|v| v.to_possible_value())
            .map(|p| p.get_name().to_string())
            .collect();
        anyhow::anyhow!("invalid value '{value}' for '--{option}': possible values are {}", names.join(", "))
    })
}

/// `gma simulate`: a SIMULATED rig's recording, exactly as the CLI writes and reads it back
/// (the same checks, the same CSV rounding), named `name`.
pub fn simulate_rig(model: &str, params: &ParamsSource, s: &RigSettings, name: &str) -> Result<Recording> {
    // Checked here first, so that problems are reported under the names given, not the temporary files'.
    params.load(crate::params::parse_spec(model)?)?;
    let dir = tempfile::tempdir().context("creating a temporary folder for the simulated recording")?;
    let params_path = match params {
        ParamsSource::Demo => None,
        ParamsSource::File(p) => Some(p.clone()),
        ParamsSource::Text { text, .. } => {
            let p = dir.path().join("params.toml");
            std::fs::write(&p, text).context("writing the parameter set to a temporary file")?;
            Some(p)
        }
    };
    let out = dir.path().join("simulated.csv");
    let args = SimulateArgs {
        model: model.into(),
        params: params_path,
        waveform: choice::<Waveform>("waveform", &s.waveform)?,
        freq_hz: s.freq_hz,
        amplitude: s.amplitude,
        bias: s.bias,
        duration_s: s.duration_s,
        noise_um: s.noise_um,
        quantum_um: s.quantum_um,
        offset_um: s.offset_um,
        oversample: s.oversample,
        eddy_model: choice::<EddyModel>("eddy-model", &s.eddy_model)?,
        no_current: s.no_current,
        seed: s.seed,
        out: out.clone(),
    };
    crate::cli::simulate::run(&args)?;
    let mut rec = Recording::read(&out)?;
    rec.name = name.into();
    Ok(rec)
}
