//! `gma fit`: identify a model from recordings (or the magnetization stage from loop files).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use model_core::ModelSpec;
use serde_json::json;

use super::common::{warn_time_limited, Data, ModelFiles, Prepared};
use crate::files::{names, write_atomic};
use crate::fit::{self, FitResult};
use crate::loops::{self, LoopFile};
use crate::params;
use crate::recording::Recording;

/// Options of `gma fit`.
#[derive(Args)]
pub struct FitArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
    /// Write the identified parameter set here (TOML; `compare`, `simulate` and the firmware load
    /// it). Written only when the fit succeeds; never one of the inputs.
    #[arg(long, value_name = "P.toml")]
    pub params_out: Option<PathBuf>,
}

/// Runs `gma fit`.
pub fn run(a: &FitArgs) -> Result<()> {
    let outputs: Vec<&std::path::Path> = a.params_out.as_deref().into_iter().collect();
    let p = a.mf.prepare(&outputs)?;
    match &p.data {
        Data::Loops(fit_files, val_files) => fit_loops(a, &p, fit_files, val_files),
        Data::Recordings(fit_files, val_files) => fit_recordings(a, &p, fit_files, val_files),
    }
}

fn fit_recordings(a: &FitArgs, p: &Prepared, fit_files: &[Recording], val_files: &[Recording]) -> Result<()> {
    let spec = p.spec;
    let t = std::time::Instant::now();
    let res = fit::fit(spec, &p.init, fit_files, p.opts)?;
    let (rows, nrmse_val) = file_rows(&res, spec, fit_files, val_files)?;
    let j = a.mf.json;
    say!(
        j,
        "model `{spec}` fitted to {} file(s): {} evaluations in {:.1} s (seed {})",
        fit_files.len(),
        res.evaluations,
        t.elapsed().as_secs_f64(),
        a.mf.seed
    );
    if res.time_limited {
        warn_time_limited(a.mf.time_limit);
    }
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
            "gma fit --model {spec} (seed {}) on {}\nfit NRMSE {:.4} %{}",
            a.mf.seed,
            names(&a.mf.files),
            res.fit.mean_nrmse() * 100.0,
            if res.time_limited { "\nstopped by --time-limit: the best set found so far" } else { "" }
        );
        write_atomic(out, params::to_toml(&res.params, &header)?.as_bytes())?;
        say!(j, "  parameters written to {}", crate::files::display(out));
    }
    if j {
        let params: serde_json::Map<String, serde_json::Value> =
            res.identified.iter().map(|(n, v)| (n.to_string(), json!(v))).collect();
        out!(
            "{}",
            json!({"model": spec.to_string(), "params": params, "nrmse_fit": res.fit.mean_nrmse(), "nrmse_val": nrmse_val,
                   "files": rows, "evaluations": res.evaluations, "seed": a.mf.seed, "time_limit_reached": res.time_limited})
        );
    }
    Ok(())
}

/// The contract's per-file rows (fit and validation, displacement and current channels).
fn file_rows(
    res: &FitResult,
    spec: ModelSpec,
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

/// `gma fit` on magnetization-loop files: the magnetization stage alone.
fn fit_loops(a: &FitArgs, p: &Prepared, fit_files: &[LoopFile], val_files: &[LoopFile]) -> Result<()> {
    let spec = p.spec;
    let model = loops::LoopModel::from_spec(spec)?;
    let t = std::time::Instant::now();
    crate::progress::phase(
        true,
        &format!("fitting the magnetization model `{spec}` to {} loop file(s)", fit_files.len()),
    );
    let res = loops::fit(model, fit_files, p.search_options())?;
    let j = a.mf.json;
    say!(
        j,
        "magnetization model `{spec}` fitted to {} loop file(s): {} evaluations in {:.1} s (seed {})",
        fit_files.len(),
        res.evaluations,
        t.elapsed().as_secs_f64(),
        a.mf.seed
    );
    if res.time_limited {
        warn_time_limited(a.mf.time_limit);
    }
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
        fit_files.iter().chain(val_files).flat_map(|f| f.h.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    for f in val_files {
        let m = loops::run(model, &res.values(), &f.h, h_max)
            .map_err(|e| anyhow::anyhow!("{}: {}", f.name, e.0))?;
        let e = fit::nrmse(&f.value, &f.channel_from_m(&m));
        say!(j, "  val   {:14} NRMSE {:6.3} %  {}", f.channel.name(), e * 100.0, f.name);
        rows.push(json!({"file": f.name, "split": "val", "channel": f.channel.name(), "nrmse": e}));
        val_nrmse.push(e);
    }
    for w in res.failures.iter().chain(&res.warnings) {
        eprintln!("gma: warning: {w}");
    }
    // An invalid result is an error: nothing is written, and --json gets the error object.
    if !res.failures.is_empty() {
        bail!("the loop fit did not produce a valid model: {}", res.failures.join("; "));
    }
    if let Some(out) = &a.params_out {
        let header = format!("gma fit --model {spec} on loop files {}", names(&a.mf.files));
        write_atomic(out, params::to_toml(&res.apply_to(&p.init), &header)?.as_bytes())?;
        say!(j, "  parameters written to {}", crate::files::display(out));
    }
    let nrmse_fit = res.nrmse.iter().sum::<f64>() / res.nrmse.len() as f64;
    let nrmse_val = (!val_nrmse.is_empty()).then(|| val_nrmse.iter().sum::<f64>() / val_nrmse.len() as f64);
    if j {
        let params: serde_json::Map<String, serde_json::Value> =
            res.params.iter().map(|(n, v)| (n.to_string(), json!(v))).collect();
        out!(
            "{}",
            json!({"model": spec.to_string(), "params": params, "nrmse_fit": nrmse_fit, "nrmse_val": nrmse_val,
            "files": rows, "evaluations": res.evaluations, "warnings": res.warnings, "seed": a.mf.seed,
            "time_limit_reached": res.time_limited})
        );
    }
    Ok(())
}
