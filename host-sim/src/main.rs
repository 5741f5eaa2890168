//! `gma`: the model workbench for giant-magnetostrictive actuators.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use host_sim::diagnose::{diagnose, Diagnosis};
use host_sim::fit::{self, FitOptions, FitResult};
use host_sim::recording::{write_atomic, Recording};
use host_sim::{cases, loops, params, plots, report, simulate};
use model_core::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};
use serde_json::json;

#[derive(Parser)]
#[command(
    name = "gma",
    version,
    about = "Model workbench for giant-magnetostrictive (Terfenol-D) actuators",
    long_about = "Model workbench for giant-magnetostrictive (Terfenol-D) actuators: compare a model \
                  with measurements, see where it fails, learn which physical effect is missing, add it \
                  and watch the error fall.\n\nMeasurement CSV columns (by name): time_s [s], command_V, \
                  current_A, displacement_um, force_N, temperature_C. Model specs are `+`-joined effects: \
                  linear, saturation|anhysteretic, hysteresis|ja, preisach, eddy_current|eddy, \
                  mechanical_dynamics|mech, amplifier_dynamics|amp, magnetic_aftereffect|aftereffect, \
                  thermal_drift|thermal, sensor_delay|delay."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on SIMULATED data, in under a minute: a rig with hidden effects, a diagnosis
    /// from a baseline model, the named effects added one by one, the error falling, an HTML report.
    #[command(allow_negative_numbers = true)]
    Demo(DemoArgs),
    /// Identify a model's parameters from one or more recordings jointly.
    #[command(allow_negative_numbers = true)]
    Fit(FitArgs),
    /// Per-file error and plots (loops, time series, residuals) of a model against recordings.
    #[command(allow_negative_numbers = true)]
    Compare(CompareArgs),
    /// Fit a model, analyse what it leaves unexplained and name the missing effect.
    #[command(allow_negative_numbers = true)]
    Diagnose(DiagnoseArgs),
    /// Climb the model ladder (diagnose, add the named effect, refit, repeat) and write one
    /// self-contained HTML page.
    #[command(allow_negative_numbers = true)]
    Report(ReportArgs),
    /// Turn the drive's telemetry stream (COBS frames captured from its UART) into measurement
    /// CSVs; lost and corrupt frames are counted, and every gap starts a new file.
    #[command(allow_negative_numbers = true)]
    Record(RecordArgs),
    /// Simulate a rig (plant simulator) and write a measurement CSV. SIMULATED data, for tests
    /// and demos.
    #[command(allow_negative_numbers = true)]
    Simulate(simulate::SimulateArgs),
    /// Natural frequency, damping ratio and step response of the actuator mechanics
    /// (m ÿ + c ẏ + k y = F, 001 eq. 14–15), discretised exactly at the loop rate.
    #[command(allow_negative_numbers = true)]
    Mechanics {
        /// Moving mass m [kg].
        #[arg(long, default_value_t = 0.1)]
        mass_kg: f32,
        /// Viscous damping c [N s/m].
        #[arg(long, default_value_t = 3000.0)]
        damping_n_s_per_m: f32,
        /// Stiffness k [N/m].
        #[arg(long, default_value_t = 9.9e6)]
        stiffness_n_per_m: f32,
        /// Sample rate [Hz] of the discretisation.
        #[arg(long, default_value_t = 10_000.0)]
        sample_rate_hz: f32,
        /// Step force [N] for the printed step response.
        #[arg(long, default_value_t = 100.0)]
        force_n: f32,
    },
}

/// Model, files and fit settings shared by fit, diagnose and report.
#[derive(Args)]
struct ModelFiles {
    /// Model spec, e.g. `ja+mech` (effects joined by `+`; see `gma --help`).
    #[arg(long)]
    model: String,
    /// Recordings (CSV) to fit.
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
    /// A validation recording: scored, never fitted (repeat `--val` for several files).
    #[arg(long, value_name = "FILE")]
    val: Vec<PathBuf>,
    /// Start values and fixed parameters (TOML as `--params-out` writes, e.g. from a loop fit);
    /// default: a Terfenol-D demo set.
    #[arg(long, visible_alias = "init", value_name = "P.toml")]
    params: Option<PathBuf>,
    /// Seed of the global search (same seed, same result).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Search effort (1 = default; 2 doubles the swarm iterations and simplex steps).
    #[arg(long, default_value_t = 1.0)]
    effort: f64,
    /// Print exactly one JSON object on stdout (human text goes to stderr).
    #[arg(long)]
    json: bool,
    /// Samples kept per file (memory ≈ 50 bytes per sample); longer files are still read and
    /// checked to the end, and the first this many samples are used, with a warning.
    #[arg(long, default_value_t = DEFAULT_MAX_SAMPLES, value_name = "N")]
    max_samples: usize,
}

/// 200 s at the board's 10 kHz: about 100 MB for a recording with every column.
const DEFAULT_MAX_SAMPLES: usize = 2_000_000;

/// Reads recordings as streams, keeping at most `max_samples` of each and saying so.
fn read_recordings(paths: &[PathBuf], max_samples: usize) -> Result<Vec<Recording>> {
    if max_samples < 3 {
        bail!("--max-samples must be at least 3, got {max_samples}");
    }
    paths
        .iter()
        .map(|p| {
            let (r, rows) = Recording::read_window(p, max_samples)?;
            if rows > r.len() as u64 {
                eprintln!(
                    "gma: warning: {}: {rows} samples; using the first {} ({:.1} s); raise --max-samples to use more",
                    r.name,
                    r.len(),
                    r.duration_s()
                );
            }
            Ok(r)
        })
        .collect()
}

/// What the shared options resolve to: spec, start parameters, fit files, validation files, options.
type Loaded = (model_core::ModelSpec, model_core::ActuatorParams, Vec<Recording>, Vec<Recording>, FitOptions);

impl ModelFiles {
    fn load(&self) -> Result<Loaded> {
        let spec = params::parse_spec(&self.model)?;
        let init = params::load(self.params.as_deref(), spec)?;
        if !(self.effort.is_finite() && self.effort > 0.0 && self.effort <= 20.0) {
            bail!("--effort must be in (0, 20], got {}", self.effort);
        }
        let (fit_files, val_files) =
            (read_recordings(&self.files, self.max_samples)?, read_recordings(&self.val, self.max_samples)?);
        for r in fit_files.iter().chain(&val_files) {
            fit::drive_for(spec, r)?;
        }
        // indicatif draws only when stderr is a terminal.
        let opts = FitOptions { seed: self.seed, progress: true, effort: self.effort };
        Ok((spec, init, fit_files, val_files, opts))
    }
}

#[derive(Args)]
struct FitArgs {
    #[command(flatten)]
    mf: ModelFiles,
    /// Write the identified parameter set here (TOML; `compare`, `simulate` and the firmware load it).
    #[arg(long, value_name = "P.toml")]
    params_out: Option<PathBuf>,
}

#[derive(Args)]
struct CompareArgs {
    /// Model spec, e.g. `ja+mech`.
    #[arg(long)]
    model: String,
    /// Parameter set (TOML from `gma fit --params-out`); default: the demo set.
    #[arg(long, value_name = "P.toml")]
    params: Option<PathBuf>,
    /// Recordings (CSV).
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
    /// Directory for the plots (created if missing).
    #[arg(long, default_value = "gma-compare")]
    out_dir: PathBuf,
    /// Plot format.
    #[arg(long, value_parser = ["svg", "png"], default_value = "svg")]
    format: String,
    /// Print exactly one JSON object on stdout.
    #[arg(long)]
    json: bool,
    /// Samples kept per file (see `gma fit --help`).
    #[arg(long, default_value_t = DEFAULT_MAX_SAMPLES, value_name = "N")]
    max_samples: usize,
}

#[derive(Args)]
struct DiagnoseArgs {
    #[command(flatten)]
    mf: ModelFiles,
}

#[derive(Args)]
struct ReportArgs {
    #[command(flatten)]
    mf: ModelFiles,
    /// The HTML file to write.
    #[arg(long, short, default_value = "gma-report.html")]
    out: PathBuf,
}

#[derive(Args)]
struct RecordArgs {
    /// The captured byte stream (`-` for stdin), e.g. `cat /dev/ttyACM0 > stream.bin`.
    #[arg(long, short)]
    input: PathBuf,
    /// Output CSV (segments after gaps get `-2`, `-3`, … suffixes; each file appears only when
    /// its segment is complete).
    #[arg(long, short)]
    out: PathBuf,
    /// Control tick [s] (the firmware's: 1e-4 s at 10 kHz).
    #[arg(long, default_value_t = 1e-4)]
    tick_s: f64,
    /// Print exactly one JSON object on stdout.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct DemoArgs {
    /// Directory for the simulated recordings, parameter files and the report.
    #[arg(long, default_value = "gma-demo")]
    out_dir: PathBuf,
    /// Seed of the simulated rig's noise and of the fits.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gma: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Human text goes to stdout, or to stderr in `--json` mode.
macro_rules! say {
    ($json:expr, $($t:tt)*) => {
        if $json { eprintln!($($t)*) } else { println!($($t)*) }
    };
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate::run(&a),
        Command::Fit(a) => run_fit(&a),
        Command::Compare(a) => run_compare(&a),
        Command::Diagnose(a) => run_diagnose(&a),
        Command::Report(a) => run_report(&a),
        Command::Demo(a) => run_demo(&a),
        Command::Record(a) => {
            host_sim::recording::check_output(&a.out)?;
            let stream = host_sim::record::open_stream(&a.input)?;
            let r = host_sim::record::record(stream, &a.out, a.tick_s)
                .with_context(|| format!("{}", a.input.display()))?;
            let files: Vec<String> = r.files.iter().map(|p| p.display().to_string()).collect();
            say!(
                a.json,
                "{} frames, {} lost (sequence gaps), {} corrupt, {} invalid, {} restarts; wrote {}",
                r.frames,
                r.lost,
                r.corrupt,
                r.invalid,
                r.restarts,
                files.join(", ")
            );
            if r.lost + r.corrupt + r.invalid + r.restarts > 0 {
                eprintln!(
                    "gma: warning: {} frames lost, {} corrupt chunks, {} frames with non-finite values, {} restarts; \
                     none of them written, and each gap starts a new file",
                    r.lost, r.corrupt, r.invalid, r.restarts
                );
            }
            if r.short > 0 {
                eprintln!(
                    "gma: warning: {} frames in segments shorter than 3 frames were not written",
                    r.short
                );
            }
            if a.json {
                println!(
                    "{}",
                    json!({"frames": r.frames, "lost": r.lost, "corrupt": r.corrupt, "invalid": r.invalid,
                           "restarts": r.restarts, "short": r.short, "files": files})
                );
            }
            Ok(())
        }
        Command::Mechanics { mass_kg, damping_n_s_per_m, stiffness_n_per_m, sample_rate_hz, force_n } => {
            for (name, v) in [
                ("--mass-kg", mass_kg),
                ("--stiffness-n-per-m", stiffness_n_per_m),
                ("--sample-rate-hz", sample_rate_hz),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    bail!("{name} must be a positive number, got {v}");
                }
            }
            if !(damping_n_s_per_m.is_finite() && damping_n_s_per_m >= 0.0) {
                bail!("--damping-n-s-per-m must be ≥ 0, got {damping_n_s_per_m}");
            }
            if !force_n.is_finite() {
                bail!("--force-n must be a finite number, got {force_n}");
            }
            let p = MassSpringDamper { mass_kg, damping_n_s_per_m, stiffness_n_per_m };
            let zoh = SecondOrderZoh::new(p, 1.0 / sample_rate_hz).context("mechanics parameters")?;
            println!("natural frequency f_n = {:.1} Hz", p.natural_frequency_hz());
            println!("damping ratio     ζ   = {:.3}", p.damping_ratio());
            println!("static compliance     = {:.4e} m/N", 1.0 / stiffness_n_per_m);
            println!("time_s,displacement_um");
            let mut s = MechState::default();
            for n in 0..20 {
                let y = zoh.step(&mut s, force_n);
                println!("{:.6},{:.6}", (n + 1) as f32 / sample_rate_hz, y * 1e6);
            }
            Ok(())
        }
    }
}

fn file_rows(
    res: &FitResult,
    spec: model_core::ModelSpec,
    fit_files: &[Recording],
    val_files: &[Recording],
) -> Result<(Vec<serde_json::Value>, Option<f64>)> {
    let mut rows = Vec::new();
    let push = |rows: &mut Vec<serde_json::Value>, r: &Recording, split: &str, s: &fit::FileScore| {
        rows.push(json!({"file": r.name, "split": split, "channel": "displacement", "nrmse": s.nrmse, "offset_um": s.offset_um}));
        if let Some(c) = s.nrmse_current {
            rows.push(json!({"file": r.name, "split": split, "channel": "current", "nrmse": c}));
        }
    };
    for (r, s) in fit_files.iter().zip(&res.fit.files) {
        push(&mut rows, r, "fit", s);
    }
    let mut nrmse_val = None;
    if !val_files.is_empty() {
        let ev = fit::evaluate(spec, &res.params, val_files)?;
        for (r, s) in val_files.iter().zip(&ev.files) {
            push(&mut rows, r, "val", s);
        }
        nrmse_val = Some(ev.mean_nrmse());
    }
    Ok((rows, nrmse_val))
}

/// Whether the first positional file is a magnetization-loop file (then all must be).
fn loop_files(paths: &[PathBuf], val: &[PathBuf]) -> Result<bool> {
    let mut kinds = Vec::new();
    for p in paths.iter().chain(val) {
        // The header decides; never read a whole (possibly huge) file for it.
        let mut head = Vec::with_capacity(4096);
        std::fs::File::open(p)
            .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 4096), &mut head))
            .with_context(|| format!("{}: cannot read", p.display()))?;
        kinds.push(loops::looks_like_loop(&String::from_utf8_lossy(&head)));
    }
    if kinds.iter().any(|k| *k) && !kinds.iter().all(|k| *k) {
        bail!("mixing magnetization-loop files and displacement recordings in one fit: fit them separately (a loop fit's --params-out can seed the displacement fit via --params)");
    }
    Ok(kinds.first().copied().unwrap_or(false))
}

/// `gma fit` on magnetization-loop files: the magnetization stage alone.
fn run_loop_fit(a: &FitArgs) -> Result<()> {
    let spec = params::parse_spec(&a.mf.model)?;
    let model = loops::LoopModel::from_spec(spec)?;
    let read = |v: &[PathBuf]| v.iter().map(|p| loops::read(p)).collect::<Result<Vec<_>>>();
    let (fit_files, val_files) = (read(&a.mf.files)?, read(&a.mf.val)?);
    let t = std::time::Instant::now();
    let opts = host_sim::search::SearchOptions { seed: a.mf.seed, effort: a.mf.effort };
    let res = loops::fit(model, &fit_files, opts)?;
    let j = a.mf.json;
    say!(
        j,
        "magnetization model `{spec}` fitted to {} loop file(s): {} evaluations in {:.1} s (seed {})",
        fit_files.len(),
        res.evaluations,
        t.elapsed().as_secs_f64(),
        a.mf.seed
    );
    for (n, v) in &res.params {
        say!(j, "  {n:20} = {v:.6e}");
    }
    let mut rows = Vec::new();
    for (f, e) in fit_files.iter().zip(&res.nrmse) {
        say!(j, "  fit   {:14} NRMSE {:6.3} %  {}", f.channel.name(), e * 100.0, f.name);
        rows.push(json!({"file": f.name, "split": "fit", "channel": f.channel.name(), "nrmse": e}));
    }
    let mut val_nrmse = Vec::new();
    let h_max =
        fit_files.iter().chain(&val_files).flat_map(|f| f.h.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    for f in &val_files {
        let m = loops::run(model, &res.values(), &f.h, h_max)
            .map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
        let e = fit::nrmse(&f.value, &f.channel_from_m(&m));
        say!(j, "  val   {:14} NRMSE {:6.3} %  {}", f.channel.name(), e * 100.0, f.name);
        rows.push(json!({"file": f.name, "split": "val", "channel": f.channel.name(), "nrmse": e}));
        val_nrmse.push(e);
    }
    for w in &res.warnings {
        eprintln!("gma: warning: {w}");
    }
    let failed: Vec<&String> = res
        .warnings
        .iter()
        .filter(|w| w.contains("integration failed") || w.contains("multivalued"))
        .collect();
    if let Some(out) = &a.params_out {
        let base = params::load(a.mf.params.as_deref(), spec)?;
        let header =
            format!("gma fit --model {spec} on loop files {}", host_sim::recording::names(&a.mf.files));
        write_atomic(out, params::to_toml(&res.apply_to(&base), &header)?.as_bytes())?;
        say!(j, "  parameters written to {}", out.display());
    }
    let nrmse_fit = res.nrmse.iter().sum::<f64>() / res.nrmse.len() as f64;
    let nrmse_val = (!val_nrmse.is_empty()).then(|| val_nrmse.iter().sum::<f64>() / val_nrmse.len() as f64);
    if j {
        let params: serde_json::Map<String, serde_json::Value> =
            res.params.iter().map(|(n, v)| (n.to_string(), json!(v))).collect();
        println!(
            "{}",
            json!({"model": spec.to_string(), "params": params, "nrmse_fit": nrmse_fit, "nrmse_val": nrmse_val,
            "files": rows, "evaluations": res.evaluations, "warnings": res.warnings, "seed": a.mf.seed})
        );
    }
    if !failed.is_empty() {
        bail!(
            "the loop fit did not produce a valid model: {}",
            failed.iter().map(|s| s.as_str()).collect::<Vec<_>>().join("; ")
        );
    }
    Ok(())
}

fn run_fit(a: &FitArgs) -> Result<()> {
    if let Some(out) = &a.params_out {
        host_sim::recording::check_output(out)?;
    }
    if loop_files(&a.mf.files, &a.mf.val)? {
        return run_loop_fit(a);
    }
    let (spec, init, fit_files, val_files, opts) = a.mf.load()?;
    let t = std::time::Instant::now();
    let res = fit::fit(spec, &init, &fit_files, opts)?;
    let (rows, nrmse_val) = file_rows(&res, spec, &fit_files, &val_files)?;
    let j = a.mf.json;
    say!(
        j,
        "model `{spec}` fitted to {} file(s): {} evaluations in {:.1} s (seed {})",
        fit_files.len(),
        res.evaluations,
        t.elapsed().as_secs_f64(),
        a.mf.seed
    );
    for (n, v) in &res.identified {
        say!(j, "  {n:40} = {v:.6e}");
    }
    for r in &rows {
        say!(
            j,
            "  {:5} {:12} NRMSE {:6.3} %  {}",
            r["split"].as_str().unwrap_or(""),
            r["channel"].as_str().unwrap_or(""),
            r["nrmse"].as_f64().unwrap_or(f64::NAN) * 100.0,
            r["file"].as_str().unwrap_or("")
        );
    }
    say!(
        j,
        "  mean fit NRMSE {:.3} %{}",
        res.fit.mean_nrmse() * 100.0,
        nrmse_val.map(|v| format!(", validation {:.3} %", v * 100.0)).unwrap_or_default()
    );
    if let Some(out) = &a.params_out {
        let header = format!(
            "gma fit --model {spec} (seed {}) on {}\nfit NRMSE {:.4} %",
            a.mf.seed,
            host_sim::recording::names(&a.mf.files),
            res.fit.mean_nrmse() * 100.0
        );
        write_atomic(out, params::to_toml(&res.params, &header)?.as_bytes())?;
        say!(j, "  parameters written to {}", out.display());
    }
    if j {
        let params: serde_json::Map<String, serde_json::Value> =
            res.identified.iter().map(|(n, v)| (n.to_string(), json!(v))).collect();
        println!(
            "{}",
            json!({"model": spec.to_string(), "params": params, "nrmse_fit": res.fit.mean_nrmse(), "nrmse_val": nrmse_val,
                   "files": rows, "evaluations": res.evaluations, "seed": a.mf.seed})
        );
    }
    Ok(())
}

fn run_compare(a: &CompareArgs) -> Result<()> {
    let spec = params::parse_spec(&a.model)?;
    let p = params::load(a.params.as_deref(), spec)?;
    std::fs::create_dir_all(&a.out_dir).with_context(|| format!("cannot create {}", a.out_dir.display()))?;
    let mut rows = Vec::new();
    let rung = report::Rung {
        spec,
        params: p,
        identified: Vec::new(),
        fit_nrmse: Vec::new(),
        val_nrmse: Vec::new(),
        diagnosis: Diagnosis {
            model: spec.to_string(),
            nrmse_fit: 0.0,
            nrmse_val: None,
            candidates: vec![],
            verdict: None,
            undistinguished: vec![],
            findings: vec![],
            baseline: None,
        },
    };
    if loop_files(&a.files, &[])? {
        return compare_loops(a, spec, &p);
    }
    let mut total = 0.0;
    // Every file is checked before the first plot is written: a bad file leaves no partial output.
    let recs = read_recordings(&a.files, a.max_samples)?;
    for r in &recs {
        fit::drive_for(spec, r)?;
    }
    for (path, rec) in a.files.iter().zip(recs) {
        let sim = fit::simulate(spec, &p, &rec)?;
        let sc = fit::score(spec, &rec, &sim);
        total += sc.nrmse;
        let stem = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "file".into());
        let mut written = Vec::new();
        let meas = rec.displacement_um.clone().unwrap_or_default();
        let time_chart = plots::Chart {
            title: format!("{} — time series", rec.name),
            x_label: "time [s]".into(),
            y_label: "displacement [µm]".into(),
            series: vec![
                plots::Series {
                    label: "measured".into(),
                    points: plots::thin(
                        &rec.time_s.iter().copied().zip(meas.iter().copied()).collect::<Vec<_>>(),
                        4000,
                    ),
                    color: 0,
                },
                plots::Series {
                    label: format!("model {spec}"),
                    points: plots::thin(
                        &rec.time_s
                            .iter()
                            .zip(&sim.displacement_um)
                            .map(|(t, y)| (*t, y + sc.offset_um))
                            .collect::<Vec<_>>(),
                        4000,
                    ),
                    color: 1,
                },
            ],
        };
        for (kind, chart) in [
            ("loop", report::loop_chart(&rec, std::slice::from_ref(&rung))?),
            ("time", time_chart),
            ("residual", report::residual_chart(&rec, std::slice::from_ref(&rung))?),
        ] {
            let out = a.out_dir.join(format!("{stem}-{kind}.{}", a.format));
            plots::write(&out, &chart)?;
            written.push(out.display().to_string());
        }
        say!(
            a.json,
            "{:50} NRMSE {:6.3} %  offset {:8.3} µm  plots: {}",
            rec.name,
            sc.nrmse * 100.0,
            sc.offset_um,
            written.join(", ")
        );
        rows.push(json!({"file": rec.name, "channel": "displacement", "nrmse": sc.nrmse, "offset_um": sc.offset_um, "plots": written}));
        if let Some(c) = sc.nrmse_current {
            rows.push(json!({"file": rec.name, "channel": "current", "nrmse": c}));
        }
    }
    let mean = total / a.files.len() as f64;
    say!(a.json, "mean NRMSE {:.3} % over {} file(s), model `{spec}`", mean * 100.0, a.files.len());
    if a.json {
        println!("{}", json!({"model": spec.to_string(), "nrmse": mean, "files": rows}));
    }
    Ok(())
}

/// `gma compare` on loop files: measured and model loops overlaid, and coercivity, remanence and
/// largest magnetization read from both.
fn compare_loops(a: &CompareArgs, spec: model_core::ModelSpec, p: &model_core::ActuatorParams) -> Result<()> {
    let model = loops::LoopModel::from_spec(spec)?;
    let values: Vec<f64> = match model {
        loops::LoopModel::Linear => vec![p.linear.offset_a_per_m as f64, p.linear.susceptibility as f64],
        loops::LoopModel::Anhysteretic => {
            vec![p.anhysteretic.ms_a_per_m as f64, p.anhysteretic.a_a_per_m as f64]
        }
        loops::LoopModel::JilesAtherton => {
            let j = p.ja;
            vec![j.ms_a_per_m as f64, j.a_a_per_m as f64, j.alpha as f64, j.k_a_per_m as f64, j.c as f64]
        }
        loops::LoopModel::Preisach => {
            vec![
                p.preisach.ms_a_per_m as f64,
                p.preisach.coercive_a_per_m as f64,
                p.preisach.spread_a_per_m as f64,
            ]
        }
    };
    let mut rows = Vec::new();
    let mut total = 0.0;
    for path in &a.files {
        let f = loops::read(path)?;
        let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let m =
            loops::run(model, &values, &f.h, h_max).map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
        let modelled = f.channel_from_m(&m);
        let e = fit::nrmse(&f.value, &modelled);
        total += e;
        let (fm, fmod) = (loops::features(&f.h, &f.magnetization()), loops::features(&f.h, &m));
        let stem = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "loop".into());
        let out = a.out_dir.join(format!("{stem}-loop.{}", a.format));
        let chart = loops::chart(&f, &m, &spec.to_string());
        plots::write(&out, &chart)?;
        say!(a.json, "{:40} NRMSE {:6.3} %  plot: {}", f.name, e * 100.0, out.display());
        say!(a.json, "  {:28} {:>14} {:>14}", "", "measured", "model");
        for (name, x, y) in [
            ("coercivity H_c [A/m]", fm.coercivity_a_per_m, fmod.coercivity_a_per_m),
            ("remanence M_r [A/m]", fm.remanence_a_per_m, fmod.remanence_a_per_m),
            ("largest |M| [A/m]", fm.max_magnetization_a_per_m, fmod.max_magnetization_a_per_m),
        ] {
            say!(a.json, "  {name:28} {x:>14.4e} {y:>14.4e}");
        }
        rows.push(json!({"file": f.name, "channel": f.channel.name(), "nrmse": e, "plots": [out.display().to_string()],
            "measured": {"coercivity_a_per_m": fm.coercivity_a_per_m, "remanence_a_per_m": fm.remanence_a_per_m, "max_magnetization_a_per_m": fm.max_magnetization_a_per_m},
            "model": {"coercivity_a_per_m": fmod.coercivity_a_per_m, "remanence_a_per_m": fmod.remanence_a_per_m, "max_magnetization_a_per_m": fmod.max_magnetization_a_per_m}}));
    }
    let mean = total / a.files.len() as f64;
    if a.json {
        println!("{}", json!({"model": spec.to_string(), "nrmse": mean, "files": rows}));
    }
    Ok(())
}

fn diagnosis_json(d: &Diagnosis) -> serde_json::Value {
    json!({
        "model": d.model, "nrmse_fit": d.nrmse_fit, "nrmse_val": d.nrmse_val,
        "candidates": d.candidates.iter().map(|c| json!({
            "effect": c.effect, "channel": c.channel, "score": c.score, "evidence": c.evidence,
            "nrmse_before": c.nrmse_before, "nrmse_after": c.nrmse_after, "evidence_r2": c.evidence_r2})).collect::<Vec<_>>(),
        "verdict": d.verdict, "undistinguished": d.undistinguished, "findings": d.findings,
    })
}

fn print_diagnosis(j: bool, d: &Diagnosis) {
    say!(
        j,
        "model `{}`: fit NRMSE {:.3} %{}",
        d.model,
        d.nrmse_fit * 100.0,
        d.nrmse_val.map(|v| format!(", validation {:.3} %", v * 100.0)).unwrap_or_default()
    );
    for f in &d.findings {
        say!(j, "  - {f}");
    }
    say!(j, "  candidates (most likely first):");
    for c in &d.candidates {
        say!(
            j,
            "    {:22} score {:.2}  {:.2} % → {:.2} %  {}",
            c.effect,
            c.score,
            c.nrmse_before * 100.0,
            c.nrmse_after * 100.0,
            c.evidence
        );
    }
    match d.verdict {
        Some(v) => say!(j, "verdict: `{v}` is missing — try `--model {}+{v}`", d.model),
        None => say!(j, "verdict: nothing significant is missing"),
    }
}

fn run_diagnose(a: &DiagnoseArgs) -> Result<()> {
    let (spec, init, fit_files, val_files, opts) = a.mf.load()?;
    let d = diagnose(spec, &init, &fit_files, &val_files, opts)?;
    print_diagnosis(a.mf.json, &d);
    if a.mf.json {
        println!("{}", diagnosis_json(&d));
    }
    Ok(())
}

fn write_report(
    path: &Path,
    title: &str,
    rungs: &[report::Rung],
    fit_files: &[Recording],
    val_files: &[Recording],
    note: &str,
) -> Result<()> {
    let html = report::html(title, rungs, fit_files, val_files, note)?;
    write_atomic(path, html.as_bytes())
}

fn run_report(a: &ReportArgs) -> Result<()> {
    host_sim::recording::check_output(&a.out)?;
    if loop_files(&a.mf.files, &a.mf.val)? {
        let spec = params::parse_spec(&a.mf.model)?;
        let files = a.mf.files.iter().map(|p| loops::read(p)).collect::<Result<Vec<_>>>()?;
        let opts = host_sim::search::SearchOptions { seed: a.mf.seed, effort: a.mf.effort };
        let res = loops::fit(loops::LoopModel::from_spec(spec)?, &files, opts)?;
        write_atomic(&a.out, loops::html(&spec.to_string(), &res, &files)?.as_bytes())?;
        say!(a.mf.json, "loop report written to {}", a.out.display());
        if a.mf.json {
            println!(
                "{}",
                json!({"report": a.out.display().to_string(), "nrmse": res.nrmse, "warnings": res.warnings})
            );
        }
        return Ok(());
    }
    let (spec, init, fit_files, val_files, opts) = a.mf.load()?;
    let j = a.mf.json;
    let rungs =
        report::ladder(spec, &init, &fit_files, &val_files, opts, |r| print_diagnosis(j, &r.diagnosis))?;
    write_report(&a.out, &format!("gma report — {spec}"), &rungs, &fit_files, &val_files, "")?;
    say!(j, "report written to {}", a.out.display());
    if j {
        println!(
            "{}",
            json!({"report": a.out.display().to_string(),
            "ladder": rungs.iter().map(|r| json!({"model": r.spec.to_string(), "nrmse_fit": r.fit_nrmse, "nrmse_val": r.val_nrmse, "verdict": r.diagnosis.verdict})).collect::<Vec<_>>()})
        );
    }
    Ok(())
}

fn run_demo(a: &DemoArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let case = cases::demo();
    std::fs::create_dir_all(&a.out_dir).with_context(|| format!("cannot create {}", a.out_dir.display()))?;
    println!(
        "gma demo: a SIMULATED Terfenol-D rig with {}, unknown to the engineer, whose model is `{}`.",
        case.plant.describe(),
        case.model
    );
    let (fit_files, val_files) = case.recordings(a.seed)?;
    for r in fit_files.iter().chain(&val_files) {
        let p = a.out_dir.join(&r.name);
        r.write(&p)?;
    }
    println!(
        "  recordings: {} fit, {} validation (different frequencies and amplitudes) in {}",
        fit_files.len(),
        val_files.len(),
        a.out_dir.display()
    );
    let opts = FitOptions { seed: a.seed, progress: false, effort: 1.0 };
    let rungs = report::ladder(case.model, &case.init, &fit_files, &val_files, opts, |r| {
        let d = &r.diagnosis;
        println!("\n  model `{}`: validation NRMSE {:.2} %", r.spec, r.headline() * 100.0);
        for c in d.candidates.iter().take(3) {
            println!(
                "    {:22} {:.2} % → {:.2} % after adding it",
                c.effect,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0
            );
        }
        match d.verdict {
            Some(v) => println!("    → missing: `{v}`; adding it"),
            None => println!("    → nothing significant is missing"),
        }
    })?;
    for (k, r) in rungs.iter().enumerate() {
        let p = a.out_dir.join(format!("params-{k}-{}.toml", r.spec.to_string().replace('+', "_")));
        write_atomic(&p, params::to_toml(&r.params, &format!("gma demo, model {}", r.spec))?.as_bytes())?;
    }
    let html = a.out_dir.join("report.html");
    write_report(&html, "gma demo — finding the missing physics (SIMULATED rig)", &rungs, &fit_files, &val_files,
        &format!("Simulated rig with {}; the engineer starts from `{}`. Every number below comes from the fits in this run.", case.plant.describe(), case.model))?;
    let first = rungs.first().map(|r| r.headline()).unwrap_or(f64::NAN);
    let last = rungs.last().map(|r| r.headline()).unwrap_or(f64::NAN);
    println!(
        "\n  validation NRMSE {:.2} % (`{}`) → {:.2} % (`{}`), {:.0}× lower; report: {} ({:.1} s)",
        first * 100.0,
        case.model,
        last * 100.0,
        rungs.last().map(|r| r.spec.to_string()).unwrap_or_default(),
        first / last,
        html.display(),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
