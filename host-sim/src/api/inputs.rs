//! What fit, diagnose and report share: the model, the files, the search settings, and reading
//! the inputs once (recordings or magnetization loops, sniffed from each file's first line).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use clap::Args;
use model_core::{ActuatorParams, ModelSpec};

use crate::columns::ReadOptions;
use crate::data_doubts::DataDoubt;
use crate::files::{check_outputs, open_all, Input, InputId};
use crate::fit::{self, FitOptions};
use crate::loops::{self, LoopFile};
use crate::params::{self, ParamSource};
use crate::recording::Recording;
use crate::same_samples;
use crate::search::SearchOptions;
use crate::warning::{warn, Warning};

/// 200 s at the board's 10 kHz: about 100 MB for a recording with every column.
pub const DEFAULT_MAX_SAMPLES: usize = 2_000_000;

/// Longest `--time-limit` accepted [s] (a week).
const MAX_TIME_LIMIT_S: f64 = 7.0 * 24.0 * 3600.0;

/// Model, files and fit settings shared by fit, diagnose and report.
#[derive(Args)]
pub struct ModelFiles {
    /// Model spec, e.g. `ja+mech` (effects joined by `+`; see `gma --help`).
    #[arg(long)]
    pub model: String,
    /// Recordings (CSV) or magnetization-loop files to fit; `-` reads standard input.
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// A validation file, of the kind of the files fitted (a recording; a loop file where loops
    /// are fitted): scored, never fitted (repeat `--val` for several files).
    #[arg(long, value_name = "FILE")]
    pub val: Vec<PathBuf>,
    /// Start values and fixed parameters (TOML as `--params-out` writes, e.g. from a loop fit);
    /// default: a Terfenol-D demo set.
    #[arg(long, visible_alias = "init", value_name = "P.toml")]
    pub params: Option<PathBuf>,
    /// Seed of the global search (same seed and inputs, same result, unless `--time-limit` cuts
    /// the search short).
    #[arg(long, default_value_t = 1, value_parser = seed)]
    pub seed: u64,
    /// Search effort in (0, 20] (1 = default; 2 doubles the swarm iterations, simplex steps and
    /// least-squares Jacobians).
    #[arg(long, default_value_t = 1.0)]
    pub effort: f64,
    /// Stop searching after this many seconds and use the best result found so far (said so in
    /// the output and the JSON's `time_limit_reached`).
    #[arg(long, value_name = "SECONDS")]
    pub time_limit: Option<f64>,
    /// Print exactly one JSON object on stdout (human text goes to stderr).
    #[arg(long)]
    pub json: bool,
    /// How the recordings (fit and validation files alike) are read.
    #[command(flatten)]
    pub read: ReadArgs,
}

/// How measurement CSVs are read when their columns are not as `gma` writes them; shared by
/// fit, diagnose, report and compare, applied to every recording (fit and `--val` files).
#[derive(Args, Clone, Debug)]
pub struct ReadArgs {
    /// Samples (or loop points) kept per file (memory ≈ 50 bytes per sample); longer files are
    /// still read and checked to the end, and the first this many samples are used, with a warning.
    #[arg(long, default_value_t = DEFAULT_MAX_SAMPLES, value_name = "N")]
    pub max_samples: usize,
    /// Read the file's column HEADER as the recognised column CANONICAL, converting from UNIT,
    /// e.g. `--column time_s=time_ms:ms`, `--column displacement_um=x_mm:mm`, `--column
    /// current_A=I:mA`. Units: time_s s|ms|us|µs; displacement_um m|mm|um|µm|nm; current_A
    /// A|mA|uA|µA; command_V V|mV; force_N N|kN; temperature_C °C|C|K|°F|F; flux_density_T T|mT|G
    /// (e.g. `--column flux_density_T=B:mT`). No UNIT: the canonical unit (a rename); `-HEADER`
    /// negates the column (`--column displacement_um=-displacement_um`). Repeat for several
    /// columns. Unmapped columns are read by their exact names, or from a header that names
    /// quantity and unit (`Time [s]`, `I (mA)`), said in a note.
    #[arg(long = "column", value_name = "CANONICAL=[-]HEADER[:UNIT]")]
    pub columns: Vec<String>,
    /// Put the recordings onto a uniform time grid: `linear` interpolates every channel linearly
    /// at the median time step, from the first sample to the last. Lets time stamps jitter by
    /// more than 1 % of the median step (refused without it); gaps over 5 median steps are
    /// still refused.
    #[arg(long, value_name = "METHOD")]
    pub resample: Option<String>,
    /// Drop the samples before t0 + SECONDS (t0: the file's first time stamp), e.g. a start-up
    /// transient; ≥ 0, and at least 3 samples must remain. Applied before `--max-samples` and
    /// `--resample`.
    #[arg(long, value_name = "SECONDS")]
    pub trim_start: Option<f64>,
    /// Pass over the first N lines of each recording before its header: a logger's preamble
    /// (a LabVIEW header block, an oscilloscope's settings lines). Line numbers in messages
    /// stay the file's.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub skip_rows: usize,
}

impl Default for ReadArgs {
    /// Files read as `gma` writes them: no mapping, no resampling, no trimming.
    fn default() -> Self {
        Self {
            max_samples: DEFAULT_MAX_SAMPLES,
            columns: Vec::new(),
            resample: None,
            trim_start: None,
            skip_rows: 0,
        }
    }
}

impl ReadArgs {
    /// Whether every option is at its default (nothing to apply).
    pub fn is_default(&self) -> bool {
        self.max_samples == DEFAULT_MAX_SAMPLES
            && self.columns.is_empty()
            && self.resample.is_none()
            && self.trim_start.is_none()
            && self.skip_rows == 0
    }

    /// The options, checked (each message names its option).
    pub fn options(&self) -> Result<ReadOptions> {
        Ok(ReadOptions::new(&self.columns, self.resample.as_deref(), self.trim_start)?
            .skipping(self.skip_rows))
    }
}

/// The inputs, read: displacement recordings or magnetization loops (never a mix).
pub enum Data {
    /// Displacement recordings: fit files and validation files.
    Recordings(Vec<Recording>, Vec<Recording>),
    /// Magnetization loops: fit files and validation files.
    Loops(Vec<LoopFile>, Vec<LoopFile>),
}

/// Everything a fitting command needs, checked before any work.
pub struct Prepared {
    /// The model.
    pub spec: ModelSpec,
    /// Start values (and fixed parameters).
    pub init: ActuatorParams,
    /// The files.
    pub data: Data,
    /// Search settings (the deadline runs from when the inputs were read).
    pub opts: FitOptions,
    /// Where the start values came from (a file or the built-in demo set).
    pub params_source: ParamSource,
    /// Doubts about the inputs themselves: a `--val` file with a fit file's content, a fit file
    /// typed right after a `--val` file, a Preisach plane far wider than the fields reached.
    pub input_warnings: Vec<Warning>,
    /// Every input (files, `--val` files, `--params`): outputs planned after the work (named
    /// after its results) are checked against them too.
    pub inputs: Vec<InputId>,
}

impl Prepared {
    /// The same settings for the loop search.
    pub fn search_options(&self) -> SearchOptions {
        SearchOptions { seed: self.opts.seed, effort: self.opts.effort, deadline: self.opts.deadline }
    }

    /// Says the doubts about the inputs on stderr (commands without a JSON `warnings` list;
    /// `fit` lists them with its other warnings).
    pub fn warn_about_inputs(&self) {
        for w in &self.input_warnings {
            w.say();
        }
    }
}

/// The fit files typed right after a `--val` file whose name looks like its sibling
/// (`--val run-val1.csv run-val2.csv`, as the glob `--val *val*.csv` writes it): `--val` takes
/// one file, so the second is read as a fit file, which the user may not mean. A differently
/// named file there (`--val val.csv fit1.csv`, the documented form) is a fit file as typed.
fn fit_files_after_val(args: &[std::ffi::OsString], fit_files: &[PathBuf]) -> Vec<(PathBuf, PathBuf)> {
    let mut found = Vec::new();
    for (k, arg) in args.iter().enumerate() {
        let text = arg.to_string_lossy();
        let (val, next) = match text.strip_prefix("--val=") {
            Some(v) => (PathBuf::from(v), k + 1),
            None if text == "--val" => match args.get(k + 1) {
                Some(v) => (PathBuf::from(v), k + 2),
                None => continue,
            },
            None => continue,
        };
        if let Some(after) = args.get(next) {
            let after = PathBuf::from(after);
            if !after.to_string_lossy().starts_with('-')
                && fit_files.contains(&after)
                && look_alike(&val, &after)
            {
                found.push((val, after));
            }
        }
    }
    found
}

/// Whether two file names look like one pattern's matches: their stems (names without the
/// extension) share a start or an end of at least three characters (`run-val1`, `run-val2`;
/// `sine_val`, `chirp_val`), and the second does not call itself a fit file where the first
/// does not (`demo-val1`, `demo-fit1`: a fit file as typed).
fn look_alike(a: &Path, b: &Path) -> bool {
    let stem =
        |p: &Path| p.file_stem().map(|s| s.to_string_lossy().to_lowercase().chars().collect::<Vec<char>>());
    let (Some(a), Some(b)) = (stem(a), stem(b)) else { return false };
    let says_fit = |s: &[char]| {
        let s: String = s.iter().collect();
        s.contains("fit") || s.contains("train")
    };
    if says_fit(&b) && !says_fit(&a) {
        return false;
    }
    let start = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let end = a.iter().rev().zip(b.iter().rev()).take_while(|(x, y)| x == y).count();
    start.max(end) >= 3
}

impl ModelFiles {
    /// Parses the spec, opens every input once (files, `-`, pipes), checks the `outputs` (none
    /// may be an input, a link or a device; their folders must take files), then reads the data.
    pub fn prepare(&self, outputs: &[&Path]) -> Result<Prepared> {
        self.prepare_also_for(outputs, |_| Ok(None))
    }

    /// As [`ModelFiles::prepare`], the parameter file (and the Preisach plane's advice) also
    /// checked for the structure `also` gives from the spec, with its role: one the command
    /// fits from the same start values (`diagnose --laws`: the other law). `also` refuses a spec
    /// it has no structure for, before any file is read.
    pub fn prepare_also_for(
        &self,
        outputs: &[&Path],
        also: impl Fn(ModelSpec) -> Result<Option<(ModelSpec, &'static str)>>,
    ) -> Result<Prepared> {
        let spec = params::parse_spec(&self.model)?;
        let also = also(spec)?;
        check_max_samples(self.read.max_samples)?;
        if !(self.effort.is_finite() && self.effort > 0.0 && self.effort <= 20.0) {
            bail!("--effort must be in (0, 20], got {}", self.effort);
        }
        let time_limit = self.time_limit.map(time_limit).transpose()?;
        let read_opts = self.read.options()?;
        let params_input = self.params.as_deref().map(Input::open).transpose()?;
        let (fit_in, val_in) = (open_all(&self.files)?, open_all(&self.val)?);
        let all: Vec<_> = fit_in.iter().chain(&val_in).chain(params_input.as_ref()).map(Input::id).collect();
        check_outputs(outputs, &all)?;
        let (init, params_source) = params::load_input_also_for(params_input, spec, also, "start values")?;
        let (data, mut input_warnings) = read_inputs(fit_in, val_in, self.read.max_samples, &read_opts)?;
        if let Data::Recordings(fit_files, val_files) = &data {
            fit::check_files(spec, &init, fit_files.iter().chain(val_files))?;
            input_warnings.extend(fit::data_doubts(spec, &init, fit_files.iter().chain(val_files))?);
            input_warnings.extend(crate::simulation::preisach_plane_advice(spec, &init, fit_files));
            if let Some((other, _)) = also {
                input_warnings.extend(crate::simulation::preisach_plane_advice(other, &init, fit_files));
            }
        }
        let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
        input_warnings.extend(fit_files_after_val(&args, &self.files).into_iter().map(|(val, fit)| {
            Warning::FitFileAfterVal { val: val.display().to_string(), fit: fit.display().to_string() }
        }));
        let deadline = time_limit.map(|t| Instant::now() + t);
        let opts = FitOptions { seed: self.seed, progress: true, effort: self.effort, deadline };
        Ok(Prepared { spec, init, data, opts, params_source, input_warnings, inputs: all })
    }
}

impl ModelFiles {
    /// Says on stderr that `--time-limit` cut the work short, when it did.
    pub fn warn_if_time_limited(&self, reached: bool) {
        if reached {
            warn(Warning::TimeLimit { seconds: self.time_limit.unwrap_or(f64::NAN) });
        }
    }
}

/// A `--time-limit` value as a duration, or why it is not one.
pub fn time_limit(seconds: f64) -> Result<Duration> {
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= MAX_TIME_LIMIT_S) {
        bail!("--time-limit must be in (0, {MAX_TIME_LIMIT_S}] s, got {seconds}");
    }
    Ok(Duration::from_secs_f64(seconds))
}

/// A `--seed`: a whole number from 0 (clap's own parse said only "invalid digit found in
/// string" for `-1`).
pub fn seed(s: &str) -> std::result::Result<u64, String> {
    s.trim().parse().map_err(|_| format!("a seed is a whole number from 0 to {}, got `{s}`", u64::MAX))
}

/// `--max-samples` must leave a recording (3 samples) and a loop (5 points).
pub fn check_max_samples(n: usize) -> Result<()> {
    if n < 5 {
        bail!("--max-samples must be at least 5, got {n}");
    }
    Ok(())
}

/// As [`read_data`], and says which input repeats an earlier one's content (it counts twice), and
/// which validation input has a fit input's content (its validation figure would be a fit
/// figure); the same file given twice or a copy, compared by the SHA-256 of the bytes read.
pub fn read_inputs(
    fit_in: Vec<Input>,
    val_in: Vec<Input>,
    max_samples: usize,
    opts: &ReadOptions,
) -> Result<(Data, Vec<Warning>)> {
    let digests =
        |inputs: &[Input]| -> Vec<_> { inputs.iter().map(|i| (i.name.clone(), i.digest())).collect() };
    let (fit_digests, val_digests) = (digests(&fit_in), digests(&val_in));
    let (data, mut warnings) = read_data(fit_in, val_in, max_samples, opts)?;
    // Every input has been read to its end: the digests are final.
    let fit_sha: Vec<(String, String)> = fit_digests.into_iter().map(|(n, d)| (n, d.sha256())).collect();
    warnings.extend(repeated_inputs(&fit_sha, "the fit's cost and its mean NRMSE"));
    let val_sha: Vec<(String, String)> = val_digests.into_iter().map(|(n, d)| (n, d.sha256())).collect();
    warnings.extend(repeated_inputs(&val_sha, "the validation files' mean NRMSE"));
    let same_bytes: Vec<Warning> = val_sha
        .into_iter()
        .filter_map(|(val, sha)| {
            let (fit, _) = fit_sha.iter().find(|(_, s)| *s == sha)?;
            Some(Warning::ValidationIsFitFile { val, fit: fit.clone() })
        })
        .collect();
    // Other bytes, the same samples: a fit file reprinted, shifted in time or cut.
    if let Data::Recordings(fit, val) = &data {
        for v in val {
            let said = |f: &Recording| {
                same_bytes.iter().any(|w| matches!(w, Warning::ValidationIsFitFile { val, fit } if *val == v.name && *fit == f.name))
            };
            let shared = fit.iter().filter(|f| !said(f)).find_map(|f| Some((f, same_samples::shared(v, f)?)));
            if let Some((f, s)) = shared {
                warnings.push(Warning::Data(DataDoubt::ValidationSharesFitSamples {
                    val: v.name.clone(),
                    fit: f.name.clone(),
                    samples: s.samples,
                    val_samples: v.len(),
                    val_from_s: v.time_s[s.first_at],
                    fit_from_s: f.time_s[s.second_at],
                }));
            }
        }
    }
    warnings.extend(same_bytes);
    Ok((data, warnings))
}

/// The inputs with the content of an earlier one (name, SHA-256 of the bytes read): each counts
/// again `counts_in` (a mean over the files, a fit's cost).
pub fn repeated_inputs(inputs: &[(String, String)], counts_in: &'static str) -> Vec<Warning> {
    inputs
        .iter()
        .enumerate()
        .filter_map(|(k, (again, sha))| {
            let (first, _) = inputs[..k].iter().find(|(_, s)| s == sha)?;
            Some(Warning::SameInputTwice { first: first.clone(), again: again.clone(), counts_in })
        })
        .collect()
}

/// Reads opened inputs: all recordings or all loop files (decided by each first line, as
/// [`crate::columns::is_loop_file`] maps it). `opts` applies to recordings only. The warnings
/// say which inputs `max_samples` cut short, and what the reader says about each recording.
pub fn read_data(
    fit_in: Vec<Input>,
    val_in: Vec<Input>,
    max_samples: usize,
    opts: &ReadOptions,
) -> Result<(Data, Vec<Warning>)> {
    let kinds: Vec<bool> = fit_in
        .iter()
        .chain(&val_in)
        .map(|i| crate::columns::is_loop_file(&i.name, &i.first_line(), opts))
        .collect::<Result<_>>()?;
    if kinds.iter().any(|k| *k) && !kinds.iter().all(|k| *k) {
        bail!(
            "mixing magnetization-loop files and displacement recordings in one fit: fit them separately \
             (a loop fit's --params-out can seed the displacement fit via --params)"
        );
    }
    let mut cut = Vec::new();
    let data = if kinds.first().copied().unwrap_or(false) {
        if !opts.is_default() {
            bail!(
                "--column, --resample, --trim-start and --skip-rows apply to measurement recordings, not to \
                 magnetization-loop files"
            );
        }
        let mut read = |v: Vec<Input>| -> Result<Vec<_>> {
            v.into_iter().map(|i| loops::read_input(i, max_samples).map(|r| kept(&mut cut, r))).collect()
        };
        let fit = read(fit_in)?;
        Data::Loops(fit, read(val_in)?)
    } else {
        let mut read = |v: Vec<Input>| -> Result<Vec<_>> {
            v.into_iter().map(|i| read_recording(i, max_samples, opts).map(|r| kept(&mut cut, r))).collect()
        };
        let fit = read(fit_in)?;
        Data::Recordings(fit, read(val_in)?)
    };
    Ok((data, cut))
}

/// What was read, its warnings set aside in `cut`.
fn kept<T, W: IntoIterator<Item = Warning>>(cut: &mut Vec<Warning>, (read, warning): (T, W)) -> T {
    cut.extend(warning);
    read
}

/// Reads one recording as a stream (mapped, trimmed and resampled as `opts` say), keeping at
/// most `max_samples`; the warnings say when it cut the file short, and what the reader has to
/// say about its columns and time axis.
pub fn read_recording(
    input: Input,
    max_samples: usize,
    opts: &ReadOptions,
) -> Result<(Recording, Vec<Warning>)> {
    let read = Recording::read_input_with(input, max_samples, opts)?;
    let r = read.recording;
    let mut warnings: Vec<Warning> = read.doubts.into_iter().map(Warning::Read).collect();
    warnings.extend((read.rows > read.kept as u64).then(|| Warning::Truncated {
        file: r.name.clone(),
        found: read.rows,
        kept: read.kept,
        kept_s: Some(r.duration_s()),
        after_trim_start: opts.trim_start_s.is_some(),
    }));
    // Gaps bridged by `--resample linear` are data the rig did not record: said.
    if opts.resample.is_some() && r.len() > read.kept {
        crate::warning::note(format_args!(
            "{}: --resample linear put {} samples onto {} at the median step {:.3e} s: {} were filled in \
             across gaps by interpolation",
            r.name,
            read.kept,
            r.len(),
            r.dt_s(),
            r.len() - read.kept
        ));
    }
    Ok((r, warnings))
}
