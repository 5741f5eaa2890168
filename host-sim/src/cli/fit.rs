//! `gma fit`: identify a model from recordings (or the magnetization stage from loop files).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;

use crate::api::fitting::{add_time_limit_warning, fit_loops, fit_recordings};
use crate::api::inputs::{Data, ModelFiles};
use crate::files::{display, names, replaces_only, to_stdout, write_atomic, OutputKind};
use crate::fit;
use crate::params;
use crate::provenance::Provenance;
use crate::warning::by_weight;

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

pub fn run(a: &FitArgs) -> Result<()> {
    let outputs: Vec<&std::path::Path> = a.params_out.as_deref().into_iter().collect();
    let params_to_stdout = match &a.params_out {
        Some(out) => to_stdout("--params-out", out, a.mf.json)?,
        None => false,
    };
    let mut p = a.mf.prepare(&outputs)?;
    // After `prepare`'s output checks: an input named as the output is said as such.
    if let Some(out) = a.params_out.as_deref().filter(|_| !params_to_stdout) {
        replaces_only(out, OutputKind::ParameterFile, "--params-out")?;
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
