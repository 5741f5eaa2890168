//! `gma fit`: identify a model from recordings (or the magnetization stage from loop files).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;

use super::common::{Data, ModelFiles, Prepared};
use crate::files::{display, names, to_stdout, write_atomic};
use crate::fit;
use crate::loop_fit;
use crate::loops::LoopFile;
use crate::params;
use crate::provenance::Provenance;
use crate::recording::Recording;
use crate::results::{FileScoreRow, FitSummary, FitText};
use crate::uncertainty;
use crate::warning::{by_weight, Warning};

/// Options of `gma fit`.
#[derive(Args)]
pub struct FitArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
    /// Write the identified parameter set here (TOML; `compare`, `simulate` and the firmware load
    /// it). Written only when the fit succeeds; never one of the inputs. `-` writes it to
    /// standard output, and the fit's text to stderr (not with `--json`).
    #[arg(long, value_name = "P.toml")]
    pub params_out: Option<PathBuf>,
    /// Hold a parameter at its start value (from --params), or at VALUE, instead of fitting it
    /// (a name as in parameter files, e.g. `ja.c`; repeat for several; displacement fits only).
    #[arg(long, value_name = "NAME[=VALUE]")]
    pub fix: Vec<String>,
    /// Narrow a parameter's search range to [LO, HI] (in its unit; within its registry range,
    /// which it can only narrow; repeat for several; displacement fits only).
    #[arg(long, value_name = "NAME=LO:HI", allow_hyphen_values = true)]
    pub bound: Vec<String>,
}

/// `--params-out` onto an existing file that is not a parameter file is refused before any work:
/// a recording's name typed one slot early (`--params-out fit1.csv fit2.csv`) would replace a
/// measurement with TOML. New paths, devices (`/dev/null`) and files that read as TOML pass.
fn replaces_only_a_parameter_file(out: &std::path::Path) -> Result<()> {
    let Ok(meta) = std::fs::metadata(out) else { return Ok(()) };
    // A parameter file is a few kB; anything over 1 MiB is not one, and is not read.
    let reads_as_toml = || {
        meta.len() <= 1 << 20
            && std::fs::read_to_string(out).is_ok_and(|text| text.parse::<toml::Table>().is_ok())
    };
    if meta.is_file() && !reads_as_toml() {
        bail!(
            "--params-out {}: the file exists and is not a parameter file (it does not read as TOML), so \
             gma will not replace it; remove it first or choose another path (e.g. fitted.toml)",
            display(out)
        );
    }
    Ok(())
}

/// Runs `gma fit`.
/// The J–A form a model with the J–A law runs (`[ja] variant`); None for other laws.
fn ja_variant(spec: model_core::ModelSpec, p: &model_core::ActuatorParams) -> Option<&'static str> {
    (spec.law() == model_core::MagnetizationLaw::JilesAtherton).then(|| p.ja.variant.name())
}

/// The header of a fitted parameter file: what made it, its fit (and validation) NRMSE, the
/// parameters held fixed (`# fixed: NAME`, which readers ignore), and where it came from: version,
/// date and every input's digest.
pub(crate) fn params_header(
    made_by: &str,
    mf: &ModelFiles,
    nrmse_fit: f64,
    nrmse_val: Option<f64>,
    time_limited: bool,
    fixed: &[&str],
) -> String {
    let fixed: String = fixed.iter().map(|n| format!("\nfixed: {n}")).collect();
    let made = Provenance::now(Some(mf.seed));
    let inputs: String =
        made.inputs.iter().map(|i| format!("\ninput {} sha256 {}", i.file, i.sha256)).collect();
    let validation = nrmse_val
        .map(|v| format!("\nvalidation NRMSE {:.4} % on {} (scored, not fitted)", v * 100.0, names(&mf.val)))
        .unwrap_or_default();
    format!(
        "{made_by} on {}\nfit NRMSE {:.4} %{validation}{}{fixed}\nmade by gma {} on {}{inputs}",
        names(&mf.files),
        nrmse_fit * 100.0,
        if time_limited { "\nstopped by --time-limit: the best set found so far" } else { "" },
        made.gma_version,
        made.date_utc
    )
}

/// The time limit is a doubt like the others: said, and in the JSON's `warnings` too.
pub(crate) fn add_time_limit_warning(
    summary: &mut FitSummary,
    warnings: &mut Vec<Warning>,
    time_limit_s: Option<f64>,
) {
    if summary.time_limit_reached {
        let w = Warning::TimeLimit { seconds: time_limit_s.unwrap_or(f64::NAN) };
        summary.warnings.get_or_insert_with(Vec::new).push(w.to_string());
        warnings.push(w);
    }
}

pub fn run(a: &FitArgs) -> Result<()> {
    let outputs: Vec<&std::path::Path> = a.params_out.as_deref().into_iter().collect();
    let params_to_stdout = match &a.params_out {
        Some(out) => to_stdout("--params-out", out, a.mf.json)?,
        None => false,
    };
    let mut p = a.mf.prepare(&outputs)?;
    // After `prepare`'s output checks: an input named as the output is said as such.
    if let Some(out) = a.params_out.as_deref().filter(|_| !params_to_stdout) {
        replaces_only_a_parameter_file(out)?;
    }
    let (mut summary, params, mut warnings) = match &p.data {
        Data::Loops(fit_files, val_files) => {
            if !(a.fix.is_empty() && a.bound.is_empty()) {
                bail!(
                    "--{}: fixing or bounding parameters applies to displacement fits, not to loop files",
                    if a.fix.is_empty() { "bound" } else { "fix" }
                );
            }
            fit_loops(&p, fit_files, val_files)?
        }
        Data::Recordings(fit_files, val_files) => {
            let c = fit::Constraints::parse(p.spec, fit_files, &a.fix, &a.bound, &mut p.init)?;
            fit_recordings(&p, fit_files, val_files, &c)?
        }
    };
    add_time_limit_warning(&mut summary, &mut warnings, a.mf.time_limit);
    // Stdout holds only the data when it carries JSON or the parameter file.
    let j = a.mf.json || params_to_stdout;
    // The result first, then its doubts heaviest first (a unit before a correlation), then
    // the details.
    say!(j, "{}", summary.headline());
    for w in by_weight(&warnings) {
        w.say();
    }
    say!(j, "{}", summary.details());
    // An invalid result is an error: nothing is written, and --json gets the error object.
    let invalid: Vec<String> = warnings.iter().filter(|w| w.invalidates()).map(|w| w.to_string()).collect();
    if !invalid.is_empty() {
        bail!("the loop fit did not produce a valid model: {}", invalid.join("; "));
    }
    if let Some(out) = &a.params_out {
        let fixed: Vec<&str> = summary.text.fixed.iter().map(|(n, _)| *n).collect();
        let header = params_header(
            &format!("gma fit --model {} (seed {})", summary.model, a.mf.seed),
            &a.mf,
            summary.nrmse_fit,
            summary.nrmse_val,
            summary.time_limit_reached,
            &fixed,
        );
        let toml = params::to_toml_for(&params, &header, p.spec, &summary.not_fitted)?;
        write_atomic(out, toml.as_bytes())?;
        let to = if params_to_stdout { "standard output".to_string() } else { display(out) };
        say!(j, "  parameters written to {to}");
    }
    if a.mf.json {
        out!(
            "{}",
            super::merged_json(
                &summary,
                &super::context_json(&p.params_source, &Provenance::now(Some(a.mf.seed)))
            )?
        );
    }
    Ok(())
}

/// The fit of displacement recordings.
pub(crate) fn fit_recordings(
    p: &Prepared,
    fit_files: &[Recording],
    val_files: &[Recording],
    constraints: &fit::Constraints,
) -> Result<(FitSummary, model_core::ActuatorParams, Vec<Warning>)> {
    let t = Instant::now();
    let res = fit::fit_constrained(p.spec, &[p.init], fit_files, p.opts, constraints)?;
    // Analysis after the fit: the parameters' uncertainty from the Jacobian at the optimum.
    let phase = crate::progress::Phase::start(
        p.opts.progress,
        "fit: parameter uncertainty (Jacobian at the optimum)",
        0,
    );
    let analysed = uncertainty::analyse(p.spec, &res, fit_files);
    phase.finish();
    let (uncertainty, mut warnings) = match analysed {
        Ok(u) => {
            let w = u.warnings();
            (Some(u), w)
        }
        // A doubt like the others: on stderr and in the JSON's `warnings`.
        Err(e) => (None, vec![Warning::NoUncertainty { why: e.to_string() }]),
    };
    // First the doubts about the inputs (a `--val` file that is a fit file), then the start's.
    warnings.splice(0..0, p.input_warnings.iter().chain(&res.start_moved).cloned());
    if let Some(w) = fit::strain_scale_doubt(&res.params, constraints) {
        warnings.push(w);
    }
    warnings.extend(fit::unresolved_mode(p.spec, &res.params, fit_files.iter().chain(val_files)));
    warnings.extend(fit::flux_scale_doubts(fit_files, &res.fit.files));
    let mut files = rows("fit", fit_files, &res.fit.files);
    let mut nrmse_val = None;
    if !val_files.is_empty() {
        let ev = fit::evaluate(p.spec, &res.params, val_files)?;
        warnings.extend(fit::flux_scale_doubts(val_files, &ev.files));
        files.extend(rows("val", val_files, &ev.files));
        nrmse_val = Some(ev.mean_nrmse());
    }
    let summary = FitSummary {
        model: p.spec.to_string(),
        ja_variant: ja_variant(p.spec, &res.params),
        params: res.identified.iter().copied().collect(),
        nrmse_fit: res.fit.mean_nrmse(),
        nrmse_val,
        files,
        evaluations: res.evaluations,
        seed: p.opts.seed,
        time_limit_reached: res.time_limited,
        warnings: Some(warnings.iter().map(|w| w.to_string()).collect()),
        fixed: (!res.fixed.is_empty()).then(|| res.fixed.iter().copied().collect()),
        not_fitted: fit::not_fitted(p.spec, fit_files)?,
        uncertainty: None,
        correlation: None,
        uncertainty_basis: None,
        start: Some(res.start.clone()),
        text: FitText {
            params_in_order: res.identified.clone(),
            loops: false,
            seconds: t.elapsed().as_secs_f64(),
            fixed: res.fixed.clone(),
            uncertainty: None,
        },
    };
    let summary = match &uncertainty {
        Some(u) => summary.with_uncertainty(u),
        None => summary,
    };
    Ok((summary, res.params, warnings))
}

/// The contract's per-file rows: displacement, and current and flux density where the model
/// is scored on them.
fn rows(split: &'static str, recs: &[Recording], scores: &[crate::score::FileScore]) -> Vec<FileScoreRow> {
    recs.iter().zip(scores).flat_map(|(r, s)| FileScoreRow::for_recording(&r.name, Some(split), s)).collect()
}

/// The magnetization stage alone, on loop files.
pub(crate) fn fit_loops(
    p: &Prepared,
    fit_files: &[LoopFile],
    val_files: &[LoopFile],
) -> Result<(FitSummary, model_core::ActuatorParams, Vec<Warning>)> {
    let spec = p.spec;
    let model = loop_fit::LoopModel::from_spec(spec, &p.init)?;
    let t = Instant::now();
    crate::progress::phase(
        p.opts.progress,
        &format!("fitting the magnetization model `{spec}` to {} loop file(s)", fit_files.len()),
    );
    let mut res = loop_fit::fit_shown(model, fit_files, &p.init, p.search_options(), p.opts.progress)?;
    res.warnings.splice(0..0, p.input_warnings.iter().cloned());
    let mut files: Vec<FileScoreRow> = fit_files
        .iter()
        .zip(&res.nrmse)
        .map(|(f, e)| FileScoreRow::new(&f.name, Some("fit"), f.channel.name(), *e))
        .collect();
    let mut val_nrmse = Vec::new();
    let h_max =
        fit_files.iter().chain(val_files).flat_map(|f| f.h.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    for f in val_files {
        let m = loop_fit::run(model, &res.values(), &f.h, h_max)
            .map_err(|e| crate::error::InRecording::error(&f.name, e.0))?;
        let e = crate::score::nrmse(&f.value, &f.channel_from_m(&m));
        files.push(FileScoreRow::new(&f.name, Some("val"), f.channel.name(), e));
        val_nrmse.push(e);
    }
    let summary = FitSummary {
        model: spec.to_string(),
        ja_variant: ja_variant(spec, &p.init),
        params: res.params.iter().copied().collect(),
        nrmse_fit: res.nrmse.iter().sum::<f64>() / res.nrmse.len() as f64,
        nrmse_val: (!val_nrmse.is_empty()).then(|| val_nrmse.iter().sum::<f64>() / val_nrmse.len() as f64),
        files,
        evaluations: res.evaluations,
        seed: p.opts.seed,
        time_limit_reached: res.time_limited,
        warnings: Some(res.warnings.iter().filter(|w| !w.invalidates()).map(|w| w.to_string()).collect()),
        fixed: None,
        not_fitted: Vec::new(),
        uncertainty: None,
        correlation: None,
        uncertainty_basis: None,
        start: Some(res.start.clone()),
        text: FitText {
            params_in_order: res.params.clone(),
            loops: true,
            seconds: t.elapsed().as_secs_f64(),
            ..FitText::default()
        },
    };
    Ok((summary, res.apply_to(&p.init), res.warnings))
}
