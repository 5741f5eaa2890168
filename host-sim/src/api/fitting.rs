//! `fit` as a whole: the search, then the parameters' uncertainty, the doubts about the result
//! and the validation scores, summarised as the CLI prints it and the JSON gives it.

use std::time::Instant;

use anyhow::Result;

use crate::api::inputs::Prepared;
use crate::fit;
use crate::loop_fit;
use crate::loops::LoopFile;
use crate::recording::Recording;
use crate::results::{FileScoreRow, FitSummary, FitText};
use crate::uncertainty;
use crate::warning::Warning;

/// Runs `gma fit`.
/// The J–A form a model with the J–A law runs (`[ja] variant`); None for other laws.
pub fn ja_variant(spec: model_core::ModelSpec, p: &model_core::ActuatorParams) -> Option<&'static str> {
    (spec.law() == model_core::MagnetizationLaw::JilesAtherton).then(|| p.ja.variant.name())
}

/// The time limit is a doubt like the others: said, and in the JSON's `warnings` too.
pub fn add_time_limit_warning(
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

/// The fit of displacement recordings.
pub fn fit_recordings(
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
    if let Some(w) = fit::strain_scale_doubt(p.spec, &res.params, constraints) {
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
    // Judged at the fitted parameters: the start set may sit elsewhere on the rod's curve.
    warnings.extend(fit::sign_and_scale_doubts(&p.init, &res, fit_files, val_files, p.opts, constraints)?);
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
    recs.iter().zip(scores).flat_map(|(r, s)| FileScoreRow::for_recording(r, Some(split), s)).collect()
}

/// The magnetization stage alone, on loop files.
pub fn fit_loops(
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
        .map(|(f, e)| FileScoreRow::new(&f.name, Some("fit"), (f.channel.name(), &f.value), *e))
        .collect();
    let mut val_nrmse = Vec::new();
    let h_max =
        fit_files.iter().chain(val_files).flat_map(|f| f.h.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    for f in val_files {
        let m = loop_fit::run(model, &res.values(), &f.h, h_max)
            .map_err(|e| crate::error::InRecording::error(&f.name, e.0))?;
        let e = crate::score::nrmse(&f.value, &f.channel_from_m(&m));
        files.push(FileScoreRow::new(&f.name, Some("val"), (f.channel.name(), &f.value), e));
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
