//! `gma compare`: per-file error and plots of a model (with a given parameter set) against
//! recordings or magnetization loops.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use model_core::{ActuatorParams, ModelSpec};

use super::common::{check_max_samples, read_data, Data, ReadArgs};
use crate::files::{check_outputs, display, open_all, output_folder, unique_stems, Input};
use crate::fit;
use crate::loops::{self, LoopFile};
use crate::params;
use crate::plots::{self, Chart};
use crate::provenance::Provenance;
use crate::recording::Recording;
use crate::report;
use crate::results::{CompareSummary, FileScoreRow};

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
    check_max_samples(a.read.max_samples)?;
    let read_opts = a.read.options()?;
    let params_input = a.params.as_deref().map(Input::open).transpose()?;
    let inputs = open_all(&a.files)?;
    let ids: Vec<_> = inputs.iter().chain(params_input.as_ref()).map(Input::id).collect();
    let (p, source) = params::load_input(params_input, spec, "the compared parameters")?;
    output_folder(&a.out_dir)?;
    let stems = unique_stems(&a.files);
    let planned: Vec<PathBuf> =
        stems.iter().flat_map(|s| ["loop", "time", "residual"].map(|k| plot_path(a, s, k))).collect();
    check_outputs(&planned.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &ids)?;
    let summary = match read_data(inputs, Vec::new(), a.read.max_samples, &read_opts)? {
        Data::Loops(files, _) => compare_loops(a, spec, &p, &files, &stems)?,
        Data::Recordings(files, _) => compare_recordings(a, spec, &p, &files, &stems)?,
    };
    say!(a.json, "{summary}");
    if a.json {
        out!("{}", super::merged_json(&summary, &super::context_json(&source, &Provenance::now(None)))?);
    }
    Ok(())
}

fn plot_path(a: &CompareArgs, stem: &str, kind: &str) -> PathBuf {
    a.out_dir.join(format!("{stem}-{kind}.{}", a.format))
}

fn compare_recordings(
    a: &CompareArgs,
    spec: ModelSpec,
    p: &ActuatorParams,
    recs: &[Recording],
    stems: &[String],
) -> Result<CompareSummary> {
    for r in recs {
        fit::drive_for(spec, r)?;
    }
    let model = [(spec, *p)];
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    let mut total = 0.0;
    for (rec, stem) in recs.iter().zip(stems) {
        let sim = fit::simulate(spec, p, rec)?;
        let sc = fit::score(spec, rec, &sim);
        total += sc.nrmse;
        let time = report::time_chart(rec, &sim, sc.offset_um, &spec.to_string());
        let mut written = Vec::new();
        for (kind, chart) in [
            ("loop", report::loop_chart(rec, &model)?),
            ("time", time),
            ("residual", report::residual_chart(rec, &model)?),
        ] {
            let out = plot_path(a, stem, kind);
            written.push(display(&out));
            charts.push((out, chart));
        }
        rows.push(FileScoreRow {
            offset_um: Some(sc.offset_um),
            plots: Some(written),
            ..FileScoreRow::new(&rec.name, None, "displacement", sc.nrmse)
        });
        if let Some(c) = sc.nrmse_current {
            rows.push(FileScoreRow::new(&rec.name, None, "current", c));
        }
    }
    report_all(
        &charts,
        CompareSummary { model: spec.to_string(), nrmse: total / recs.len() as f64, files: rows },
    )
}

/// Writes every chart (only now that all were drawn: a failing file leaves no partial set of
/// plots) and hands back the summary.
fn report_all(charts: &[(PathBuf, Chart)], summary: CompareSummary) -> Result<CompareSummary> {
    for (path, chart) in charts {
        plots::write(path, chart)?;
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
    let model = loops::LoopModel::from_spec(spec, p)?;
    let values = model.values_of(p);
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    let mut total = 0.0;
    for (f, stem) in files.iter().zip(stems) {
        let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let m =
            loops::run(model, &values, &f.h, h_max).map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
        let e = fit::nrmse(&f.value, &f.channel_from_m(&m));
        total += e;
        let out = plot_path(a, stem, "loop");
        rows.push(FileScoreRow {
            plots: Some(vec![display(&out)]),
            measured: Some(loops::features(&f.h, &f.magnetization())),
            model: Some(loops::features(&f.h, &m)),
            ..FileScoreRow::new(&f.name, None, f.channel.name(), e)
        });
        charts.push((out, loops::chart(f, &m, &spec.to_string())));
    }
    report_all(
        &charts,
        CompareSummary { model: spec.to_string(), nrmse: total / files.len() as f64, files: rows },
    )
}
