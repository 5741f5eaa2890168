//! `gma demo`: the main job on a SIMULATED rig, end to end, in under a minute.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use crate::files::{check_outputs, display, no_stdout, output_folder, shell_word, write_atomic};
use crate::fit::FitOptions;
use crate::{cases, params, report};

/// Options of `gma demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Directory for the simulated recordings, parameter files and the report.
    #[arg(long, default_value = "gma-demo")]
    pub out_dir: PathBuf,
    /// Seed of the simulated rig's noise and of the fits.
    #[arg(long, default_value_t = 1, value_parser = crate::api::inputs::seed)]
    pub seed: u64,
    /// Print exactly one JSON object on stdout (the narrative goes to stderr).
    #[arg(long)]
    pub json: bool,
}

/// Runs `gma demo`.
pub fn run(a: &DemoArgs) -> Result<()> {
    let t = std::time::Instant::now();
    let j = a.json;
    let case = cases::demo();
    no_stdout("--out-dir", &a.out_dir, "the folder of the recordings, parameter files and report")?;
    let folder = output_folder(&a.out_dir)?;
    say!(
        j,
        "gma demo: a SIMULATED Terfenol-D rig with {}, unknown to the engineer, whose model is `{}`.",
        case.plant.describe(),
        case.model
    );
    let (fit_files, val_files) = case.recordings(a.seed)?;
    let html = a.out_dir.join("report.html");
    // Every output is checked before the fits, as every command does; the parameter files'
    // names come from the ladder, so they are checked once it is climbed, before any is written.
    let recordings: Vec<PathBuf> =
        fit_files.iter().chain(&val_files).map(|r| a.out_dir.join(&r.name)).collect();
    check_outputs(&recordings.iter().chain([&html]).map(PathBuf::as_path).collect::<Vec<_>>(), &[])?;
    for (r, p) in fit_files.iter().chain(&val_files).zip(&recordings) {
        r.write(p)?;
    }
    say!(
        j,
        "  recordings: {} fit, {} validation (different frequencies and amplitudes) in {}",
        fit_files.len(),
        val_files.len(),
        display(&a.out_dir)
    );
    let opts = FitOptions { seed: a.seed, ..FitOptions::default() };
    let rungs = report::ladder(case.model, &case.init, &fit_files, &val_files, opts, |r| {
        let d = &r.diagnosis;
        // The headline scores whole files; diagnose scores each file after its burn-in (the
        // unknown initial state), so its figures differ and are labelled so.
        say!(
            j,
            "\n  model `{}`: validation NRMSE {:.2} % (whole files); after each file's burn-in, as diagnose scores:",
            r.spec,
            r.headline() * 100.0
        );
        for c in d.candidates.iter().take(3) {
            say!(
                j,
                "    {:22} {:.2} % → {:.2} % with it added",
                c.effect,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0
            );
        }
        match d.verdict {
            Some(v) => say!(j, "    → missing: `{v}`; adding it"),
            None => say!(j, "    → {}", d.no_verdict()),
        }
    })?;
    let param_paths =
        super::report::params_paths(&a.out_dir, &rungs.iter().map(|r| r.spec).collect::<Vec<_>>());
    check_outputs(&param_paths.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &[])?;
    let mut param_files = Vec::new();
    for (r, p) in rungs.iter().zip(&param_paths) {
        write_atomic(
            p,
            params::to_toml_for(
                &r.params,
                &format!("gma demo, model {}", r.spec),
                r.spec,
                &crate::fit::not_fitted(r.spec, &fit_files)?,
            )?
            .as_bytes(),
        )?;
        param_files.push(display(p));
    }
    let note = format!(
        "Simulated rig with {}; the engineer starts from `{}`. Every number below comes from the fits in this run.",
        case.plant.describe(),
        case.model
    );
    let uncertainties = report::rung_uncertainties(&rungs, &fit_files, || {});
    let doubts = report::result_doubts(&rungs, &fit_files, &val_files, &[], &uncertainties);
    let page = report::html(
        "gma demo — finding the missing physics (SIMULATED rig)",
        &rungs,
        &fit_files,
        &val_files,
        &note,
        &doubts,
    )?;
    let provenance = crate::provenance::Provenance::now(Some(a.seed));
    let start = params::ParamSource {
        parameters_source: "the demo case's start values".into(),
        parameters_defaulted: Vec::new(),
        parameters_not_fitted: Vec::new(),
        effects_not_fitted: Vec::new(),
    };
    let sections =
        report::uncertainty_html(&rungs, &uncertainties) + &report::provenance_html(&provenance, &start);
    write_atomic(&html, report::with_sections(page, &sections).as_bytes())?;
    let first = rungs.first().map(|r| r.headline()).unwrap_or(f64::NAN);
    let last = rungs.last().map(|r| r.headline()).unwrap_or(f64::NAN);
    say!(
        j,
        "\n  validation NRMSE {:.2} % (`{}`) → {:.2} % (`{}`), {:.0}× lower; report: {} ({:.1} s)",
        first * 100.0,
        case.model,
        last * 100.0,
        rungs.last().map(|r| r.spec.to_string()).unwrap_or_default(),
        first / last,
        display(&html),
        t.elapsed().as_secs_f64()
    );
    if let (Some(last), Some(params_last)) = (rungs.last(), param_paths.last()) {
        say_next_steps(j, &a.out_dir, case.model, last.spec, (&fit_files, &val_files), params_last);
    }
    if j {
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        out!(
            "{}",
            json!({
                "simulated": true,
                "hidden_effects": case.plant.describe(),
                "start_model": case.model.to_string(),
                "seed": a.seed,
                "recordings": fit_files.iter().chain(&val_files).map(|r| display(&a.out_dir.join(&r.name))).collect::<Vec<_>>(),
                "ladder": rungs.iter().map(|r| json!({
                    "model": r.spec.to_string(),
                    "nrmse_fit": mean(&r.fit_nrmse),
                    "nrmse_val": mean(&r.val_nrmse),
                    "verdict": r.diagnosis.verdict,
                })).collect::<Vec<_>>(),
                "parameter_files": param_files,
                "report": display(&html),
                "seconds": t.elapsed().as_secs_f64(),
                "provenance": provenance,
            })
        );
    }
    folder.keep();
    Ok(())
}

/// The same steps by hand, on the files just written: what an engineer does next with
/// recordings of their own (`first`: the demo's starting model, `last`: its final one).
fn say_next_steps(
    j: bool,
    out_dir: &std::path::Path,
    first: model_core::ModelSpec,
    last: model_core::ModelSpec,
    (fit_files, val_files): (&[crate::recording::Recording], &[crate::recording::Recording]),
    params_last: &std::path::Path,
) {
    let word = |r: &crate::recording::Recording| shell_word(&out_dir.join(&r.name));
    let fit: Vec<String> = fit_files.iter().map(word).collect();
    let val: String = val_files.iter().map(|r| format!(" --val {}", word(r))).collect();
    let val_only: Vec<String> = val_files.iter().map(word).collect();
    let params_last = shell_word(params_last);
    say!(
        j,
        "\n  next, the same steps by hand (your own recordings in place of these; `gma <command> --help`):\n    \
         gma diagnose --model {first} {fit}{val}\n    \
         gma fit --model {spec} {fit}{val} --params-out fitted.toml\n    \
         gma compare --model {spec} --params {params_last} {val_only} --format png",
        fit = fit.join(" "),
        spec = last,
        val_only = val_only.join(" "),
    );
}
