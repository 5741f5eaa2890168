//! `gma demo`: the main job on a SIMULATED rig, end to end, in under a minute.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use crate::files::{display, output_folder, write_atomic};
use crate::fit::FitOptions;
use crate::{cases, params, report};

/// Options of `gma demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Directory for the simulated recordings, parameter files and the report.
    #[arg(long, default_value = "gma-demo")]
    pub out_dir: PathBuf,
    /// Seed of the simulated rig's noise and of the fits.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `gma demo`.
pub fn run(a: &DemoArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let case = cases::demo();
    output_folder(&a.out_dir)?;
    out!(
        "gma demo: a SIMULATED Terfenol-D rig with {}, unknown to the engineer, whose model is `{}`.",
        case.plant.describe(),
        case.model
    );
    let (fit_files, val_files) = case.recordings(a.seed)?;
    for r in fit_files.iter().chain(&val_files) {
        let p = a.out_dir.join(&r.name);
        r.write(&p)?;
    }
    out!(
        "  recordings: {} fit, {} validation (different frequencies and amplitudes) in {}",
        fit_files.len(),
        val_files.len(),
        display(&a.out_dir)
    );
    let opts = FitOptions { seed: a.seed, ..FitOptions::default() };
    let rungs = report::ladder(case.model, &case.init, &fit_files, &val_files, opts, |r| {
        let d = &r.diagnosis;
        out!("\n  model `{}`: validation NRMSE {:.2} %", r.spec, r.headline() * 100.0);
        for c in d.candidates.iter().take(3) {
            out!(
                "    {:22} {:.2} % → {:.2} % after adding it",
                c.effect,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0
            );
        }
        match d.verdict {
            Some(v) => out!("    → missing: `{v}`; adding it"),
            None => out!("    → nothing significant is missing"),
        }
    })?;
    for (k, r) in rungs.iter().enumerate() {
        let p = a.out_dir.join(format!("params-{k}-{}.toml", r.spec.to_string().replace('+', "_")));
        write_atomic(&p, params::to_toml(&r.params, &format!("gma demo, model {}", r.spec))?.as_bytes())?;
    }
    let html = a.out_dir.join("report.html");
    let note = format!(
        "Simulated rig with {}; the engineer starts from `{}`. Every number below comes from the fits in this run.",
        case.plant.describe(),
        case.model
    );
    let page = report::html(
        "gma demo — finding the missing physics (SIMULATED rig)",
        &rungs,
        &fit_files,
        &val_files,
        &note,
    )?;
    write_atomic(&html, page.as_bytes())?;
    let first = rungs.first().map(|r| r.headline()).unwrap_or(f64::NAN);
    let last = rungs.last().map(|r| r.headline()).unwrap_or(f64::NAN);
    out!(
        "\n  validation NRMSE {:.2} % (`{}`) → {:.2} % (`{}`), {:.0}× lower; report: {} ({:.1} s)",
        first * 100.0,
        case.model,
        last * 100.0,
        rungs.last().map(|r| r.spec.to_string()).unwrap_or_default(),
        first / last,
        display(&html),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
