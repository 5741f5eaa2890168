//! The `gma` binary as a user runs it: real files, exit codes and messages.

use std::process::Command;

fn gma(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_gma")).args(args).output().expect("run gma")
}

#[test]
fn simulate_writes_the_csv_contract() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim.csv");
    let o =
        gma(&["simulate", "--model", "ja+mech+amp", "--duration-s", "0.05", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("SIMULATED"));
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time_s,command_V,current_A,displacement_um"));
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|c| c.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 500);
    assert!(rows.iter().all(|r| r.len() == 4 && r.iter().all(|v| v.is_finite())));
    // Uniform 10 kHz time axis, and a displacement that actually moves (tens of µm).
    assert!(rows.windows(2).all(|w| ((w[1][0] - w[0][0]) - 1e-4).abs() < 1e-9));
    let (lo, hi) = rows.iter().fold((f64::MAX, f64::MIN), |(l, h), r| (l.min(r[3]), h.max(r[3])));
    assert!(hi - lo > 5.0, "stroke {} µm", hi - lo);
}

#[test]
fn a_typo_in_the_model_spec_is_named_with_a_suggestion() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim.csv");
    let o = gma(&["simulate", "--model", "ja+eddy_curent", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("unknown effect `eddy_curent`") && err.contains("did you mean `eddy_current`?"),
        "{err}"
    );
    assert!(!out.exists(), "no output file on error");
}

#[test]
fn a_bad_parameter_file_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let params = dir.path().join("p.toml");
    let mut p = model_core::ActuatorParams::TERFENOL_DEMO;
    p.ja.k_a_per_m = -3.0;
    std::fs::write(&params, toml::to_string(&p).unwrap()).unwrap();
    let out = dir.path().join("sim.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja",
        "--params",
        params.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("ja.k_a_per_m") && err.contains("> 0"), "{err}");
}
