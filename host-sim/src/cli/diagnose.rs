//! `gma diagnose`: fit a model, analyse what it leaves unexplained, name the missing effect.

use anyhow::{bail, Result};
use clap::Args;
use serde_json::json;

use super::common::{warn_time_limited, Data, ModelFiles};
use crate::diagnose::{diagnose, Diagnosis};

/// Options of `gma diagnose`.
#[derive(Args)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    pub mf: ModelFiles,
}

/// Runs `gma diagnose`.
pub fn run(a: &DiagnoseArgs) -> Result<()> {
    let p = a.mf.prepare(&[])?;
    let Data::Recordings(fit_files, val_files) = &p.data else {
        bail!("diagnose works on displacement recordings; for magnetization loops use `gma fit` and `gma compare`");
    };
    let d = diagnose(p.spec, &p.init, fit_files, val_files, p.opts)?;
    print(a.mf.json, &d);
    if d.time_limited {
        warn_time_limited(a.mf.time_limit);
    }
    if a.mf.json {
        out!("{}", to_json(&d));
    }
    Ok(())
}

/// The diagnosis as the contract's JSON object (plus `undistinguished`, `findings`, `evidence_r2`,
/// `time_limit_reached`).
pub fn to_json(d: &Diagnosis) -> serde_json::Value {
    json!({
        "model": d.model, "nrmse_fit": d.nrmse_fit, "nrmse_val": d.nrmse_val,
        "candidates": d.candidates.iter().map(|c| json!({
            "effect": c.effect, "channel": c.channel, "score": c.score, "evidence": c.evidence,
            "nrmse_before": c.nrmse_before, "nrmse_after": c.nrmse_after, "evidence_r2": c.evidence_r2})).collect::<Vec<_>>(),
        "verdict": d.verdict, "undistinguished": d.undistinguished, "findings": d.findings,
        "time_limit_reached": d.time_limited,
    })
}

/// The diagnosis in words.
pub fn print(j: bool, d: &Diagnosis) {
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
