//! `gma report`: the model ladder (or a loop fit) as one self-contained HTML page.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use super::common::{Data, ModelFiles};
use crate::files::{display, write_atomic};
use crate::progress::Phase;
use crate::provenance::Provenance;
use crate::results::UncertaintyFields;
use crate::{loops, report};

/// Options of `gma report`.
#[derive(Args)]
pub struct ReportArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
    /// The HTML file to write (only when the report is complete; never one of the inputs).
    #[arg(long, short, default_value = "gma-report.html")]
    pub out: PathBuf,
}

/// Runs `gma report`.
pub fn run(a: &ReportArgs) -> Result<()> {
    let p = a.mf.prepare(&[a.out.as_path()])?;
    p.warn_about_inputs();
    let j = a.mf.json;
    let spec = p.spec;
    // Every input has been read to its end: their digests are final.
    let provenance = Provenance::now(Some(a.mf.seed));
    let provenance_section = report::provenance_html(&provenance, &p.params_source);
    let extra = super::context_json(&p.params_source, &provenance);
    match &p.data {
        Data::Loops(files, val_files) => {
            let res = loops::fit_shown(
                loops::LoopModel::from_spec(spec, &p.init)?,
                files,
                &p.init,
                p.search_options(),
                true,
            )?;
            let (page, nrmse_val) = loops::html(&spec.to_string(), &res, files, val_files)?;
            write_atomic(&a.out, report::with_sections(page, &provenance_section).as_bytes())?;
            a.mf.warn_if_time_limited(res.time_limited);
            say!(j, "loop report written to {}", display(&a.out));
            if j {
                let result = json!({"report": display(&a.out), "nrmse": res.nrmse, "nrmse_val": nrmse_val, "warnings": p.input_warnings.iter().chain(&res.warnings).map(|w| w.to_string()).collect::<Vec<_>>(),
                           "time_limit_reached": res.time_limited});
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
            let html = report::html(&format!("gma report — {spec}"), &rungs, fit_files, val_files, "")?;
            let sections = report::uncertainty_html(&rungs, &uncertainties) + &provenance_section;
            write_atomic(&a.out, report::with_sections(html, &sections).as_bytes())?;
            phase.finish();
            a.mf.warn_if_time_limited(time_limited);
            for (r, u) in rungs.iter().zip(&uncertainties) {
                say!(j, "parameters of `{}` (± std, 95 % interval):", r.spec);
                match u {
                    Ok(u) => {
                        for p in &u.params {
                            match (p.std, p.ci95) {
                                (Some(s), Some((lo, hi))) => {
                                    say!(
                                        j,
                                        "  {:28} = {:.6e} ± {s:.2e}  [{lo:.4e}, {hi:.4e}]",
                                        p.bound.name,
                                        p.value
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
            say!(j, "report written to {}", display(&a.out));
            if j {
                let ladder: Vec<_> = rungs
                    .iter()
                    .zip(&uncertainties)
                    .map(|(r, u)| {
                        let rung = json!({"model": r.spec.to_string(), "nrmse_fit": r.fit_nrmse, "nrmse_val": r.val_nrmse, "verdict": r.diagnosis.verdict, "not_refitted": r.diagnosis.not_refitted, "cut_short": r.diagnosis.cut_short});
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
