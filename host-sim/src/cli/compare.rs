//! `gma compare`: per-file error and plots of a model (with a given parameter set) against
//! recordings or magnetization loops.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use model_core::{ActuatorParams, ModelSpec};
use serde_json::json;

use super::common::{check_max_samples, read_data, Data, DEFAULT_MAX_SAMPLES};
use crate::files::{check_outputs, display, open_all, output_folder, unique_stems, Input};
use crate::fit;
use crate::loops::{self, LoopFile};
use crate::params;
use crate::plots::{self, Chart};
use crate::recording::Recording;
use crate::report;

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
    /// Samples kept per file (see `gma fit --help`).
    #[arg(long, default_value_t = DEFAULT_MAX_SAMPLES, value_name = "N")]
    pub max_samples: usize,
}

/// Runs `gma compare`.
pub fn run(a: &CompareArgs) -> Result<()> {
    let spec = params::parse_spec(&a.model)?;
    check_max_samples(a.max_samples)?;
    let params_input = a.params.as_deref().map(Input::open).transpose()?;
    let inputs = open_all(&a.files)?;
    let ids: Vec<_> = inputs.iter().chain(params_input.as_ref()).map(Input::id).collect();
    if params_input.is_none() {
        eprintln!("gma: note: no --params: comparing the built-in Terfenol-D demo parameter set");
    }
    let p = params::load_input(params_input, spec)?;
    output_folder(&a.out_dir)?;
    let stems = unique_stems(&a.files);
    let planned: Vec<PathBuf> =
        stems.iter().flat_map(|s| ["loop", "time", "residual"].map(|k| plot_path(a, s, k))).collect();
    check_outputs(&planned.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &ids)?;
    match read_data(inputs, Vec::new(), a.max_samples)? {
        Data::Loops(files, _) => compare_loops(a, spec, &p, &files, &stems),
        Data::Recordings(files, _) => compare_recordings(a, spec, &p, &files, &stems),
    }
}

/// Draws every chart first and writes them only when all succeeded: a failing file leaves no
/// partial set of plots.
fn write_all(charts: &[(PathBuf, Chart)]) -> Result<()> {
    for (path, chart) in charts {
        plots::write(path, chart)?;
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
) -> Result<()> {
    for r in recs {
        fit::drive_for(spec, r)?;
    }
    let model = [(spec, *p)];
    let mut rows = Vec::new();
    let mut lines = Vec::new();
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
        lines.push(format!(
            "{:50} NRMSE {:6.3} %  offset {:8.3} µm  plots: {}",
            rec.name,
            sc.nrmse * 100.0,
            sc.offset_um,
            written.join(", ")
        ));
        rows.push(json!({"file": rec.name, "channel": "displacement", "nrmse": sc.nrmse, "offset_um": sc.offset_um, "plots": written}));
        if let Some(c) = sc.nrmse_current {
            rows.push(json!({"file": rec.name, "channel": "current", "nrmse": c}));
        }
    }
    write_all(&charts)?;
    for l in lines {
        say!(a.json, "{l}");
    }
    let mean = total / recs.len() as f64;
    say!(a.json, "mean NRMSE {:.3} % over {} file(s), model `{spec}`", mean * 100.0, recs.len());
    if a.json {
        out!("{}", json!({"model": spec.to_string(), "nrmse": mean, "files": rows}));
    }
    Ok(())
}

/// Loop files: measured and model loops overlaid, and coercivity, remanence and largest
/// magnetization read from both.
fn compare_loops(
    a: &CompareArgs,
    spec: ModelSpec,
    p: &ActuatorParams,
    files: &[LoopFile],
    stems: &[String],
) -> Result<()> {
    let model = loops::LoopModel::from_spec(spec)?;
    let values = model.values_of(p);
    let mut rows = Vec::new();
    let mut charts = Vec::new();
    let mut text = Vec::new();
    let mut total = 0.0;
    for (f, stem) in files.iter().zip(stems) {
        let h_max = f.h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let m =
            loops::run(model, &values, &f.h, h_max).map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
        let e = fit::nrmse(&f.value, &f.channel_from_m(&m));
        total += e;
        let (fm, fmod) = (loops::features(&f.h, &f.magnetization()), loops::features(&f.h, &m));
        let out = plot_path(a, stem, "loop");
        text.push(format!("{:40} NRMSE {:6.3} %  plot: {}", f.name, e * 100.0, display(&out)));
        text.push(format!("  {:28} {:>14} {:>14}", "", "measured", "model"));
        for (name, x, y) in [
            ("coercivity H_c [A/m]", fm.coercivity_a_per_m, fmod.coercivity_a_per_m),
            ("remanence M_r [A/m]", fm.remanence_a_per_m, fmod.remanence_a_per_m),
            ("largest |M| [A/m]", fm.max_magnetization_a_per_m, fmod.max_magnetization_a_per_m),
        ] {
            text.push(format!("  {name:28} {x:>14.4e} {y:>14.4e}"));
        }
        rows.push(json!({"file": f.name, "channel": f.channel.name(), "nrmse": e, "plots": [display(&out)],
            "measured": {"coercivity_a_per_m": fm.coercivity_a_per_m, "remanence_a_per_m": fm.remanence_a_per_m, "max_magnetization_a_per_m": fm.max_magnetization_a_per_m},
            "model": {"coercivity_a_per_m": fmod.coercivity_a_per_m, "remanence_a_per_m": fmod.remanence_a_per_m, "max_magnetization_a_per_m": fmod.max_magnetization_a_per_m}}));
        charts.push((out, loops::chart(f, &m, &spec.to_string())));
    }
    write_all(&charts)?;
    for l in text {
        say!(a.json, "{l}");
    }
    let mean = total / files.len() as f64;
    if a.json {
        out!("{}", json!({"model": spec.to_string(), "nrmse": mean, "files": rows}));
    }
    Ok(())
}
