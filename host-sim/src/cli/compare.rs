//! `gma compare`: per-file error and plots of a model (with a given parameter set) against
//! recordings or magnetization loops.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use model_core::{ActuatorParams, ModelSpec};

use crate::analysis;
use crate::api::inputs::{check_max_samples, read_data, repeated_inputs, Data, ReadArgs};
use crate::files::{
    check_outputs, display, is_stdout, no_stdout, open_all, output_folder, replaces_only, to_stdout,
    unique_stems, Input, OutputKind, OutputWriter,
};
use crate::fit::{self};
use crate::loop_fit;
use crate::loop_plots;
use crate::loops::{self, LoopFile};
use crate::params;
use crate::plots::{self, Chart, XScale};
use crate::provenance::Provenance;
use crate::recording::Recording;
use crate::report;
use crate::results::{CompareSummary, FileScoreRow};
use crate::simulated::Simulation;
use crate::warning::{by_weight, Warning};

/// Options of `gma compare`.
#[derive(Args)]
pub struct CompareArgs {
    /// Model spec, e.g. `ja+mech`.
    #[arg(long)]
    pub model: String,
    /// Parameter set (TOML from `gma fit --params-out`); default: the built-in Terfenol-D demo
    /// set (said so on stderr).
    #[arg(long, value_name = "P.toml")]
    pub params: Option<PathBuf>,
    /// Recordings (CSV) or magnetization-loop files; `-` reads standard input.
    #[arg(required = true, value_name = "FILE")]
    pub files: Vec<PathBuf>,
    /// Directory for the plots (created if missing); one set of plots per input, named after it
    /// (`x-loop.svg`; a second input named `x` gets `x-2-loop.svg`).
    #[arg(long, default_value = "gma-compare")]
    pub out_dir: PathBuf,
    /// Plot format.
    #[arg(long, value_parser = ["svg", "png"], default_value = "svg")]
    pub format: String,
    /// Also write one CSV of every recording's time series: columns `file, time_s, measured_um,
    /// model_um, residual_um` (model with its fitted offset; residual = measured − model), and
    /// `measured_flux_T, model_flux_T, residual_flux_T` when a recording has `flux_density_T`
    /// (empty cells for the recordings without it). `-` writes it to standard output, and the
    /// text to stderr (not with `--json`).
    #[arg(long, value_name = "PATH")]
    pub out_csv: Option<PathBuf>,
    /// Largest lag [samples] of the residual autocorrelation and input cross-correlation.
    #[arg(long, value_name = "L", default_value_t = analysis::DEFAULT_MAX_LAG)]
    pub max_lag: usize,
    /// Print exactly one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// How the recordings are read (see `gma fit --help`).
    #[command(flatten)]
    pub read: ReadArgs,
}

/// Runs `gma compare`.
pub fn run(a: &CompareArgs) -> Result<()> {
    let spec = params::parse_spec(&a.model)?;
    no_stdout("--out-dir", &a.out_dir, "the folder of the plots")?;
    if let Some(csv) = &a.out_csv {
        to_stdout("--out-csv", csv, a.json)?;
    }
    check_max_samples(a.read.max_samples)?;
    let read_opts = a.read.options()?;
    let params_input = a.params.as_deref().map(Input::open).transpose()?;
    let inputs = open_all(&a.files)?;
    let ids: Vec<_> = inputs.iter().chain(params_input.as_ref()).map(Input::id).collect();
    let (p, source) = params::load_input(params_input, spec, "the compared parameters")?;
    let folder = output_folder(&a.out_dir)?;
    let stems = unique_stems(&a.files);
    if a.max_lag == 0 || a.max_lag > analysis::MAX_LAG_LIMIT {
        anyhow::bail!(
            "--max-lag {}: give a number of samples from 1 to {}",
            a.max_lag,
            analysis::MAX_LAG_LIMIT
        );
    }
    let planned: Vec<PathBuf> = stems
        .iter()
        .flat_map(|s| PLOTS.map(|k| plot_path(a, s, k)))
        .chain(a.out_csv.iter().cloned())
        .collect();
    check_outputs(&planned.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &ids)?;
    if let Some(csv) = &a.out_csv {
        replaces_only(csv, OutputKind::ComparisonTable, "--out-csv")?;
    }
    let digests: Vec<_> = inputs.iter().map(|i| (i.name.clone(), i.digest())).collect();
    let (data, mut cut) = read_data(inputs, Vec::new(), a.read.max_samples, &read_opts)?;
    // Every input has been read to its end: the digests are final.
    cut.extend(repeated_inputs(
        &digests.into_iter().map(|(n, d)| (n, d.sha256())).collect::<Vec<_>>(),
        "the mean NRMSE",
    ));
    let mut summary = match data {
        Data::Loops(files, _) => {
            if let Some(csv) = &a.out_csv {
                anyhow::bail!(
                    "--out-csv {}: writes recordings' time series; {} is a magnetization loop (no time axis)",
                    display(csv),
                    files.first().map(|f| f.name.as_str()).unwrap_or("the input")
                );
            }
            cut.extend(files.iter().filter_map(loops::field_in_kilo));
            compare_loops(a, spec, &p, &files, &stems)?
        }
        Data::Recordings(files, _) => {
            let (summary, doubts) = compare_recordings(a, spec, (&p, &source), &files, &stems)?;
            cut.extend(doubts);
            summary
        }
    };
    summary.warnings = cut.iter().map(ToString::to_string).collect();
    // A set the fit and the drive refuse, run as given: said on stderr when the file was read,
    // and listed with the other doubts, so that `--json` carries it too.
    if let Some(why) = params::multivalued_ja(spec, &p) {
        summary
            .warnings
            .push(format!("{why}; a fit and the drive refuse it, other commands use it as given"));
    }
    summary.warnings.extend(crate::field_units::kilo_doubt(&source.parameters_source, spec, &p));
    folder.keep();
    // The result first, then its doubts heaviest first, then each file's figures.
    let to_stderr = text_to_stderr(a);
    say!(to_stderr, "{}", summary.headline());
    for w in by_weight(&cut) {
        w.say();
    }
    say!(to_stderr, "{}", summary.details());
    if let Some(path) = &a.out_csv {
        let to = if is_stdout(path) { "standard output".to_string() } else { display(path) };
        say!(to_stderr, "time series written to {to}");
    }
    if a.json {
        out!("{}", super::merged_json(&summary, &super::context_json(&source, &Provenance::now(None)))?);
    }
    Ok(())
}

/// Whether the text goes to stderr: stdout holds only the JSON, or the `--out-csv -` table.
fn text_to_stderr(a: &CompareArgs) -> bool {
    a.json || a.out_csv.as_deref().is_some_and(is_stdout)
}

/// The plots of one recording, by file-name suffix.
const PLOTS: [&str; 7] = ["loop", "time", "residual", "correlation", "spectrum", "bode", "flux-loop"];

fn plot_path(a: &CompareArgs, stem: &str, kind: &str) -> PathBuf {
    a.out_dir.join(format!("{stem}-{kind}.{}", a.format))
}

fn compare_recordings(
    a: &CompareArgs,
    spec: ModelSpec,
    (p, source): (&ActuatorParams, &params::ParamSource),
    recs: &[Recording],
    stems: &[String],
) -> Result<(CompareSummary, Vec<Warning>)> {
    fit::check_files(spec, p, recs)?;
    let mut doubts: Vec<_> = fit::unresolved_mode(spec, p, recs).into_iter().collect();
    doubts.extend(fit::unfitted_gain(spec, p, source, recs));
    doubts.extend(fit::unfitted_effects(spec, source));
    doubts.extend(fit::data_doubts(spec, p, recs)?);
    doubts.extend(fit::sign_doubts(spec, p, recs)?);
    let model = [(spec, *p)];
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    let mut total = 0.0;
    // The table goes to a temporary file beside its target as it is made (it may be far larger
    // than the recordings' memory), renamed into place only when everything else succeeded
    // (`-`: streamed to stdout as it is made).
    let mut csv = match &a.out_csv {
        Some(path) => Some(csv::Writer::from_writer(OutputWriter::create(path)?)),
        None => None,
    };
    // Recordings with a search coil add its flux density (cells empty for the others).
    let any_flux = recs.iter().any(|r| r.flux_density_t.is_some());
    if let Some(w) = &mut csv {
        let mut header = vec!["file", "time_s", "measured_um", "model_um", "residual_um"];
        if any_flux {
            header.extend(["measured_flux_T", "model_flux_T", "residual_flux_T"]);
        }
        w.write_record(header)?;
    }
    for (rec, stem) in recs.iter().zip(stems) {
        let sim = crate::simulation::simulate(spec, p, rec)?;
        let sc = crate::score::score(spec, rec, &sim);
        doubts.extend(fit::flux_scale_doubts(std::slice::from_ref(rec), &[sc]));
        total += sc.nrmse;
        let time = report::time_chart(rec, &sim, sc.offset_um, &spec.to_string());
        let mut written = Vec::new();
        let flux_loop = report::flux_loop_chart(rec, &model)?.map(|c| ("flux-loop", c));
        for (kind, chart) in [
            ("loop", report::loop_chart(rec, &model)?),
            ("time", time),
            ("residual", report::residual_chart(rec, &model)?),
        ]
        .into_iter()
        .chain(flux_loop)
        {
            let out = plot_path(a, stem, kind);
            written.push(display(&out));
            charts.push((out, vec![chart], XScale::Linear));
        }
        let summary = match analysis::analyse(rec, &sim, sc.offset_um, a.max_lag) {
            Ok(fa) => {
                for (kind, panels, scale) in [
                    ("correlation", fa.correlation_charts(), XScale::Linear),
                    ("spectrum", vec![fa.spectrum_chart()], XScale::Log),
                    ("bode", fa.bode_charts(&spec.to_string()), XScale::Log),
                ] {
                    let out = plot_path(a, stem, kind);
                    written.push(display(&out));
                    charts.push((out, panels, scale));
                }
                Some(fa.summary)
            }
            Err(e) => {
                crate::warning::note(format_args!("{}: no residual or frequency analysis: {e}", rec.name));
                None
            }
        };
        if let Some(w) = &mut csv {
            write_time_series(w, rec, &sim, sc.offset_um, any_flux)?;
        }
        let mut channels = FileScoreRow::for_recording(rec, None, &sc);
        channels[0].plots = Some(written);
        channels[0].analysis = summary;
        rows.extend(channels);
    }
    // Its doubts are the caller's, said after the headline.
    let summary = CompareSummary {
        model: spec.to_string(),
        nrmse: total / recs.len() as f64,
        files: rows,
        warnings: Vec::new(),
    };
    let table = match (&a.out_csv, csv) {
        (Some(path), Some(w)) => Some((
            path.as_path(),
            w.into_inner().map_err(|e| anyhow::anyhow!("{}: {}", display(path), e.error()))?,
        )),
        _ => None,
    };
    Ok((report_all(&charts, table, summary)?, doubts))
}

/// Appends one recording's rows to the `--out-csv` table: values in shortest round-trip form,
/// so measured − model = residual holds to rounding when read back.
fn write_time_series(
    w: &mut csv::Writer<OutputWriter>,
    rec: &Recording,
    sim: &Simulation,
    offset_um: f64,
    flux_columns: bool,
) -> Result<()> {
    let measured = rec.displacement_um.as_deref().unwrap_or_default();
    let flux = rec
        .flux_density_t
        .as_deref()
        .map(|b| (b, crate::score::flux_fit(b, &sim.field_a_per_m, &sim.magnetization_a_per_m).1));
    for (k, ((t, m), y)) in rec.time_s.iter().zip(measured).zip(&sim.displacement_um).enumerate() {
        let model = y + offset_um;
        let residual = m - model;
        if !(model.is_finite() && residual.is_finite()) {
            return Err(crate::error::InRecording::error(
                &rec.name,
                format!("the model output at t = {t} s is not a finite number"),
            ));
        }
        let mut row =
            vec![rec.name.clone(), t.to_string(), m.to_string(), model.to_string(), residual.to_string()];
        if flux_columns {
            match &flux {
                Some((b, model)) => row.extend([b[k], model[k], b[k] - model[k]].map(|v| v.to_string())),
                None => row.extend([String::new(), String::new(), String::new()]),
            }
        }
        w.write_record(row)?;
    }
    Ok(())
}

/// Draws and writes every chart (only now that every file's chart data exists: a bad input
/// leaves no partial set of plots) and the `--out-csv` table, and hands back the summary.
fn report_all(
    charts: &[(PathBuf, Vec<Chart>, XScale)],
    table: Option<(&Path, OutputWriter)>,
    summary: CompareSummary,
) -> Result<CompareSummary> {
    for (path, panels, scale) in charts {
        plots::write_panels(path, panels, *scale)?;
    }
    if let Some((path, table)) = table {
        table.finish(path)?;
    }
    Ok(summary)
}

/// Loop files: measured and model loops overlaid, and coercivity, remanence and largest
/// magnetization read from both.
fn compare_loops(
    a: &CompareArgs,
    spec: ModelSpec,
    p: &ActuatorParams,
    files: &[LoopFile],
    stems: &[String],
) -> Result<CompareSummary> {
    let model = loop_fit::LoopModel::from_spec(spec, p)?;
    let values = model.values_of(p);
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    let mut total = 0.0;
    for (f, stem) in files.iter().zip(stems) {
        let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let m = loop_fit::run(model, &values, &f.h, h_max)
            .map_err(|e| crate::error::InRecording::error(&f.name, e.0))?;
        let e = crate::score::nrmse(&f.value, &f.channel_from_m(&m));
        total += e;
        let out = plot_path(a, stem, "loop");
        rows.push(FileScoreRow {
            plots: Some(vec![display(&out)]),
            measured: Some(loops::features(&f.h, &f.magnetization())),
            model: Some(loops::features(&f.h, &m)),
            ..FileScoreRow::new(&f.name, None, (f.channel.name(), &f.value), e)
        });
        charts.push((out, vec![loop_plots::chart(f, &m, &spec.to_string())], XScale::Linear));
    }
    report_all(
        &charts,
        None,
        CompareSummary {
            model: spec.to_string(),
            nrmse: total / files.len() as f64,
            files: rows,
            warnings: Vec::new(),
        },
    )
}
