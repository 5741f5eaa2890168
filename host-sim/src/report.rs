//! The model ladder and its self-contained HTML report (inline SVG): diagnose the given
//! structure, add the effect it names, refit, and repeat until nothing significant is missing;
//! then show the error falling, the loops, the residuals and the evidence.

use std::fmt::Write as _;

use anyhow::Result;
use model_core::{ActuatorParams, ModelSpec};

use crate::diagnose::{diagnose, Diagnosis};
use crate::fit::{evaluate, FitOptions};
use crate::params::ParamSource;
use crate::plots::{self, Chart, Series};
use crate::provenance::Provenance;
use crate::recording::Recording;
use crate::simulated::Simulation;
use crate::simulation::simulate;
use crate::uncertainty::{self, Uncertainty, CORRELATION_WARNING};
use crate::warning::{by_weight, Warning};

/// Most effects the ladder adds before it stops.
pub const MAX_RUNGS: usize = 4;

/// One rung: a structure, its identified parameters and its errors.
#[derive(Debug, Clone)]
pub struct Rung {
    /// The structure.
    pub spec: ModelSpec,
    /// Identified parameters.
    pub params: ActuatorParams,
    /// Identified parameter values by name.
    pub identified: Vec<(&'static str, f64)>,
    /// NRMSE per fit file.
    pub fit_nrmse: Vec<f64>,
    /// NRMSE per validation file.
    pub val_nrmse: Vec<f64>,
    /// The diagnosis of this rung.
    pub diagnosis: Diagnosis,
}

impl Rung {
    /// Mean validation NRMSE (fit when there are no validation files).
    pub fn headline(&self) -> f64 {
        let v = if self.val_nrmse.is_empty() { &self.fit_nrmse } else { &self.val_nrmse };
        v.iter().sum::<f64>() / v.len().max(1) as f64
    }
}

/// Climbs the ladder from `spec`. `on_rung` is told about each rung as it is found.
pub fn ladder(
    spec: ModelSpec,
    init: &ActuatorParams,
    fit_files: &[Recording],
    val_files: &[Recording],
    opts: FitOptions,
    mut on_rung: impl FnMut(&Rung),
) -> Result<Vec<Rung>> {
    let mut rungs: Vec<Rung> = Vec::new();
    let mut spec = spec;
    for k in 0..MAX_RUNGS {
        crate::progress::phase(
            opts.progress,
            &format!("report: rung {} of at most {MAX_RUNGS}, model `{spec}`", k + 1),
        );
        // Every rung from the engineer's start values, as the same steps by hand run: a rung
        // started from the last verdict's refit inherits the basin where the lower structure bent
        // its lags to mimic what was missing (the demo's `ja+mech` fit an overdamped mode for
        // the eddy lag, and its candidates' fresh searches, started there, never left it).
        let d = diagnose(spec, init, fit_files, val_files, opts)?;
        let base = d.baseline.clone().expect("diagnose keeps its baseline fit");
        let val =
            if val_files.is_empty() { Vec::new() } else { evaluate(spec, &base.params, val_files)?.files };
        let rung = Rung {
            spec,
            params: base.params,
            identified: base.identified.clone(),
            fit_nrmse: base.fit.files.iter().map(|f| f.nrmse).collect(),
            val_nrmse: val.iter().map(|f| f.nrmse).collect(),
            diagnosis: d.clone(),
        };
        on_rung(&rung);
        rungs.push(rung);
        let Some(v) = d.verdict else { break };
        if d.time_limited {
            break; // the next rung would start from a search cut short
        }
        spec = spec.with(v);
    }
    Ok(rungs)
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Loop chart (drive → displacement) of one file: measured and each model's.
pub fn loop_chart(rec: &Recording, models: &[(ModelSpec, ActuatorParams)]) -> Result<Chart> {
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    drive_loop(rec, models, meas, "loop", "displacement [µm]", |spec, sim| {
        let off = crate::score::score(spec, rec, sim).offset_um;
        sim.displacement_um.iter().map(|y| y + off).collect()
    })
}

/// The flux-density loop of a recording with a search coil: measured B and each model's
/// μ0 (H + g M) + c ([`crate::score::flux_fit`]) against the drive; `None` without the column.
pub fn flux_loop_chart(rec: &Recording, models: &[(ModelSpec, ActuatorParams)]) -> Result<Option<Chart>> {
    let Some(b) = rec.flux_density_t.as_deref() else { return Ok(None) };
    let chart =
        drive_loop(rec, models, b, "flux-density loop", "flux density (zero arbitrary) [T]", |_, sim| {
            crate::score::flux_fit(b, &sim.field_a_per_m, &sim.magnetization_a_per_m).1
        })?;
    Ok(Some(chart))
}

/// A channel against the drive (the current, else the command): the measured values and each
/// model's (`model` maps a run of the model to the channel).
fn drive_loop(
    rec: &Recording,
    models: &[(ModelSpec, ActuatorParams)],
    measured: &[f64],
    what: &str,
    y_label: &str,
    model: impl Fn(ModelSpec, &Simulation) -> Vec<f64>,
) -> Result<Chart> {
    let (drive, unit) = match (&rec.current_a, &rec.command_v) {
        (Some(i), _) => (i.clone(), "coil current [A]"),
        (None, Some(u)) => (u.clone(), "command [V]"),
        _ => (vec![0.0; rec.len()], "drive"),
    };
    let against_drive =
        |y: &[f64]| plots::thin(&drive.iter().copied().zip(y.iter().copied()).collect::<Vec<_>>(), 4000);
    let mut series = vec![Series { label: "measured".into(), points: against_drive(measured), color: 0 }];
    for (k, (spec, params)) in models.iter().enumerate() {
        let y = model(*spec, &simulate(*spec, params, rec)?);
        series.push(Series { label: format!("model {spec}"), points: against_drive(&y), color: k + 1 });
    }
    Ok(Chart {
        title: format!("{} — {what}", rec.name),
        x_label: unit.into(),
        y_label: y_label.into(),
        y_range: None,
        series,
    })
}

/// Residual chart (measured − model against time) of one file for each model.
pub fn residual_chart(rec: &Recording, models: &[(ModelSpec, ActuatorParams)]) -> Result<Chart> {
    let meas = rec.displacement_um.clone().unwrap_or_default();
    let mut series = Vec::new();
    for (k, (spec, params)) in models.iter().enumerate() {
        let sim = simulate(*spec, params, rec)?;
        let off = crate::score::score(*spec, rec, &sim).offset_um;
        let pts: Vec<(f64, f64)> = rec
            .time_s
            .iter()
            .zip(meas.iter().zip(&sim.displacement_um))
            .map(|(t, (m, y))| (*t, m - y - off))
            .collect();
        series.push(Series { label: format!("{spec}"), points: plots::thin(&pts, 4000), color: k + 1 });
    }
    Ok(Chart {
        title: format!("{} — residual", rec.name),
        x_label: "time [s]".into(),
        y_label: "measured − model [µm]".into(),
        y_range: None,
        series,
    })
}

/// Time-series chart of one file: measured displacement and the model's (`label`), offset added.
pub fn time_chart(rec: &Recording, sim: &Simulation, offset_um: f64, label: &str) -> Chart {
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    let measured: Vec<(f64, f64)> = rec.time_s.iter().copied().zip(meas.iter().copied()).collect();
    let model: Vec<(f64, f64)> =
        rec.time_s.iter().zip(&sim.displacement_um).map(|(t, y)| (*t, y + offset_um)).collect();
    Chart {
        title: format!("{} — time series", rec.name),
        x_label: "time [s]".into(),
        y_label: "displacement [µm]".into(),
        y_range: None,
        series: vec![
            Series { label: "measured".into(), points: plots::thin(&measured, 4000), color: 0 },
            Series { label: format!("model {label}"), points: plots::thin(&model, 4000), color: 1 },
        ],
    }
}

/// The doubts about the ladder's result, its last rung's fit: those about the inputs given, a
/// strain scale outside the materials' range, a mode no file can show, and the uncertainty's
/// (`uncertainties` per rung, as [`rung_uncertainties`] gives them).
pub fn result_doubts(
    rungs: &[Rung],
    fit_files: &[Recording],
    val_files: &[Recording],
    input_warnings: &[Warning],
    uncertainties: &[std::result::Result<Uncertainty, String>],
) -> Vec<Warning> {
    let mut doubts = input_warnings.to_vec();
    if let Some(last) = rungs.last() {
        doubts.extend(crate::fit::strain_scale_doubt(
            last.spec,
            &last.params,
            &crate::fit::Constraints::default(),
        ));
        doubts.extend(crate::fit::unresolved_mode(
            last.spec,
            &last.params,
            fit_files.iter().chain(val_files),
        ));
    }
    if let Some(Ok(u)) = uncertainties.last() {
        doubts.extend(u.warnings());
    }
    doubts
}

/// The page's opening, what a reader looks for first: the ladder's result (its last model, that
/// model's error and verdict) and the heaviest doubt about it, the others after it.
fn result_html(rungs: &[Rung], doubts: &[Warning]) -> String {
    let (Some(first), Some(last)) = (rungs.first(), rungs.last()) else { return String::new() };
    let mean = |v: &[f64]| 100.0 * v.iter().sum::<f64>() / v.len().max(1) as f64;
    let mut h = format!(
        "<h2>Result</h2><p class=v>{}</p><p>Model <code>{}</code>: fit NRMSE {:.2} %",
        esc(&last.diagnosis.headline()),
        last.spec,
        mean(&last.fit_nrmse)
    );
    if !last.val_nrmse.is_empty() {
        let _ = write!(h, ", validation NRMSE {:.2} %", mean(&last.val_nrmse));
    }
    if rungs.len() > 1 {
        let _ = write!(
            h,
            " (from {:.2} % with <code>{}</code>, whole files)",
            first.headline() * 100.0,
            first.spec
        );
    }
    h.push_str(".</p>");
    let doubts = by_weight(doubts);
    if let Some((top, rest)) = doubts.split_first() {
        let _ = write!(h, "<p class=v>Warning: {}</p>", esc(&top.to_string()));
        if !rest.is_empty() {
            let _ =
                write!(h, "<details><summary>{} more warning(s), heaviest first</summary><ul>", rest.len());
            for w in rest {
                let _ = write!(h, "<li>{}</li>", esc(&w.to_string()));
            }
            h.push_str("</ul></details>");
        }
    }
    h
}

/// The self-contained HTML page: the result and its heaviest doubt first ([`result_doubts`]),
/// then the ladder, the diagnoses, the loops and residuals.
pub fn html(
    title: &str,
    rungs: &[Rung],
    fit_files: &[Recording],
    val_files: &[Recording],
    note: &str,
    doubts: &[Warning],
) -> Result<String> {
    let models: Vec<(ModelSpec, ActuatorParams)> = rungs.iter().map(|r| (r.spec, r.params)).collect();
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title><style>\
         body{{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}}\
         table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}\
         th{{background:#f3f3f3}}td.l{{text-align:left}}.v{{color:#b00;font-weight:bold}}.fig{{margin:1em 0}}\
         code{{background:#f3f3f3;padding:0 3px}}</style></head><body><h1>{t}</h1>",
        t = esc(title)
    );
    if !note.is_empty() {
        let _ = write!(h, "<p>{}</p>", esc(note));
    }
    h.push_str(&result_html(rungs, doubts));
    // Ladder table.
    h.push_str("<h2>Model ladder</h2><table><tr><th class=l>model</th><th>fit NRMSE (mean)</th><th>validation NRMSE (mean)</th>");
    for f in fit_files {
        let _ = write!(h, "<th>{} (fit)</th>", esc(&f.name));
    }
    for f in val_files {
        let _ = write!(h, "<th>{} (val)</th>", esc(&f.name));
    }
    h.push_str("<th class=l>diagnosis</th></tr>");
    for r in rungs {
        let mean = |v: &[f64]| {
            if v.is_empty() {
                "—".to_string()
            } else {
                format!("{:.2} %", 100.0 * v.iter().sum::<f64>() / v.len() as f64)
            }
        };
        let _ = write!(
            h,
            "<tr><td class=l><code>{}</code></td><td>{}</td><td>{}</td>",
            r.spec,
            mean(&r.fit_nrmse),
            mean(&r.val_nrmse)
        );
        for v in r.fit_nrmse.iter().chain(&r.val_nrmse) {
            let _ = write!(h, "<td>{:.2} %</td>", v * 100.0);
        }
        let verdict = match r.diagnosis.verdict {
            Some(v) => format!("<span class=v>missing: {v}</span>"),
            None => esc(&r.diagnosis.no_verdict()),
        };
        let _ = write!(h, "<td class=l>{verdict}</td></tr>");
    }
    h.push_str(
        "</table><p>The ladder scores whole files, as <code>gma fit</code> and <code>gma compare</code> do. Each \
         diagnosis below scores the validation files (the fit files when there are none) after each file's burn-in (its samples up to the \
         drive's second reversal, where the rig's unknown initial magnetic state still shows), as \
         <code>gma diagnose</code> does: the same model reads differently there.</p>",
    );
    // Error falling.
    let _ = write!(h, "<div class=fig>{}</div>", error_ladder_svg(rungs)?);
    // Diagnoses.
    for r in rungs {
        let d = &r.diagnosis;
        let _ = write!(h, "<h2>Diagnosis of <code>{}</code></h2><ul>", r.spec);
        for f in &d.findings {
            let _ = write!(h, "<li>{}</li>", esc(f));
        }
        h.push_str(
            "</ul><table><tr><th class=l>candidate</th><th>score</th><th>NRMSE before (after burn-in)</th>\
             <th>after refit</th><th class=l>evidence</th></tr>",
        );
        for c in &d.candidates {
            let cls = if Some(c.effect) == d.verdict { " class=v" } else { "" };
            let _ = write!(
                h,
                "<tr><td class=l><span{cls}>{}</span></td><td>{:.2}</td><td>{:.2} %</td><td>{:.2} %</td><td class=l>{}</td></tr>",
                c.effect,
                c.score,
                c.nrmse_before * 100.0,
                c.nrmse_after * 100.0,
                esc(&c.evidence)
            );
        }
        h.push_str("</table><details><summary>identified parameters</summary><table>");
        for (n, v) in &r.identified {
            let _ = write!(h, "<tr><td class=l>{n}</td><td>{v:.6e}</td></tr>");
        }
        h.push_str("</table></details>");
    }
    // Loops and residuals per file.
    h.push_str("<h2>Loops and residuals</h2>");
    for rec in val_files.iter().chain(fit_files) {
        let _ = write!(h, "<div class=fig>{}</div>", plots::svg(&loop_chart(rec, &models)?, (900, 420))?);
        if let Some(flux) = flux_loop_chart(rec, &models)? {
            let _ = write!(h, "<div class=fig>{}</div>", plots::svg(&flux, (900, 420))?);
        }
        let _ = write!(h, "<div class=fig>{}</div>", plots::svg(&residual_chart(rec, &models)?, (900, 300))?);
    }
    if let Some(last) = models.last() {
        h.push_str(&analysis_section(last, val_files.iter().chain(fit_files))?);
    }
    h.push_str("<p><small>Generated by gma (host-sim). NRMSE = rms(measured − model) / (max − min of measured), offset fitted per file.</small></p></body></html>");
    Ok(h)
}

/// Each rung's parameter uncertainty (from its baseline fit's Jacobian, as `gma fit` reports
/// it), or why there is none; `on_rung` is called after each.
pub fn rung_uncertainties(
    rungs: &[Rung],
    fit_files: &[Recording],
    mut on_rung: impl FnMut(),
) -> Vec<std::result::Result<Uncertainty, String>> {
    rungs
        .iter()
        .map(|r| {
            let u = match &r.diagnosis.baseline {
                Some(base) => uncertainty::analyse(r.spec, base, fit_files).map_err(|e| format!("{e:#}")),
                None => Err("the rung kept no fit".into()),
            };
            on_rung();
            u
        })
        .collect()
}

/// The report's uncertainty section: per rung, each identified parameter's value ± standard
/// deviation and 95 % interval, the pairs correlated beyond |ρ| > [`CORRELATION_WARNING`] and
/// the correlation matrix (lower triangle).
pub fn uncertainty_html(
    rungs: &[Rung],
    uncertainties: &[std::result::Result<Uncertainty, String>],
) -> String {
    let mut h = String::from(
        "<h2>Parameter uncertainty</h2><p>From the Jacobian at each rung's optimum, the residuals' \
         autocorrelation taken into account (as <code>gma fit</code> reports it); log-scaled parameters \
         have log-normal intervals.</p>",
    );
    for (r, u) in rungs.iter().zip(uncertainties) {
        let _ = write!(h, "<h3>Model <code>{}</code></h3>", r.spec);
        let u = match u {
            Ok(u) => u,
            Err(e) => {
                let _ = write!(h, "<p>No uncertainty: {}</p>", esc(e));
                continue;
            }
        };
        h.push_str(
            "<table><tr><th class=l>parameter</th><th>value</th><th>± std</th><th>95 % interval</th></tr>",
        );
        for p in &u.params {
            let (std, ci) = match (p.std, p.ci95) {
                (Some(s), Some((lo, hi))) => {
                    (format!("{s:.3e}"), format!("[{lo:.4e}, {hi:.4e}]{}", p.clipped_note()))
                }
                _ => ("—".into(), "not identifiable".into()),
            };
            let _ = write!(
                h,
                "<tr><td class=l>{}</td><td>{:.6e}</td><td>{std}</td><td>{ci}</td></tr>",
                p.bound.name, p.value
            );
        }
        h.push_str("</table>");
        let mut pairs = Vec::new();
        for i in 0..u.params.len() {
            for j in 0..i {
                let rho = u.correlation[i][j];
                if rho.abs() > CORRELATION_WARNING {
                    pairs.push(format!(
                        "<code>{}</code> – <code>{}</code>: ρ = {rho:+.3}",
                        u.params[j].bound.name, u.params[i].bound.name
                    ));
                }
            }
        }
        let _ = write!(
            h,
            "<p>Strongly correlated pairs (|ρ| &gt; {CORRELATION_WARNING}): {}. N = {} residuals, lag-1 \
             autocorrelation {:.2}, effective N {:.0}.</p>",
            if pairs.is_empty() { "none".to_string() } else { pairs.join("; ") },
            u.samples,
            u.lag1_autocorrelation,
            u.effective_samples
        );
        h.push_str("<details><summary>correlation matrix</summary><table><tr><th></th>");
        for k in 1..=u.params.len() {
            let _ = write!(h, "<th>{k}</th>");
        }
        h.push_str("</tr>");
        for (i, p) in u.params.iter().enumerate() {
            let _ = write!(h, "<tr><td class=l>{} {}</td>", i + 1, p.bound.name);
            for rho in &u.correlation[i][..=i] {
                // Not identifiable: no correlation.
                let cell = if rho.is_finite() { format!("{rho:+.2}") } else { "?".into() };
                let _ = write!(h, "<td>{cell}</td>");
            }
            h.push_str("</tr>");
        }
        h.push_str("</table></details>");
    }
    h
}

/// The report's provenance section: gma version, command line, seed, date and every input's
/// SHA-256, and where the start parameters came from.
pub fn provenance_html(p: &Provenance, params: &ParamSource) -> String {
    let mut h = String::from("<h2>Provenance</h2><table>");
    let row = |h: &mut String, k: &str, v: &str| {
        let _ = write!(h, "<tr><td class=l>{k}</td><td class=l>{v}</td></tr>");
    };
    row(&mut h, "gma version", &esc(p.gma_version));
    row(&mut h, "command line", &format!("<code>{}</code>", esc(&p.command())));
    row(&mut h, "seed", &p.seed.map_or("—".into(), |s| s.to_string()));
    row(&mut h, "date (UTC)", &esc(&p.date_utc));
    let defaulted = if params.parameters_defaulted.is_empty() {
        String::new()
    } else {
        format!(" (demo values for: {})", esc(&params.parameters_defaulted.join(", ")))
    };
    row(&mut h, "start parameters", &format!("{}{defaulted}", esc(&params.parameters_source)));
    h.push_str("</table>");
    if p.inputs.is_empty() {
        // `gma demo` reads nothing: its recordings are simulated in the run (by the seed above).
        h.push_str("<p>No input files: the recordings were SIMULATED in this run.</p>");
        return h;
    }
    h.push_str("<table><tr><th class=l>input</th><th>bytes</th><th class=l>SHA-256</th></tr>");
    for i in &p.inputs {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td class=l><code>{}</code></td></tr>",
            esc(&i.file),
            i.bytes,
            i.sha256
        );
    }
    h.push_str("</table>");
    h
}

/// `page` with `sections` added at the end of its body.
pub fn with_sections(mut page: String, sections: &str) -> String {
    let at = page.rfind("</body>").unwrap_or(page.len());
    page.insert_str(at, sections);
    page
}

/// The error ladder as bars: one group per model (named on the axis), fit and validation mean
/// NRMSE [%] written on the bars.
fn error_ladder_svg(rungs: &[Rung]) -> Result<String> {
    let mean = |v: &[f64]| (!v.is_empty()).then(|| 100.0 * v.iter().sum::<f64>() / v.len() as f64);
    let bars = plots::Bars {
        title: "error as effects are added".into(),
        y_label: "mean NRMSE [%]".into(),
        categories: rungs.iter().map(|r| r.spec.to_string()).collect(),
        series: vec![
            ("fit".into(), rungs.iter().map(|r| mean(&r.fit_nrmse)).collect(), 2),
            ("validation".into(), rungs.iter().map(|r| mean(&r.val_nrmse)).collect(), 1),
        ],
        value_format: |v| format!("{v:.1} %"),
    };
    plots::bars_svg(&bars, (760, 340))
}

/// Residual correlation and frequency response of the final model on each file (the analysis
/// of `gma compare`); a file too short for it gets a line saying why.
fn analysis_section<'a>(
    (spec, params): &(ModelSpec, ActuatorParams),
    files: impl Iterator<Item = &'a Recording>,
) -> Result<String> {
    let mut h = format!("<h2>Residual and frequency analysis of <code>{spec}</code></h2>");
    h.push_str(
        "<p>Residual autocorrelation and drive–residual cross-correlation with the ±1.96/√N band of \
         white noise (a correlated residual makes that band optimistic); H1 frequency responses of \
         the measured and the model displacement from the same drive, over the excited band.</p>",
    );
    for rec in files {
        let sim = simulate(*spec, params, rec)?;
        let off = crate::score::score(*spec, rec, &sim).offset_um;
        match crate::analysis::analyse(rec, &sim, off, crate::analysis::DEFAULT_MAX_LAG) {
            Ok(fa) => {
                let _ = write!(h, "<pre>{}</pre>", esc(&fa.summary.to_string()));
                let _ = write!(
                    h,
                    "<div class=fig>{}</div>",
                    plots::svg_panels(&fa.correlation_charts(), (900, 560), plots::XScale::Linear)?
                );
                let _ = write!(
                    h,
                    "<div class=fig>{}</div>",
                    plots::svg_panels(&fa.bode_charts(&spec.to_string()), (900, 760), plots::XScale::Log)?
                );
            }
            Err(e) => {
                let _ = write!(h, "<p>{}: no analysis: {}</p>", esc(&rec.name), esc(&e.to_string()));
            }
        }
    }
    Ok(h)
}
