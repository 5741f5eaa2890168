//! What the diagnosis says beside the verdict: the baseline's residual, the error's trends across
//! files, and what is left once the verdict is added.

use super::candidate::Candidate;
use super::scoring::displacement_scores;
use super::signatures::structured_residual;
use super::signatures::whiteness;
use super::signatures::Signals;
use crate::diagnose::drive_stats;
use crate::fit::{self, evaluate, FitResult};
use crate::recording::Recording;
use crate::signal::mean;
use crate::warning::Warning;
use anyhow::Result;
use model_core::{Effect, ModelSpec};

/// What the baseline's fit says by itself: whether its residual is white, and the parameters it
/// bent to the end of their range.
pub(crate) fn baseline_findings(spec: ModelSpec, base: &FitResult, sigs: &[Signals]) -> Vec<String> {
    let mut findings = Vec::new();
    // λ_s far outside the materials' range is most often a displacement in another unit, said
    // first (a doubt about the data outweighs the residual's statistics) and as `gma fit` says it.
    if let Some(w) = fit::strain_scale_doubt(spec, &base.params, &fit::Constraints::default()) {
        findings.push(format!("in the fit of `{spec}`: {w}"));
    }
    let white = whiteness(&sigs.iter().map(|s| s.residual.as_slice()).collect::<Vec<_>>());
    let (not_white, white_limit) = structured_residual(white, sigs.len());
    findings.push(if not_white {
        format!(
            "residual is not white: {:.0} % of autocorrelation lags 1–20 lie outside the 95 % band, white noise leaves at \
             most {:.0} % (something systematic is left)",
            white * 100.0,
            white_limit * 100.0
        )
    } else {
        format!("residual is close to white: {:.0} % of lags 1–20 outside the 95 % band", white * 100.0)
    });
    // The other parameters the fit left at a range's end, in one finding: a structure that
    // lacks an effect often bends a parameter that far to stand in for it.
    let at_edge: Vec<String> = base
        .free
        .iter()
        .filter(|f| f.name() != model_core::effects::STRAIN_SCALE.key)
        .filter_map(|f| {
            let value = (f.get)(&base.params);
            f.bound.at_edge(value).then(|| {
                Warning::AtEdge { param: f.name(), value, lo: f.bound.lo, hi: f.bound.hi }.to_string()
            })
        })
        .collect();
    if !at_edge.is_empty() {
        findings.push(format!(
            "in the fit of `{spec}`, {}: a structure that lacks an effect often bends a parameter to the end \
             of its range to stand in for it (refitted with that effect, the parameter moves off the end); a \
             parameter the data do not need ends there too",
            at_edge.join("; ")
        ));
    }
    findings
}

/// The baseline's error across all files against excitation frequency, drive amplitude and
/// record length: a finding where it follows one of them.
pub(crate) fn file_trends(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    fit_files: &[Recording],
    val_files: &[Recording],
) -> Result<Vec<String>> {
    let mut per_file: Vec<(f64, f64, f64, f64)> = Vec::new(); // freq, amplitude, duration, nrmse
    let all_files: Vec<&Recording> = fit_files.iter().chain(val_files).collect();
    let all_scores = evaluate(spec, params, &all_files.iter().map(|r| (*r).clone()).collect::<Vec<_>>())?;
    for (rec, sc) in all_files.iter().zip(&all_scores.files) {
        let (f, a) = drive_stats(rec);
        per_file.push((f, a, rec.duration_s(), sc.nrmse));
    }
    // The extreme files along each quantity, the error at each, and the quantity's values there.
    let trend = |key: fn(&(f64, f64, f64, f64)) -> f64, what: &'static str, unit: &'static str| {
        let mut order: Vec<usize> = (0..per_file.len()).collect();
        order.sort_by(|&a, &b| key(&per_file[a]).total_cmp(&key(&per_file[b])));
        let (lo, hi) = (*order.first()?, *order.last()?);
        let (a, b) = (&per_file[lo], &per_file[hi]);
        if key(b) <= 1.5 * key(a) {
            return None;
        }
        let ratio = b.3 / a.3.max(1e-12);
        (!(0.67..=1.5).contains(&ratio)).then_some(Trend { lo, hi, what, unit, from: key(a), to: key(b) })
    };
    // The amplitude is the current's where a file has one, else the command's.
    let drive_unit = match (
        all_files.iter().all(|r| r.current_a.is_some()),
        all_files.iter().all(|r| r.current_a.is_none()),
    ) {
        (true, _) => "A (current_A)",
        (_, true) => "V (command_V)",
        _ => "A (current_A) or V (command_V, files without a current)",
    };
    let trends: Vec<Trend> = [
        trend(|r| r.0, "excitation frequency", "Hz"),
        trend(|r| r.1, "drive amplitude (rms)", drive_unit),
        trend(|r| r.2, "record length", "s"),
    ]
    .into_iter()
    .flatten()
    .collect();
    let names: Vec<&str> = all_files.iter().map(|r| r.name.as_str()).collect();
    Ok(trend_findings(&trends, &per_file, &names))
}

/// What the final structure (the verdict added, or the given one) still leaves, in findings.
pub(crate) fn what_is_left(
    baseline: &super::judge::Baseline,
    candidates: &[Candidate],
    verdict: Option<Effect>,
) -> Result<Vec<String>> {
    let super::judge::Baseline { spec, base, fit_files, score_files, fit_skip, score_skip, held_out, .. } =
        *baseline;
    let before = mean(baseline.score_disp.iter().map(|s| s.nrmse));
    let mut findings = Vec::new();
    let (final_spec, final_params, final_val) = match candidates.first().filter(|c| Some(c.effect) == verdict)
    {
        Some(c) if c.channel == "displacement" => {
            (spec.with(c.effect), c.refit.as_ref().map_or(base.params, |f| f.params), c.nrmse_after)
        }
        // Judged on another channel: what is left is reported on the displacement.
        Some(c) => {
            let p = c.refit.as_ref().map_or(base.params, |f| f.params);
            let val = displacement_scores(spec.with(c.effect), &p, score_files, score_skip)?;
            (spec.with(c.effect), p, mean(val.iter().map(|s| s.nrmse)))
        }
        _ => (spec, base.params, before),
    };
    // A verdict judged on the current (or the flux) can leave the displacement worse for now:
    // the refit spends its freedom on the channel the effect models. Said, never left to be
    // found in the ladder.
    if let Some(c) = candidates.first().filter(|c| Some(c.effect) == verdict && c.channel != "displacement") {
        if final_val > before {
            findings.push(format!(
                "with `{effect}` added the displacement's validation NRMSE rises from {before:.2} % to {after:.2} %: \
                 `{effect}` is judged on the {channel} it models (above), where the refit spent its freedom",
                effect = c.effect,
                before = before * 100.0,
                after = final_val * 100.0,
                channel = c.channel
            ));
        }
    }
    let final_fit = displacement_scores(final_spec, &final_params, fit_files, fit_skip)?;
    let white_final = whiteness(&final_fit.iter().map(|s| s.residual.as_slice()).collect::<Vec<_>>());
    let (structured, band) = structured_residual(white_final, final_fit.len());
    if structured {
        findings.push(match verdict {
            None => format!(
                "{:.2} % unexplained ({} NRMSE), not one of the known effects: the residual is structured ({:.0} % of \
                 autocorrelation lags 1–20 outside the 95 % band, white noise leaves at most {:.0} %) yet no candidate passes",
                final_val * 100.0,
                if held_out { "validation" } else { "fit-file" },
                white_final * 100.0,
                band * 100.0
            ),
            Some(v) => format!(
                "with `{v}` added {:.2} % stays unexplained and structured ({:.0} % of lags outside the band, white noise at \
                 most {:.0} %): diagnose `{}` again; what is left may be none of the known effects",
                final_val * 100.0,
                white_final * 100.0,
                band * 100.0,
                spec.with(v)
            ),
        });
    }
    Ok(findings)
}

/// The files at the two ends of one quantity (frequency, amplitude, length) whose errors differ.
pub(crate) struct Trend {
    pub(crate) lo: usize,
    pub(crate) hi: usize,
    pub(crate) what: &'static str,
    pub(crate) unit: &'static str,
    pub(crate) from: f64,
    pub(crate) to: f64,
}

/// One finding per pair of files: trends read from the same two files are one observation (the
/// files differ in those quantities at once and cannot say which the error follows).
pub(crate) fn trend_findings(
    trends: &[Trend],
    per_file: &[(f64, f64, f64, f64)],
    names: &[&str],
) -> Vec<String> {
    let mut out = Vec::new();
    let mut done = vec![false; trends.len()];
    for (i, t) in trends.iter().enumerate() {
        if done[i] {
            continue;
        }
        let same: Vec<&Trend> = trends
            .iter()
            .enumerate()
            .filter(|(_, u)| (u.lo, u.hi) == (t.lo, t.hi) || (u.lo, u.hi) == (t.hi, t.lo))
            .map(|(j, u)| {
                done[j] = true;
                u
            })
            .collect();
        let (a, b) = (per_file[t.lo].3, per_file[t.hi].3);
        if let [only] = same.as_slice() {
            out.push(format!(
                "error {} with {}: {:.2} % at {:.3} {unit} → {:.2} % at {:.3} {unit}",
                if b > a { "grows" } else { "falls" },
                only.what,
                a * 100.0,
                only.from,
                b * 100.0,
                only.to,
                unit = only.unit
            ));
        } else {
            // Each quantity's values in the files' order (from the first file to the second).
            let how: Vec<String> = same
                .iter()
                .map(|u| {
                    let (x, y) = if u.lo == t.lo { (u.from, u.to) } else { (u.to, u.from) };
                    format!("{} {x:.3} → {y:.3} {}", u.what, u.unit)
                })
                .collect();
            out.push(format!(
                "error {:.2} % in {} against {:.2} % in {}, files that differ in {} at once: they cannot say which \
                 the error follows (a file that changes one of them alone can)",
                a * 100.0,
                names[t.lo],
                b * 100.0,
                names[t.hi],
                how.join(", ")
            ));
        }
    }
    out
}
