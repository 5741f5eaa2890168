//! No silent defaults, `--json` on every command, the report's provenance and uncertainty, and
//! progress through every phase of a report. Recordings are SIMULATED by `gma simulate` (the
//! plant); what is checked here is what the commands say about them, not the physics.

mod common;

use common::{err, gma, refused};

fn one_json(o: &std::process::Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(text.trim_end().lines().count(), 1, "stdout is not one line:\n{text}");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("not JSON: {e}\n{text}"))
}

/// A simulated `ja+eddy` recording.
fn recording(dir: &std::path::Path, name: &str, freq_hz: &str) -> String {
    let p = dir.join(name);
    let o = gma(&[
        "simulate",
        "--model",
        "ja+eddy",
        "--freq-hz",
        freq_hz,
        "--bias",
        "0",
        "--duration-s",
        "0.04",
        "--noise-um",
        "0.02",
        "--out",
        p.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    p.to_str().unwrap().to_string()
}

/// SHA-256 by the system's `sha256sum` (not the code under test).
fn sha256sum(path: &str) -> Option<String> {
    let o = std::process::Command::new("sha256sum").arg(path).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).split_whitespace().next().unwrap().to_string())
}

#[test]
fn the_demo_set_and_defaulted_stages_are_said_in_text_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let rec = recording(dir.path(), "r.csv", "100");
    let plots = dir.path().join("plots");
    let o = gma(&["compare", "--model", "ja", "--json", "--out-dir", plots.to_str().unwrap(), &rec]);
    assert!(
        err(&o).contains("gma: note: no parameter file given") && err(&o).contains("demo set"),
        "{}",
        err(&o)
    );
    let j = one_json(&o);
    assert_eq!(j["parameters_source"], "built-in demo set", "{j}");
    assert_eq!(j["parameters_defaulted"], serde_json::json!([]), "{j}");
    // A parameter file without the `[mech]` table, for a model that needs it.
    let full = host_sim::params::to_toml(&model_core::ActuatorParams::TERFENOL_DEMO, "test").unwrap();
    let start = full.find("[mech]").expect("a [mech] table");
    let end = full[start + 1..].find("\n[").map_or(full.len(), |k| start + 1 + k + 1);
    let p = dir.path().join("no-mech.toml");
    std::fs::write(&p, format!("{}{}", &full[..start], &full[end..])).unwrap();
    let o = gma(&[
        "compare",
        "--model",
        "ja+mech",
        "--params",
        p.to_str().unwrap(),
        "--json",
        "--out-dir",
        plots.to_str().unwrap(),
        &rec,
    ]);
    assert!(err(&o).contains("no-mech.toml has no `mech`"), "{}", err(&o));
    let j = one_json(&o);
    assert_eq!(j["parameters_source"], p.to_str().unwrap(), "{j}");
    assert_eq!(j["parameters_defaulted"], serde_json::json!(["mech"]), "{j}");
    // Fitting commands say where their start values came from, too.
    let fitted = dir.path().join("fitted.toml");
    let o = gma(&[
        "fit",
        "--model",
        "ja",
        "--json",
        "--effort",
        "0.2",
        "--params-out",
        fitted.to_str().unwrap(),
        &rec,
    ]);
    assert!(err(&o).contains("start values are the built-in"), "{}", err(&o));
    let j = one_json(&o);
    assert_eq!(j["parameters_source"], "built-in demo set");
    // The parameter file names what it was made from, as the JSON does.
    let digest = j["provenance"]["inputs"][0]["sha256"].as_str().unwrap();
    assert_eq!(digest.len(), 64);
    let header = std::fs::read_to_string(&fitted).unwrap();
    assert!(header.contains(&format!("# input {rec} sha256 {digest}")), "{header}");
}

#[test]
fn every_command_prints_one_json_object() {
    let dir = tempfile::tempdir().unwrap();
    let o = gma(&["mechanics", "--json", "--mass-kg", "0.2", "--stiffness-n-per-m", "8e6"]);
    assert!(o.status.success(), "{}", err(&o));
    let j = one_json(&o);
    let f_n = (8e6f64 / 0.2).sqrt() / (2.0 * std::f64::consts::PI);
    assert!((j["natural_frequency_hz"].as_f64().unwrap() - f_n).abs() < 1e-3 * f_n, "{j}");
    let step = j["step_response"].as_array().unwrap();
    assert_eq!(step.len(), 20);
    assert!(step[19]["displacement_um"].as_f64().unwrap() > 0.0, "{j}");
    // The text went to stderr.
    assert!(err(&o).contains("natural frequency"), "{}", err(&o));
    // Failures are the error object, on every command.
    let o = gma(&["mechanics", "--json", "--mass-kg", "-1"]);
    refused(&o, &["--mass-kg"], "negative mass");
    assert_eq!(one_json(&o)["error"]["exit_code"], 1);
    let file = dir.path().join("a-file");
    std::fs::write(&file, "not a folder").unwrap();
    let o = gma(&["demo", "--json", "--out-dir", file.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", err(&o));
    assert!(one_json(&o)["error"]["message"].as_str().is_some());
    let o =
        gma(&["simulate", "--json", "--freq-hz", "-3", "--out", dir.path().join("x.csv").to_str().unwrap()]);
    refused(&o, &["--freq-hz"], "negative frequency");
    assert_eq!(one_json(&o)["error"]["exit_code"], 1);
    let out = dir.path().join("s.csv");
    let o = gma(&["simulate", "--json", "--duration-s", "0.01", "--out", out.to_str().unwrap()]);
    let j = one_json(&o);
    assert_eq!(j["samples"], 100, "{j}");
    assert_eq!(j["simulated"], true, "{j}");
    assert_eq!(j["parameters_source"], "built-in demo set", "{j}");
}

#[test]
fn the_report_carries_provenance_uncertainty_and_shows_every_phase() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (recording(dir.path(), "a.csv", "40"), recording(dir.path(), "b.csv", "300"));
    let html = dir.path().join("r.html");
    let o = gma(&[
        "report",
        "--model",
        "ja",
        "--json",
        "--seed",
        "7",
        "--effort",
        "0.3",
        "-o",
        html.to_str().unwrap(),
        &a,
        &b,
    ]);
    let log = err(&o);
    assert!(o.status.success(), "{log}");
    let j = one_json(&o);
    let p = &j["provenance"];
    assert_eq!(p["gma_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(p["seed"], 7);
    let cmd: Vec<&str> = p["command_line"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert_eq!(&cmd[1..4], ["report", "--model", "ja"]);
    let date = p["date_utc"].as_str().unwrap();
    assert!(date.len() == 20 && date.ends_with('Z') && date.as_bytes()[10] == b'T', "{date}");
    let inputs = p["inputs"].as_array().unwrap();
    assert_eq!(inputs.len(), 2, "{p}");
    let page = std::fs::read_to_string(&html).unwrap();
    for (input, file) in inputs.iter().zip([&a, &b]) {
        assert_eq!(input["file"], file.as_str());
        assert_eq!(input["bytes"], std::fs::metadata(file).unwrap().len());
        if let Some(sum) = sha256sum(file) {
            assert_eq!(input["sha256"], sum.as_str());
        }
        assert!(page.contains(input["sha256"].as_str().unwrap()), "the page lacks {file}'s digest");
    }
    assert!(page.contains("Provenance") && page.contains("built-in demo set") && page.contains(date));
    // Uncertainty: in the page and per rung in the JSON, each interval around its value.
    assert!(
        page.contains("Parameter uncertainty")
            && page.contains("95 % interval")
            && page.contains("correlation matrix")
    );
    let rung = &j["ladder"][0];
    let u = rung["uncertainty"].as_object().unwrap_or_else(|| panic!("no uncertainty in {rung}"));
    assert!(!u.is_empty());
    for (name, e) in u {
        if let (Some(lo), Some(hi)) = (e["ci95"][0].as_f64(), e["ci95"][1].as_f64()) {
            let v = e["value"].as_f64().unwrap();
            assert!(lo <= v && v <= hi && e["std"].as_f64().unwrap() >= 0.0, "{name}: {e}");
        }
    }
    assert!(rung["correlation"]["matrix"].is_array(), "{rung}");
    // Off a terminal, every phase has its start and done lines.
    for line in [
        "gma: report: rung 1 of at most",
        "gma: diagnose: fitting the given model `ja`",
        "gma: fitting ja: done",
        "gma: diagnose: residual evidence and trends across files: started",
        "gma: diagnose: residual evidence and trends across files: done",
        "gma: diagnose: `ja` plus each candidate effect, searched afresh and refined from the fit of `ja`: done",
        "gma: diagnose: scoring the refits of `ja` plus each of",
        "candidate effects: done",
        "gma: report: parameter uncertainty of",
        "gma: report: drawing the page (each model on each file): started",
        "gma: report: drawing the page (each model on each file): done",
        // The text (on stderr with --json) has the uncertainty too.
        "parameters of `ja` (± std, 95 % interval):",
    ] {
        assert!(log.contains(line), "no `{line}` in the log:\n{log}");
    }
}
