//! `gma report`: the model ladder (or a loop fit) as one self-contained HTML page.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use super::common::{Data, ModelFiles};
use crate::files::{display, write_atomic};
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
    let j = a.mf.json;
    let spec = p.spec;
    match &p.data {
        Data::Loops(files, _) => {
            let res =
                loops::fit(loops::LoopModel::from_spec(spec, &p.init)?, files, &p.init, p.search_options())?;
            write_atomic(&a.out, loops::html(&spec.to_string(), &res, files)?.as_bytes())?;
            a.mf.warn_if_time_limited(res.time_limited);
            say!(j, "loop report written to {}", display(&a.out));
            if j {
                out!(
                    "{}",
                    json!({"report": display(&a.out), "nrmse": res.nrmse, "warnings": res.warnings.iter().map(|w| w.to_string()).collect::<Vec<_>>(),
                           "time_limit_reached": res.time_limited})
                );
            }
        }
        Data::Recordings(fit_files, val_files) => {
            let rungs =
                report::ladder(spec, &p.init, fit_files, val_files, p.opts, |r| say!(j, "{}", r.diagnosis))?;
            let time_limited = rungs.iter().any(|r| r.diagnosis.time_limited);
            let html = report::html(&format!("gma report — {spec}"), &rungs, fit_files, val_files, "")?;
            write_atomic(&a.out, html.as_bytes())?;
            a.mf.warn_if_time_limited(time_limited);
            say!(j, "report written to {}", display(&a.out));
            if j {
                out!(
                    "{}",
                    json!({"report": display(&a.out), "time_limit_reached": time_limited,
                    "ladder": rungs.iter().map(|r| json!({"model": r.spec.to_string(), "nrmse_fit": r.fit_nrmse, "nrmse_val": r.val_nrmse, "verdict": r.diagnosis.verdict})).collect::<Vec<_>>()})
                );
            }
        }
    }
    Ok(())
}
