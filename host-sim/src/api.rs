//! The workbench as a library for bindings (the Python package in `host-sim/python`): fit,
//! compare, diagnose and simulate on files or on arrays in memory, with the CLI's checks, errors
//! and result types ([`crate::results`], [`crate::diagnose::Diagnosis`]). Nothing here prints a
//! result; the notes and warnings the CLI prints on stderr are said here too, through
//! [`crate::warning`] (a binding collects them with [`crate::warning::heard`]).

pub mod fitting;
pub mod inputs;
pub mod simulate;

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use model_core::{ActuatorParams, ModelSpec};

use crate::columns::ReadOptions;
use crate::diagnose::Diagnosis;
use crate::files::{names, open_all, Input};
use crate::fit::{self, FitOptions};
use crate::loop_fit;
use crate::loops::{self, LoopFile};
use crate::params::ParamSource;
use crate::recording::{self, Recording, COLUMNS};
use crate::results::{CompareSummary, FileScoreRow, FitSummary};
use crate::simulated::Simulation;
use crate::warning::Warning;
use inputs::{Data, Prepared};
use simulate::SimulateArgs;

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
    let [time, command_v, current_a, displacement_um, force_n, temperature_c, flux_density_t] = cols;
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
        ("flux_density_T", &flux_density_t),
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
    // As the CSV reader checks a file's: in f32, the model's stepping, shown as model-core states it.
    let (lo, hi) = (model_core::DT_MIN_S, model_core::DT_MAX_S);
    if !(lo..=hi).contains(&(dt as f32)) {
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
    Ok(Recording {
        name: name.into(),
        time_s,
        command_v,
        current_a,
        displacement_um,
        force_n,
        temperature_c,
        flux_density_t,
        header: Vec::new(),
    })
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
    /// The parameters, checked for `spec`, and where they came from (the CLI's
    /// `parameters_source` / `parameters_defaulted`; the same notes).
    pub fn load(&self, spec: ModelSpec) -> Result<(ActuatorParams, ParamSource)> {
        match self {
            ParamsSource::Demo => crate::params::load_input(None, spec, "parameters"),
            ParamsSource::File(path) => {
                crate::params::load_input(Some(Input::open(path)?), spec, "parameters")
            }
            ParamsSource::Text { name, text } => crate::params::load_text(name, text, spec, None),
        }
    }
}

/// How files are read: the CLI's `--max-samples`, `--column`, `--resample`, `--trim-start`,
/// `--skip-rows`.
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
    /// Lines passed over before each recording's header (a logger's preamble).
    pub skip_rows: usize,
}

impl Default for ReadSettings {
    fn default() -> Self {
        Self {
            max_samples: inputs::DEFAULT_MAX_SAMPLES,
            columns: Vec::new(),
            resample: None,
            trim_start_s: None,
            skip_rows: 0,
        }
    }
}

impl ReadSettings {
    /// The settings that differ from the default, by their keyword names.
    fn set(&self) -> Vec<&'static str> {
        let d = ReadSettings::default();
        [
            (self.max_samples != d.max_samples, "max_samples"),
            (!self.columns.is_empty(), "columns"),
            (self.resample.is_some(), "resample"),
            (self.trim_start_s.is_some(), "trim_start_s"),
            (self.skip_rows != 0, "skip_rows"),
        ]
        .into_iter()
        .filter_map(|(set, name)| set.then_some(name))
        .collect()
    }

    fn options(&self) -> Result<ReadOptions> {
        inputs::check_max_samples(self.max_samples)?;
        Ok(ReadOptions::new(&self.columns, self.resample.as_deref(), self.trim_start_s)?
            .skipping(self.skip_rows))
    }
}

/// Reads one measurement CSV as the CLI does; the warnings say when `max_samples` cut it short,
/// and what the reader says about its columns and time axis.
pub fn read_recording(path: PathBuf, read: &ReadSettings) -> Result<(Recording, Vec<Warning>)> {
    let opts = read.options()?;
    inputs::read_recording(Input::open(&path)?, read.max_samples, &opts)
}

/// Reads one magnetization-loop file as the CLI does; the warning says when `max_samples` cut
/// it short.
pub fn read_loop(path: PathBuf, read: &ReadSettings) -> Result<(LoopFile, Option<Warning>)> {
    read.options()?;
    loops::read_input(Input::open(&path)?, read.max_samples)
}

/// Reads fit and validation sources: files as the CLI reads them (recordings or loops, never a
/// mix), arrays in their place among them.
/// Also says which validation file has a fit file's content (files only: arrays are not hashed).
fn read_sources(fit_src: &[Source], val_src: &[Source], read: &ReadSettings) -> Result<(Data, Vec<Warning>)> {
    let opts = read.options()?;
    // They say how a file is read: applied to arrays they would change data the caller holds.
    let set = read.set();
    if let Some(k) = fit_src.iter().chain(val_src).position(|s| matches!(s, Source::Arrays(_))) {
        if !set.is_empty() {
            bail!(
                "{} applies to files read from disk, and input {k} is given as arrays: slice, scale or \
                 resample the arrays before the call, or pass the file's path",
                set.join(", ")
            );
        }
    }
    let paths = |v: &[Source]| -> Vec<PathBuf> {
        v.iter().filter_map(|s| if let Source::File(p) = s { Some(p.clone()) } else { None }).collect()
    };
    let (fit_paths, val_paths) = (paths(fit_src), paths(val_src));
    // Arrays get the doubts a file's time axis gets when it is read.
    let array_doubts = fit_src.iter().chain(val_src).filter_map(|s| match s {
        Source::Arrays(r) => r.time_doubt().map(Warning::Read),
        Source::File(_) => None,
    });
    if fit_paths.is_empty() && val_paths.is_empty() {
        let arrays = |v: &[Source]| {
            v.iter().filter_map(|s| if let Source::Arrays(r) = s { Some(r.clone()) } else { None }).collect()
        };
        return Ok((Data::Recordings(arrays(fit_src), arrays(val_src)), array_doubts.collect()));
    }
    let (data, mut warnings) =
        inputs::read_inputs(open_all(&fit_paths)?, open_all(&val_paths)?, read.max_samples, &opts)?;
    warnings.extend(array_doubts);
    let has_arrays = fit_src.iter().chain(val_src).any(|s| matches!(s, Source::Arrays(_)));
    match data {
        Data::Loops(..) if has_arrays => bail!(
            "mixing magnetization-loop files and recordings given as arrays in one call: loop files are read from files only"
        ),
        Data::Loops(f, v) => Ok((Data::Loops(f, v), warnings)),
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
            Ok((Data::Recordings(merge(fit_src, f), merge(val_src, v)), warnings))
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
    /// Progress lines of the search, as the CLI writes them (to stderr, or to the caller's
    /// sink: [`crate::progress::to_sink`]).
    pub progress: bool,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self { seed: 1, effort: 1.0, time_limit_s: None, fix: Vec::new(), bound: Vec::new(), progress: false }
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
    let time_limit = s.time_limit_s.map(inputs::time_limit).transpose()?;
    let (init, params_source) = params.load(spec)?;
    let (data, mut input_warnings) = read_sources(fit_src, val_src, read)?;
    if let Data::Recordings(fit_files, val_files) = &data {
        fit::check_files(spec, &init, fit_files.iter().chain(val_files))?;
        input_warnings.extend(fit::data_doubts(spec, &init, fit_files.iter().chain(val_files))?);
    }
    let deadline = time_limit.map(|t| Instant::now() + t);
    Ok(Prepared {
        spec,
        init,
        data,
        opts: FitOptions { seed: s.seed, progress: s.progress, effort: s.effort, deadline },
        params_source,
        input_warnings,
        // The library API writes no files: nothing to check outputs against.
        inputs: Vec::new(),
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
    let (mut summary, fitted, mut warnings) = match &p.data {
        Data::Loops(fit_files, val_files) => {
            if !(s.fix.is_empty() && s.bound.is_empty()) {
                bail!(
                    "--{}: fixing or bounding parameters applies to displacement fits, not to loop files",
                    if s.fix.is_empty() { "bound" } else { "fix" }
                );
            }
            fitting::fit_loops(&p, fit_files, val_files)?
        }
        Data::Recordings(fit_files, val_files) => {
            let c = fit::Constraints::parse(p.spec, fit_files, &s.fix, &s.bound, &mut p.init)?;
            fitting::fit_recordings(&p, fit_files, val_files, &c)?
        }
    };
    // Said as the CLI says them (a binding shows them: the Python package as `UserWarning`s).
    fitting::add_time_limit_warning(&mut summary, &mut warnings, s.time_limit_s);
    for w in &warnings {
        w.say();
    }
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
    let params_toml = crate::params::to_toml_for(&fitted, &header, p.spec, &summary.not_fitted)?;
    Ok(FitOutcome { params_toml, summary })
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
        bail!("diagnose works on displacement recordings; for magnetization loops use `fit` and `compare`");
    };
    p.warn_about_inputs();
    let d = crate::diagnose::diagnose(p.spec, &p.init, fit_files, val_files, p.opts)?;
    if d.time_limited {
        crate::warning::warn(Warning::TimeLimit { seconds: s.time_limit_s.unwrap_or(f64::NAN) });
    }
    Ok(d)
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
    let (p, source) = params.load(spec)?;
    let (mut rows, mut predictions, mut total) = (Vec::new(), Vec::new(), 0.0);
    let (data, read_warnings) = read_sources(sources, &[], read)?;
    let mut warnings: Vec<String> = read_warnings.iter().map(ToString::to_string).collect();
    match data {
        Data::Recordings(recs, _) => {
            fit::check_files(spec, &p, &recs)?;
            warnings.extend(fit::unresolved_mode(spec, &p, &recs).map(|w| w.to_string()));
            warnings.extend(fit::unfitted_gain(spec, &p, &source, &recs).map(|w| w.to_string()));
            warnings.extend(fit::unfitted_effects(spec, &source).map(|w| w.to_string()));
            warnings.extend(fit::data_doubts(spec, &p, &recs)?.iter().map(|w| w.to_string()));
            warnings.extend(fit::sign_doubts(spec, &p, &recs)?.iter().map(|w| w.to_string()));
            for rec in &recs {
                let mut sim = crate::simulation::simulate(spec, &p, rec)?;
                let sc = crate::score::score(spec, rec, &sim);
                warnings.extend(
                    fit::flux_scale_doubts(std::slice::from_ref(rec), &[sc]).iter().map(|w| w.to_string()),
                );
                total += sc.nrmse;
                sim.displacement_um.iter_mut().for_each(|y| *y += sc.offset_um);
                rows.extend(FileScoreRow::for_recording(rec, None, &sc));
                predictions.push(Prediction::Recording {
                    name: rec.name.clone(),
                    time_s: rec.time_s.clone(),
                    sim,
                });
            }
        }
        Data::Loops(files, _) => {
            let lm = loop_fit::LoopModel::from_spec(spec, &p)?;
            let values = lm.values_of(&p);
            for f in &files {
                let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let m = loop_fit::run(lm, &values, &f.h, h_max)
                    .map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
                let model_value = f.channel_from_m(&m);
                let e = crate::score::nrmse(&f.value, &model_value);
                total += e;
                rows.push(FileScoreRow {
                    measured: Some(loops::features(&f.h, &f.magnetization())),
                    model: Some(loops::features(&f.h, &m)),
                    ..FileScoreRow::new(&f.name, None, (f.channel.name(), &f.value), e)
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
    // Said as the CLI says them: the reader's notes as notes, then the model's warnings.
    for w in &read_warnings {
        w.say();
    }
    for w in &warnings[read_warnings.len()..] {
        crate::warning::warn(w);
    }
    let summary = CompareSummary {
        model: spec.to_string(),
        nrmse: total / sources.len() as f64,
        files: rows,
        warnings,
    };
    Ok((summary, predictions))
}

/// The model's response to a drive given as arrays (`time_s` and `current_A`, or `command_V`
/// for a model with `amp` or a rig logging the command only): the same run `compare` makes,
/// without a measurement to score it against: the rod starts demagnetised, or after the
/// pre-history `initial_excursion_a_per_m` (e.g. the state `compare` estimated for the file).
pub fn model_response(
    model: &str,
    params: &ParamsSource,
    drive: &Recording,
    initial_excursion_a_per_m: Option<f64>,
) -> Result<Simulation> {
    let spec = crate::params::parse_spec(model)?;
    let (p, _) = params.load(spec)?;
    let initial = match initial_excursion_a_per_m {
        Some(x) if x.is_finite() => crate::simulation::InitialState::Excursion(x),
        Some(x) => bail!("initial_excursion_a_per_m must be finite, got {x}"),
        None => crate::simulation::InitialState::Demagnetized,
    };
    Ok(crate::simulation::simulate_drive(spec, &p, drive, initial)?.0)
}

/// `gma simulate` with `options` as on its command line (`("--freq-hz", Some("80"))`,
/// `("--no-current", None)`; `--out` and `--params` are set here): a SIMULATED rig's recording,
/// parsed by the CLI's own option definitions (same defaults, same refusals), written and read
/// back as the CLI writes it (same CSV rounding), named `name`.
pub fn simulate_rig(
    model: Option<&str>,
    params: &ParamsSource,
    options: &[(String, Option<String>)],
    name: &str,
) -> Result<Recording> {
    #[derive(clap::Parser)]
    #[command(name = "gma simulate", allow_negative_numbers = true)]
    struct SimulateCli {
        #[command(flatten)]
        args: SimulateArgs,
    }
    if let Some((option, _)) =
        options.iter().find(|(o, _)| matches!(o.as_str(), "--out" | "-o" | "--params" | "--model"))
    {
        bail!("{option} is set by the call itself, not as an option");
    }
    let dir = tempfile::tempdir().context("creating a temporary folder for the simulated recording")?;
    let out = dir.path().join("simulated.csv");
    let mut argv: Vec<std::ffi::OsString> = vec!["gma simulate".into(), "--out".into(), out.clone().into()];
    if let Some(m) = model {
        argv.extend(["--model".into(), m.into()]);
    }
    for (option, value) in options {
        argv.push(option.into());
        argv.extend(value.iter().map(Into::into));
    }
    let mut args = SimulateCli::try_parse_from(argv).map_err(|e| usage_error(&e))?.args;
    // The file is temporary: no "wrote … to FILE" line.
    args.quiet = true;
    // Checked here first, so that problems are reported under the names given, not the temporary
    // files'; its notes are the run's below, said once.
    crate::warning::heard(|| params.load(crate::params::parse_spec(&args.model)?)).0?;
    // A parameter text is run from a temporary copy, whose path the run's notes name.
    let temporary = match params {
        ParamsSource::Demo => None,
        ParamsSource::File(p) => {
            args.params = Some(p.clone());
            None
        }
        ParamsSource::Text { name, text } => {
            let p = dir.path().join("params.toml");
            std::fs::write(&p, text).context("writing the parameter set to a temporary file")?;
            let path = crate::files::display(&p);
            args.params = Some(p);
            Some((path, name.as_str()))
        }
    };
    let (ran, said) = crate::warning::heard(|| simulate::run(&args).map(|_| ()));
    // The notes name the text as given, not its temporary copy.
    for s in said {
        crate::warning::say(match &temporary {
            Some((path, name)) => s.map_text(|t| t.replace(path, name)),
            None => s,
        });
    }
    ran?;
    let mut rec = Recording::read(&out)?;
    rec.name = name.into();
    Ok(rec)
}

/// clap's refusal of an option as one line: what is wrong and the accepted values, without the
/// pointer to `--help` (there is no command line to ask).
fn usage_error(e: &clap::Error) -> anyhow::Error {
    let text = e.to_string();
    // The usage line lists the command line's flags, which a library call does not have.
    let text = text.split("\n\nFor more information").next().unwrap_or_default();
    let text = text.split("\n\nUsage:").next().unwrap_or_default();
    let words: Vec<&str> = text.trim_start_matches("error: ").split_whitespace().collect();
    anyhow::anyhow!("{}", words.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::inputs::ModelFiles;

    #[derive(clap::Parser)]
    struct FitCli {
        #[command(flatten)]
        mf: ModelFiles,
    }

    /// The settings a binding leaves unset are the CLI's defaults.
    #[test]
    fn defaults_are_the_command_lines() {
        let cli = FitCli::try_parse_from(["gma", "--model", "ja", "rig.csv"]).unwrap().mf;
        let (f, r) = (FitSettings::default(), ReadSettings::default());
        assert_eq!((f.seed, f.effort, f.time_limit_s), (cli.seed, cli.effort, cli.time_limit));
        assert_eq!(
            (r.max_samples, r.columns, r.resample, r.trim_start_s),
            (cli.read.max_samples, cli.read.columns, cli.read.resample, cli.read.trim_start)
        );
    }

    /// Arrays pass where a CSV with the same numbers passes, and a bad element is named.
    #[test]
    fn arrays_are_read_as_the_csv_with_the_same_numbers() {
        let t: Vec<f64> = (0..50).map(|k| k as f64 * 1e-4).collect();
        let i: Vec<f64> = t.iter().map(|t| (300.0 * t).sin()).collect();
        let csv: String = std::iter::once("time_s,current_A\n".to_string())
            .chain(t.iter().zip(&i).map(|(t, i)| format!("{t:?},{i:?}\n")))
            .collect();
        let from_csv = Recording::parse("a", csv.as_bytes()).unwrap();
        let arrays = vec![("time_s".to_string(), t.clone()), ("current_A".to_string(), i.clone())];
        // The same numbers (arrays have no header line).
        assert_eq!(recording_from_arrays("a", arrays).unwrap(), Recording { header: Vec::new(), ..from_csv });
        let mut bad = i.clone();
        bad[7] = f64::INFINITY;
        let e =
            recording_from_arrays("a", vec![("time_s".into(), t), ("current_A".into(), bad)]).unwrap_err();
        let at = e.downcast_ref::<ArrayError>().unwrap();
        assert_eq!((at.array.as_str(), at.index), ("current_A", Some(7)));
    }

    /// `simulate_rig` takes the CLI's option names and refuses as the CLI does.
    #[test]
    fn rig_options_are_the_command_lines() {
        let opt = |o: &str, v: &str| (o.to_string(), Some(v.to_string()));
        let r = simulate_rig(None, &ParamsSource::Demo, &[opt("--duration-s", "0.01")], "s").unwrap();
        assert_eq!((r.len(), r.name.as_str()), (100, "s"));
        let e =
            simulate_rig(Some("ja"), &ParamsSource::Demo, &[opt("--waveform", "triangle")], "s").unwrap_err();
        assert!(e.to_string().contains("'triangle'") && e.to_string().contains("multisine"), "{e}");
        let e = simulate_rig(Some("ja"), &ParamsSource::Demo, &[opt("--freq-hz", "-5")], "s").unwrap_err();
        assert!(e.to_string().contains("--freq-hz must be a positive number"), "{e}");
    }
}
