//! `gma compare`'s residual and frequency analysis and `--out-csv`, through the binary, on
//! SIMULATED recordings (`gma simulate`, the workbench's own plant).

mod common;

use common::{err, gma, one_svg_document, refused};
use std::path::Path;

fn simulate(path: &Path, model: &str, waveform: &str, freq_hz: &str, duration_s: &str) {
    let o = gma(&[
        "simulate",
        "--model",
        model,
        "--waveform",
        waveform,
        "--freq-hz",
        freq_hz,
        "--amplitude",
        "0.5",
        "--bias",
        "1",
        "--duration-s",
        duration_s,
        "--noise-um",
        "0.02",
        "--out",
        path.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
}

fn json(o: &std::process::Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", err(o));
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&o.stdout)))
}

/// `--out-csv` adds up (measured − model = residual), and the figures the JSON and text give
/// per file (MATLAB's fit %) follow from it by hand.
#[test]
fn compare_writes_the_analysis_plots_and_a_time_series_csv_that_adds_up() {
    let dir = tempfile::tempdir().unwrap();
    let chirp = dir.path().join("chirp.csv");
    let sine = dir.path().join("sine.csv");
    simulate(&chirp, "ja+mech+eddy", "chirp", "2000", "0.5");
    simulate(&sine, "ja+mech+eddy", "sine", "100", "0.2");
    let plots = dir.path().join("plots");
    let table = dir.path().join("series.csv");
    let run = |model: &str| {
        json(&gma(&[
            "compare",
            "--model",
            model,
            "--json",
            "--format",
            "png",
            "--out-dir",
            plots.to_str().unwrap(),
            "--out-csv",
            table.to_str().unwrap(),
            chirp.to_str().unwrap(),
            sine.to_str().unwrap(),
        ]))
    };
    let lumped = run("ja+mech+eddy");
    for stem in ["chirp", "sine"] {
        for kind in ["loop", "time", "residual", "correlation", "spectrum", "bode"] {
            let png = std::fs::read(plots.join(format!("{stem}-{kind}.png"))).unwrap();
            assert!(png.starts_with(b"\x89PNG"), "{stem}-{kind}.png is not a PNG");
        }
    }

    // The CSV: one header, every sample of both files in order, measured − model = residual.
    let mut rd = csv::Reader::from_path(&table).unwrap();
    assert_eq!(rd.headers().unwrap(), vec!["file", "time_s", "measured_um", "model_um", "residual_um"]);
    let rows: Vec<csv::StringRecord> = rd.records().map(Result::unwrap).collect();
    let count = |name: &Path| rows.iter().filter(|r| &r[0] == name.to_str().unwrap()).count();
    assert_eq!((count(&chirp), count(&sine)), (5000, 2000), "rows per file");
    let mut residual_ss = 0.0;
    for r in &rows {
        let v = |k: usize| r[k].parse::<f64>().unwrap();
        assert_eq!(v(2) - v(3), v(4), "measured − model ≠ residual in {r:?}");
        residual_ss += v(4) * v(4);
    }
    assert!(residual_ss > 0.0);

    // MATLAB's fit, 100 (1 − ‖y − ŷ‖/‖y − ȳ‖), worked out by hand from the CSV, is each file's
    // `fit_percent`, and the text shows it.
    for (k, name) in [&chirp, &sine].iter().enumerate() {
        let own: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| &r[0] == name.to_str().unwrap())
            .map(|r| (r[2].parse::<f64>().unwrap(), r[4].parse::<f64>().unwrap()))
            .collect();
        let mean = own.iter().map(|(y, _)| y).sum::<f64>() / own.len() as f64;
        let residual = own.iter().map(|(_, e)| e * e).sum::<f64>().sqrt();
        let about_mean = own.iter().map(|(y, _)| (y - mean) * (y - mean)).sum::<f64>().sqrt();
        let by_hand = 100.0 * (1.0 - residual / about_mean);
        let reported = lumped["files"][k]["fit_percent"].as_f64().unwrap();
        assert!(
            (reported - by_hand).abs() < 1e-6,
            "{name:?}: fit_percent {reported} against {by_hand} by hand"
        );
        assert!((50.0..100.0).contains(&by_hand), "{name:?}: fit {by_hand} %");
    }
    let text = gma(&[
        "compare",
        "--model",
        "ja+mech+eddy",
        "--out-dir",
        plots.to_str().unwrap(),
        sine.to_str().unwrap(),
    ]);
    let fit = lumped["files"][1]["fit_percent"].as_f64().unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).contains(&format!("fit {fit:5.1} %")), "{}", err(&text));

    // The JSON gains the analysis; the bounds follow N.
    let files = lumped["files"].as_array().unwrap();
    let a = &files[0]["analysis"];
    assert_eq!(files[0]["plots"].as_array().unwrap().len(), 6);
    let acf = &a["residual_autocorrelation"];
    assert_eq!(acf["samples"], 5000);
    assert!((acf["bound"].as_f64().unwrap() - 1.96 / 5000f64.sqrt()).abs() < 1e-12);
    assert_eq!(acf["max_lag"], 100);
    let share = acf["outside_share"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&share));
    let chirp_band = a["frequency_response"]["band_hz"].as_array().unwrap();
    let (lo, hi) = (chirp_band[0].as_f64().unwrap(), chirp_band[1].as_f64().unwrap());
    // The chirp sweeps 200 Hz – 2 kHz: its excited band lies inside that and covers most of it.
    assert!((150.0..400.0).contains(&lo) && hi > 1500.0 && hi <= 2050.0, "band {lo}–{hi} Hz");
    // A single 100 Hz sine excites only the bins of its window's main lobe and first side lobes (within 3 bins of 19.5 Hz).
    let sine_fr = &files[1]["analysis"]["frequency_response"];
    let sine_band = sine_fr["band_hz"].as_array().unwrap();
    assert!(
        sine_band[0].as_f64().unwrap() >= 40.0 && sine_band[1].as_f64().unwrap() <= 160.0,
        "{sine_band:?}"
    );
    assert!(sine_fr["bins"].as_u64().unwrap() <= 5, "{sine_fr}");

    // Leaving out the eddy currents shows in the frequency response and the whiteness.
    let no_eddy = run("ja+mech");
    let fr =
        |j: &serde_json::Value, k: &str| j["files"][0]["analysis"]["frequency_response"][k].as_f64().unwrap();
    assert!(
        fr(&no_eddy, "phase_error_deg_rms") > 2.0 * fr(&lumped, "phase_error_deg_rms"),
        "phase error without eddy {} vs with {}",
        fr(&no_eddy, "phase_error_deg_rms"),
        fr(&lumped, "phase_error_deg_rms")
    );
}

#[test]
fn every_svg_plot_is_one_document_with_all_its_panels_inside() {
    // The Bode plot (gain, phase, coherence) and the correlation plot (autocorrelation above,
    // cross-correlation below) are stacked panels in one figure: each must be drawn into the one
    // SVG document, not after the first panel closed it.
    let dir = tempfile::tempdir().unwrap();
    let val = dir.path().join("val.csv");
    simulate(&val, "ja+mech+eddy", "chirp", "2000", "0.5");
    let plots = dir.path().join("plots");
    let o =
        gma(&["compare", "--model", "ja+mech", "--out-dir", plots.to_str().unwrap(), val.to_str().unwrap()]);
    assert!(o.status.success(), "{}", err(&o));
    for kind in ["loop", "time", "residual", "correlation", "spectrum", "bode"] {
        let svg = std::fs::read_to_string(plots.join(format!("val-{kind}.svg"))).unwrap();
        one_svg_document(&svg).unwrap_or_else(|e| panic!("val-{kind}.svg: {e}"));
    }
    // The later panels' labels lie inside the document.
    for (kind, labels) in [
        ("bode", &["gain [dB re 1 µm/A]", "phase [deg]", "coherence γ² [1]"][..]),
        ("correlation", &["residual autocorrelation", "current_A to residual cross-correlation"][..]),
    ] {
        let svg = std::fs::read_to_string(plots.join(format!("val-{kind}.svg"))).unwrap();
        let end = svg.rfind("</svg>").unwrap();
        for label in labels {
            let at = svg.find(label).unwrap_or_else(|| panic!("val-{kind}.svg lacks `{label}`"));
            assert!(at < end, "val-{kind}.svg: `{label}` after the closing `</svg>`");
        }
    }
}

#[test]
fn a_recording_too_short_for_the_spectra_is_compared_without_them() {
    let dir = tempfile::tempdir().unwrap();
    let short = dir.path().join("short.csv");
    simulate(&short, "ja+mech", "sine", "500", "0.01");
    let o = gma(&[
        "compare",
        "--model",
        "ja+mech",
        "--json",
        "--out-dir",
        dir.path().to_str().unwrap(),
        short.to_str().unwrap(),
    ]);
    let j = json(&o);
    assert!(j["files"][0].get("analysis").is_none(), "{j}");
    assert_eq!(j["files"][0]["plots"].as_array().unwrap().len(), 3);
    assert!(err(&o).contains("no residual or frequency analysis"), "{}", err(&o));
}

#[test]
fn bad_analysis_options_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.csv");
    simulate(&rec, "ja+mech", "sine", "100", "0.1");
    let r = rec.to_str().unwrap();
    let out = dir.path().join("o");
    let o = gma(&["compare", "--model", "ja", "--max-lag", "0", "--out-dir", out.to_str().unwrap(), r]);
    refused(&o, &["--max-lag 0"], "zero lags");
    let o = gma(&["compare", "--model", "ja", "--out-csv", r, "--out-dir", out.to_str().unwrap(), r]);
    refused(&o, &["is the input"], "--out-csv onto the input");
    assert!(std::fs::read_to_string(&rec).unwrap().starts_with("time_s"), "the input was replaced");
    assert!(!out.join("rec-loop.svg").exists(), "plots written before the refusal");
}

/// One recording given twice (or a copy of it) counts twice in the mean NRMSE: compared as
/// asked, and said, in the JSON's `warnings` and on stderr.
#[test]
fn a_recording_given_twice_is_said_to_count_twice_in_the_mean() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.csv");
    let other = dir.path().join("other.csv");
    simulate(&rec, "ja+mech", "sine", "100", "0.1");
    simulate(&other, "ja+mech", "sine", "200", "0.1");
    let copy = dir.path().join("copy.csv");
    std::fs::copy(&rec, &copy).unwrap();
    let out = dir.path().join("o");
    let (r, c, x) = (rec.to_str().unwrap(), copy.to_str().unwrap(), other.to_str().unwrap());
    for (files, twice) in [(vec![r, x, r], true), (vec![r, c], true), (vec![r, x], false)] {
        let mut args = vec!["compare", "--model", "ja+mech", "--json", "--out-dir", out.to_str().unwrap()];
        args.extend(&files);
        let o = gma(&args);
        let j = json(&o);
        let warnings: Vec<&str> =
            j["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap()).collect();
        let said = warnings.iter().any(|w| w.contains("same content") && w.contains("counts twice"));
        assert_eq!(said, twice, "{files:?}: {warnings:?}");
        assert_eq!(said, err(&o).contains("counts twice"), "{}", err(&o));
    }
}
