//! A loop file's plots: measured and modelled loops, and the page section that shows them.

use anyhow::Result;

use crate::loop_fit::{nrmse, run, LoopFit};
use crate::loops::{feature_text, features, LoopChannel, LoopFile, COERCIVITY_LABEL, REMANENCE_LABEL};

/// The loop chart of one file: measured and modelled, H in kA/m.
pub fn chart(f: &LoopFile, m: &[f64], label: &str) -> crate::plots::Chart {
    use crate::plots::{Chart, Series};
    let modelled = f.channel_from_m(m);
    let (unit, scale) = match f.channel {
        LoopChannel::FluxDensity => ("flux density B [T]", 1.0),
        LoopChannel::Magnetization => ("magnetization M [kA/m]", 1e-3),
    };
    Chart {
        title: format!("{} — {label}", f.name),
        x_label: "field H [kA/m]".into(),
        y_label: unit.into(),
        y_range: None,
        series: vec![
            Series {
                label: "measured".into(),
                points: f.h.iter().zip(&f.value).map(|(h, v)| (h * 1e-3, v * scale)).collect(),
                color: 0,
            },
            Series {
                label: format!("model {label}"),
                points: f.h.iter().zip(&modelled).map(|(h, v)| (h * 1e-3, v * scale)).collect(),
                color: 1,
            },
        ],
    }
}

/// A self-contained HTML page for a loop fit: parameters, warnings, per-file error, loops
/// overlaid, and coercivity, remanence and largest |M| side by side.
pub fn html(
    spec: &str,
    fit: &LoopFit,
    files: &[LoopFile],
    val_files: &[LoopFile],
) -> Result<(String, Vec<f64>)> {
    use std::fmt::Write as _;
    let reach = |fs: &[&LoopFile]| fs.iter().flat_map(|f| f.h.iter()).fold(0.0f64, |a, v| a.max(v.abs()));
    // As `gma fit` scores them: the fit files at their own reach, validation files at the reach
    // of all files.
    let h_fit = reach(&files.iter().collect::<Vec<_>>());
    let h_all = reach(&files.iter().chain(val_files).collect::<Vec<_>>());
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>gma loop fit — {spec}</title>\
         <style>body{{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #ccc;padding:4px 8px;text-align:right}}td.l{{text-align:left}}.w{{color:#b00}}</style>\
         </head><body><h1>Magnetization loop fit — <code>{spec}</code></h1><p>{} evaluations; {} fit file(s), {} \
         validation file(s) (scored, never fitted).</p><table><tr><th>parameter</th><th>value</th></tr>",
        fit.evaluations,
        files.len(),
        val_files.len()
    );
    for (n, v) in &fit.params {
        let _ = write!(h, "<tr><td class=l>{n}</td><td>{v:.5e}</td></tr>");
    }
    h.push_str("</table>");
    for w in &fit.warnings {
        let _ = write!(h, "<p class=w>warning: {}</p>", w.to_string().replace('<', "&lt;"));
    }
    let mut val_nrmse = Vec::new();
    let roles =
        files.iter().map(|f| (f, "fit", h_fit)).chain(val_files.iter().map(|f| (f, "validation", h_all)));
    for (f, role, h_max) in roles {
        let m = run(fit.model, &fit.values(), &f.h, h_max)
            .map_err(|e| crate::error::InRecording::error(&f.name, e.0))?;
        let e = nrmse(&f.value, &f.channel_from_m(&m));
        if role == "validation" {
            val_nrmse.push(e);
        }
        let (a, b) = (features(&f.h, &f.magnetization()), features(&f.h, &m));
        let _ = write!(
            h,
            "<h2>{} ({role})</h2><p>NRMSE {:.3} % ({})</p><table><tr><th></th><th>measured</th><th>model</th></tr>\
             <tr><td class=l>{COERCIVITY_LABEL}</td><td>{}</td><td>{}</td></tr>\
             <tr><td class=l>{REMANENCE_LABEL}</td><td>{}</td><td>{}</td></tr>\
             <tr><td class=l>largest |M| [A/m]</td><td>{}</td><td>{}</td></tr></table>{}",
            f.name.replace('<', "&lt;"),
            e * 100.0,
            f.channel.name(),
            feature_text(a.coercivity_a_per_m),
            feature_text(b.coercivity_a_per_m),
            feature_text(a.remanence_a_per_m),
            feature_text(b.remanence_a_per_m),
            feature_text(a.max_magnetization_a_per_m),
            feature_text(b.max_magnetization_a_per_m),
            crate::plots::svg(&chart(f, &m, spec), (900, 520))?
        );
    }
    h.push_str("</body></html>");
    Ok((h, val_nrmse))
}
