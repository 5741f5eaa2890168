//! `gma report`: the model ladder (or a loop fit) as one self-contained HTML page.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use model_core::{ActuatorParams, ModelSpec};
use serde_json::json;

use super::fit::params_header;
use crate::api::inputs::{Data, ModelFiles};
use crate::files::{
    check_outputs, display, no_stdout, output_folder, replaces_only, to_stdout, write_atomic, InputId,
    OutputKind,
};
use crate::progress::Phase;
use crate::provenance::Provenance;
use crate::recording::Recording;
use crate::results::UncertaintyFields;
use crate::uncertainty::Uncertainty;
use crate::{fit, loop_fit, loop_plots, params, report};

/// Options of `gma report`.
#[derive(Args)]
pub struct ReportArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
    /// The HTML file to write (only when the report is complete; never one of the inputs). `-`
    /// writes the page to standard output, and the text to stderr (not with `--json`).
    #[arg(long, short, default_value = "gma-report.html")]
    pub out: PathBuf,
    /// Also write each fitted model's parameters into DIR (created if missing), as `gma fit
    /// --params-out` writes them, for `compare`, `fit --params` or the board: `params-K-MODEL.toml`,
    /// K its step on the ladder (0: the model given), `+` written `_`.
    #[arg(long, value_name = "DIR")]
    pub params_out_dir: Option<PathBuf>,
}

/// The parameter files of a ladder's models in `dir`, in ladder order (`report`, `demo`).
pub(crate) fn params_paths(dir: &Path, specs: &[ModelSpec]) -> Vec<PathBuf> {
    specs
        .iter()
        .enumerate()
        .map(|(k, spec)| dir.join(format!("params-{k}-{}.toml", spec.to_string().replace('+', "_"))))
        .collect()
}

/// The files in `dir` named as a ladder's parameter files (`params-K-….toml`).
fn ladder_files_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let named = |n: &str| {
        n.strip_prefix("params-").and_then(|r| r.split_once('-')).is_some_and(|(k, rest)| {
            !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) && rest.ends_with(".toml")
        })
    };
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read the folder {}", display(dir)))?;
    Ok(entries
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(named))
        .collect())
}

/// Refuses a ladder file already in `--params-out-dir` that was not fitted to this run's inputs
/// (`ours`, their SHA-256 digests), as its header's `# input … sha256 …` lines say: this run
/// would replace the rungs it shares with that ladder and leave the others beside them, two
/// rigs' parameters read as one ladder.
fn from_these_inputs(existing: &Path, ours: &[String]) -> Result<()> {
    let text = std::fs::read_to_string(existing).unwrap_or_default();
    let mut theirs: Vec<&str> = text
        .lines()
        .take_while(|l| l.starts_with('#'))
        .filter_map(|l| l.strip_prefix("# input ")?.rsplit_once(" sha256 ").map(|(_, d)| d.trim()))
        .collect();
    theirs.sort_unstable();
    theirs.dedup();
    let mut ours: Vec<&str> = ours.iter().map(String::as_str).collect();
    ours.sort_unstable();
    ours.dedup();
    if theirs != ours {
        let what = if theirs.is_empty() {
            "has no `# input` lines in its header, so it was not written by a `gma report` on these files"
        } else {
            "was fitted to other files (the inputs its header lists are not this run's)"
        };
        bail!(
            "--params-out-dir {}: {} {what}; this run would replace the ladder files it shares with it and \
             leave the others beside them, two ladders read as one. Choose an empty folder, or move the \
             params-K-….toml files out of this one",
            display(existing.parent().unwrap_or(Path::new("."))),
            display(Path::new(existing.file_name().unwrap_or_default())),
        );
    }
    Ok(())
}

/// Writes each model's parameter file (paths from [`params_paths`]), after checking them all;
/// each marks what no file constrained when fitted on `fit_files` ([`fit::not_fitted`]).
fn write_params(
    paths: &[PathBuf],
    sets: &[(ModelSpec, ActuatorParams, String)],
    inputs: &[InputId],
    fit_files: &[Recording],
) -> Result<()> {
    check_outputs(&paths.iter().map(PathBuf::as_path).collect::<Vec<_>>(), inputs)?;
    for (path, (spec, set, header)) in paths.iter().zip(sets) {
        let not_fitted = if fit_files.is_empty() { Vec::new() } else { fit::not_fitted(*spec, fit_files)? };
        write_atomic(path, params::to_toml_for(set, header, *spec, &not_fitted)?.as_bytes())?;
    }
    Ok(())
}

/// Runs `gma report`.
pub fn run(a: &ReportArgs) -> Result<()> {
    let page_to_stdout = to_stdout("--out", &a.out, a.mf.json)?;
    if let Some(dir) = &a.params_out_dir {
        no_stdout("--params-out-dir", dir, "a folder for one parameter file per model")?;
    }
    let p = a.mf.prepare(&[a.out.as_path()])?;
    // After `prepare`'s output checks: an input named as the output is said as such.
    replaces_only(&a.out, OutputKind::HtmlPage, "--out")?;
    let written_to = if page_to_stdout { "standard output".to_string() } else { display(&a.out) };
    // The folder now, the file names (the models found) after the ladder.
    let params_folder = match &a.params_out_dir {
        Some(dir) => Some((dir.as_path(), output_folder(dir)?)),
        None => None,
    };
    // Before any work: the given model's file, and every ladder file already in the folder (the
    // ladder's other names are known only once found), against the inputs: re-seeding from an
    // earlier rung's file is a natural next run, and would be overwritten after the ladder.
    if let Some((dir, _)) = params_folder {
        check_outputs(&[params_paths(dir, &[p.spec])[0].as_path()], &p.inputs)?;
        let ours: Vec<String> = crate::digests::input_digests().into_iter().map(|d| d.sha256).collect();
        for existing in ladder_files_in(dir)? {
            check_outputs(&[existing.as_path()], &p.inputs)?;
            from_these_inputs(&existing, &ours)?;
        }
    }
    p.warn_about_inputs();
    // Stdout holds only the data when it carries JSON or the page.
    let j = a.mf.json || page_to_stdout;
    let spec = p.spec;
    // Every input has been read to its end: their digests are final.
    let provenance = Provenance::now(Some(a.mf.seed));
    let provenance_section = report::provenance_html(&provenance, &p.params_source);
    let extra = super::context_json(&p.params_source, &provenance);
    match &p.data {
        Data::Loops(files, val_files) => {
            let res = loop_fit::fit_shown(
                loop_fit::LoopModel::from_spec(spec, &p.init)?,
                files,
                &p.init,
                p.search_options(),
                true,
            )?;
            let (page, nrmse_val) = loop_plots::html(&spec.to_string(), &res, files, val_files)?;
            // The page first: it shows a failed fit too.
            write_atomic(&a.out, report::with_sections(page, &provenance_section).as_bytes())?;
            // As `gma fit` refuses to write an invalid loop model's parameters.
            let invalid: Vec<String> =
                res.warnings.iter().filter(|w| w.invalidates()).map(|w| w.to_string()).collect();
            let params_file = match &params_folder {
                Some(_) if !invalid.is_empty() => {
                    bail!(
                        "loop report written to {written_to}, but the loop fit did not produce a valid model, so no \
                         parameter file was written: {}",
                        invalid.join("; ")
                    )
                }
                Some((dir, _)) => {
                    let paths = params_paths(dir, &[spec]);
                    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
                    let header = params_header(
                        &format!("gma report --model {spec} (seed {}), loop fit", a.mf.seed),
                        &a.mf,
                        mean(&res.nrmse).unwrap_or(f64::NAN),
                        mean(&nrmse_val),
                        res.time_limited,
                        &[],
                    );
                    write_params(&paths, &[(spec, res.apply_to(&p.init), header)], &p.inputs, &[])?;
                    Some(display(&paths[0]))
                }
                None => None,
            };
            if let Some((_, folder)) = params_folder {
                folder.keep();
            }
            a.mf.warn_if_time_limited(res.time_limited);
            say!(j, "loop report written to {written_to}");
            if let Some(f) = &params_file {
                say!(j, "  parameters written to {f}");
            }
            if a.mf.json {
                let result = json!({"report": display(&a.out), "nrmse": res.nrmse, "nrmse_val": nrmse_val, "warnings": p.input_warnings.iter().chain(&res.warnings).map(|w| w.to_string()).collect::<Vec<_>>(),
                           "time_limit_reached": res.time_limited, "params_file": params_file});
                out!("{}", super::merged_json(&result, &extra)?);
            }
        }
        Data::Recordings(fit_files, val_files) => {
            let rungs =
                report::ladder(spec, &p.init, fit_files, val_files, p.opts, |r| say!(j, "{}", r.diagnosis))?;
            let time_limited = rungs.iter().any(|r| r.diagnosis.time_limited);
            let phase = Phase::start(
                p.opts.progress,
                &format!("report: parameter uncertainty of {} model(s)", rungs.len()),
                rungs.len() as u64,
            );
            let uncertainties = report::rung_uncertainties(&rungs, fit_files, || phase.step(""));
            phase.finish();
            let phase =
                Phase::start(p.opts.progress, "report: drawing the page (each model on each file)", 0);
            let doubts =
                report::result_doubts(&rungs, fit_files, val_files, &p.input_warnings, &uncertainties);
            let html =
                report::html(&format!("gma report — {spec}"), &rungs, fit_files, val_files, "", &doubts)?;
            let sections = report::uncertainty_html(&rungs, &uncertainties) + &provenance_section;
            // The page first: the parameter files after it cannot cost the report.
            write_atomic(&a.out, report::with_sections(html, &sections).as_bytes())?;
            let params_files = match &params_folder {
                Some((dir, _)) => {
                    let specs: Vec<ModelSpec> = rungs.iter().map(|r| r.spec).collect();
                    let paths = params_paths(dir, &specs);
                    let sets = ladder_param_sets(a, spec, &rungs);
                    write_params(&paths, &sets, &p.inputs, fit_files)?;
                    paths.iter().map(|p| Some(display(p))).collect()
                }
                None => vec![None; rungs.len()],
            };
            if let Some((_, folder)) = params_folder {
                folder.keep();
            }
            phase.finish();
            a.mf.warn_if_time_limited(time_limited);
            say_uncertainties(j, &rungs, &uncertainties);
            say!(j, "report written to {written_to}");
            for f in params_files.iter().flatten() {
                say!(j, "parameters written to {f}");
            }
            if a.mf.json {
                let ladder: Vec<_> = rungs
                    .iter()
                    .zip(&uncertainties)
                    .zip(&params_files)
                    .map(|((r, u), params_file)| {
                        let rung = json!({"model": r.spec.to_string(), "nrmse_fit": r.fit_nrmse, "nrmse_val": r.val_nrmse, "verdict": r.diagnosis.verdict, "not_refitted": r.diagnosis.not_refitted, "cut_short": r.diagnosis.cut_short, "params_file": params_file});
                        match u {
                            Ok(u) => super::merged_json(&rung, &UncertaintyFields::from(u)),
                            Err(e) => super::merged_json(&rung, &json!({"uncertainty_error": e})),
                        }
                    })
                    .collect::<Result<_>>()?;
                let result =
                    json!({"report": display(&a.out), "time_limit_reached": time_limited, "ladder": ladder});
                out!("{}", super::merged_json(&result, &extra)?);
            }
        }
    }
    Ok(())
}

/// Each rung's parameters with their standard deviation and 95 % interval, as text.
fn say_uncertainties(
    j: bool,
    rungs: &[report::Rung],
    uncertainties: &[std::result::Result<Uncertainty, String>],
) {
    for (r, u) in rungs.iter().zip(uncertainties) {
        say!(j, "parameters of `{}` (± std, 95 % interval):", r.spec);
        match u {
            Ok(u) => {
                for p in &u.params {
                    match (p.std, p.ci95) {
                        (Some(s), Some((lo, hi))) => {
                            say!(
                                j,
                                "  {:28} = {:.6e} ± {s:.2e}  [{lo:.4e}, {hi:.4e}]{}",
                                p.bound.name,
                                p.value,
                                p.clipped_note()
                            )
                        }
                        _ => {
                            say!(j, "  {:28} = {:.6e} ± ?  (not identifiable)", p.bound.name, p.value)
                        }
                    }
                }
            }
            Err(e) => say!(j, "  no uncertainty: {e}"),
        }
    }
}

/// Each rung's parameter set with the header its file carries.
fn ladder_param_sets(
    a: &ReportArgs,
    spec: ModelSpec,
    rungs: &[report::Rung],
) -> Vec<(ModelSpec, ActuatorParams, String)> {
    rungs
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let header = params_header(
                &format!("gma report --model {spec} (seed {}), step {k}: `{}`", a.mf.seed, r.spec),
                &a.mf,
                mean(&r.fit_nrmse),
                (!r.val_nrmse.is_empty()).then(|| mean(&r.val_nrmse)),
                r.diagnosis.time_limited,
                &[],
            );
            (r.spec, r.params, header)
        })
        .collect()
}
