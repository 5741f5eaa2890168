//! `gma simulate --drive FILE`: a parameter set run on a measured drive, on the file's own time
//! base. The drive files here are written by hand (a sine of our choosing) or by the plant
//! simulator, whose integrator (2× oversampled, its own drive generator) is not the model the
//! `--drive` path runs.

mod common;

use common::{err, gma, refused};

/// Reads a CSV written by gma: header and columns.
fn read_csv(path: &std::path::Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let mut cols = vec![Vec::new(); header.len()];
    for l in lines {
        for (c, v) in cols.iter_mut().zip(l.split(',')) {
            c.push(v.parse::<f64>().unwrap());
        }
    }
    (header, cols)
}

fn col<'a>(csv: &'a (Vec<String>, Vec<Vec<f64>>), name: &str) -> &'a [f64] {
    let k = csv.0.iter().position(|h| h == name).unwrap_or_else(|| panic!("no `{name}` in {:?}", csv.0));
    &csv.1[k]
}

/// A drive-only recording: `n` samples at `dt_s` of a 1 A sine at `freq_hz` around 1 A, in the
/// columns `header` names (time in the first, current in the second; `scale` converts A and s
/// into the file's units).
fn drive_file(path: &std::path::Path, header: &str, n: usize, dt_s: f64, freq_hz: f64, scale: (f64, f64)) {
    let mut s = format!("{header}\n");
    for k in 0..n {
        let t = k as f64 * dt_s;
        let i = 1.0 + (2.0 * std::f64::consts::PI * freq_hz * t).sin();
        s.push_str(&format!("{:.7},{:.6}\n", t * scale.0, i * scale.1));
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn the_measured_current_drives_the_model_on_the_files_time_base() {
    let dir = tempfile::tempdir().unwrap();
    // 5 kHz: not the parameter set's 10 kHz, so the time base must come from the file.
    let drive = dir.path().join("drive.csv");
    drive_file(&drive, "time_s,current_A", 400, 2e-4, 50.0, (1.0, 1.0));
    let out = dir.path().join("sim.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja",
        "--drive",
        drive.to_str().unwrap(),
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(j["drive_column"], "current_A", "{j}");
    assert_eq!(j["samples"], 400, "{j}");
    assert_eq!(j["parameters_source"], "built-in demo set", "{j}");
    assert!(err(&o).contains("SIMULATED") && err(&o).contains("demo set"), "{}", err(&o));
    let (input, output) = (read_csv(&drive), read_csv(&out));
    assert_eq!(col(&output, "time_s"), col(&input, "time_s"));
    assert_eq!(col(&output, "current_A"), col(&input, "current_A"));
    let y = col(&output, "displacement_um");
    assert!(y.iter().all(|v| v.is_finite()));
    // The rod stretches with the current: the displacement follows the drive's cycles (2.5
    // periods here), largest where the current is.
    let (i_max, y_max) = (col(&input, "current_A"), y);
    let k_i = (0..400).max_by(|&a, &b| i_max[a].total_cmp(&i_max[b])).unwrap();
    let span = y_max.iter().fold(f64::MIN, |a, &b| a.max(b)) - y_max.iter().fold(f64::MAX, |a, &b| a.min(b));
    assert!(span > 1.0, "displacement span {span} µm");
    assert!(y_max[k_i] > y_max.iter().sum::<f64>() / 400.0, "the displacement does not follow the current");
}

#[test]
fn a_drive_run_reproduces_the_plant_on_the_plants_own_drive() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("rig.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja+mech",
        "--freq-hz",
        "80",
        "--duration-s",
        "0.05",
        "--out",
        rig.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let out = dir.path().join("again.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja+mech",
        "--drive",
        rig.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let (plant, model) = (read_csv(&rig), read_csv(&out));
    let (yp, ym) = (col(&plant, "displacement_um"), col(&model, "displacement_um"));
    assert_eq!(yp.len(), ym.len());
    let range = yp.iter().fold(f64::MIN, |a, &b| a.max(b)) - yp.iter().fold(f64::MAX, |a, &b| a.min(b));
    let rms = (yp.iter().zip(ym).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / yp.len() as f64).sqrt();
    // Two integrators of the same physics (the plant at 2× the rate with its own drive, the
    // model on the sampled drive): within 1 % of the range.
    assert!(rms / range < 0.01, "NRMSE {:.3} %", 100.0 * rms / range);
}

/// compare estimates each file's initial magnetic state; given that state, `simulate --drive`
/// runs the model compare scored: the same NRMSE (offset removed as compare removes it), where
/// the default demagnetised start differs.
#[test]
fn the_initial_state_compare_estimated_gives_the_run_compare_scored() {
    let dir = tempfile::tempdir().unwrap();
    // A rig that does not start where the model boots: a biased sine that starts at its top.
    let rig = dir.path().join("rig.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja",
        "--freq-hz",
        "30",
        "--duration-s",
        "0.1",
        "--bias",
        "1.5",
        "--amplitude",
        "1.2",
        "--noise-um",
        "0.05",
        "--out",
        rig.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let mut params = model_core::ActuatorParams::TERFENOL_DEMO;
    params.ja.k_a_per_m *= 1.5; // not the rig's set: the fit of the state matters
    let p = dir.path().join("p.toml");
    std::fs::write(&p, toml::to_string(&params).unwrap()).unwrap();
    let plots = dir.path().join("plots");
    let o = gma(&[
        "compare",
        "--model",
        "ja",
        "--params",
        p.to_str().unwrap(),
        "--json",
        "--out-dir",
        plots.to_str().unwrap(),
        rig.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (compared, excursion) = (
        j["files"][0]["nrmse"].as_f64().unwrap(),
        j["files"][0]["initial_excursion_a_per_m"].as_f64().unwrap(),
    );
    let nrmse_of = |extra: &[&str]| -> f64 {
        let out = dir.path().join("run.csv");
        let mut args = vec![
            "simulate",
            "--model",
            "ja",
            "--params",
            p.to_str().unwrap(),
            "--drive",
            rig.to_str().unwrap(),
        ];
        args.extend(extra);
        args.extend(["--overwrite", "--out", out.to_str().unwrap()]);
        let o = gma(&args);
        assert!(o.status.success(), "{}", err(&o));
        let (measured, model) = (read_csv(&rig), read_csv(&out));
        let (y, m) = (col(&measured, "displacement_um"), col(&model, "displacement_um"));
        let offset = y.iter().zip(m).map(|(a, b)| a - b).sum::<f64>() / y.len() as f64;
        let rms =
            (y.iter().zip(m).map(|(a, b)| (a - b - offset).powi(2)).sum::<f64>() / y.len() as f64).sqrt();
        rms / (y.iter().fold(f64::MIN, |a, &b| a.max(b)) - y.iter().fold(f64::MAX, |a, &b| a.min(b)))
    };
    let x = excursion.to_string();
    let given = nrmse_of(&["--initial-excursion", &x]);
    // The CSV rounds the model to f32: the same run to that precision.
    assert!((given - compared).abs() <= 1e-4 * compared, "simulate {given} against compare {compared}");
    let demagnetised = nrmse_of(&[]);
    assert!(
        (demagnetised - compared).abs() > 1e-3 * compared,
        "the state made no difference: {demagnetised}"
    );
    refused(
        &gma(&[
            "simulate",
            "--model",
            "ja",
            "--drive",
            rig.to_str().unwrap(),
            "--initial-excursion",
            "nan",
            "--out",
            "x.csv",
        ]),
        &["--initial-excursion"],
        "a NaN state",
    );
    // A headerless loop file given as the drive is said to be one, not only `no time_s column`.
    let headerless = dir.path().join("loop.csv");
    std::fs::write(&headerless, "-40000,-0.95\n0,0.3\n40000,0.95\n0,-0.3\n-40000,-0.95\n").unwrap();
    refused(
        &gma(&["simulate", "--model", "ja", "--drive", headerless.to_str().unwrap(), "--out", "x.csv"]),
        &["loop.csv:1: no `time_s` column", "as in a magnetization-loop file without a header"],
        "a headerless loop file as the drive",
    );
}

#[test]
fn mapped_columns_and_the_command_drive() {
    let dir = tempfile::tempdir().unwrap();
    let drive = dir.path().join("ms.csv");
    // Time in ms, current in mA.
    drive_file(&drive, "t_ms,I_mA", 300, 1e-4, 100.0, (1e3, 1e3));
    let out = dir.path().join("o.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja",
        "--drive",
        drive.to_str().unwrap(),
        "--column",
        "time_s=t_ms:ms",
        "--column",
        "current_A=I_mA:mA",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let i = read_csv(&out);
    assert!((col(&i, "time_s")[299] - 0.0299).abs() < 1e-9);
    assert!((col(&i, "current_A").iter().fold(f64::MIN, |a, &b| a.max(b)) - 2.0).abs() < 1e-3);
    // A command-only file drives `amp+ja` through the amplifier; the model's current is written.
    let cmd = dir.path().join("cmd.csv");
    drive_file(&cmd, "time_s,command_V", 300, 1e-4, 100.0, (1.0, 0.5));
    let o = gma(&[
        "simulate",
        "--model",
        "amp+ja",
        "--drive",
        cmd.to_str().unwrap(),
        "--json",
        "--overwrite",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["drive_column"], "command_V", "{j}");
    let c = read_csv(&out);
    assert!(col(&c, "current_A").iter().any(|v| v.abs() > 0.1), "the amplifier drove no current");
}

#[test]
fn a_drive_the_model_cannot_use_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.csv");
    let only_current = dir.path().join("i.csv");
    drive_file(&only_current, "time_s,current_A", 50, 1e-4, 100.0, (1.0, 1.0));
    let o = gma(&[
        "simulate",
        "--model",
        "amp+ja",
        "--drive",
        only_current.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["i.csv", "command_V"], "amp model on a current-only file");
    let no_drive = dir.path().join("y.csv");
    std::fs::write(&no_drive, "time_s,displacement_um\n0,1\n0.0001,2\n0.0002,3\n").unwrap();
    let o = gma(&["simulate", "--drive", no_drive.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    refused(&o, &["y.csv", "current_A", "command_V"], "no drive column");
    // The waveform options make no sense with a measured drive: a usage error.
    let o = gma(&[
        "simulate",
        "--drive",
        only_current.to_str().unwrap(),
        "--freq-hz",
        "10",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", err(&o));
    // Reading options without --drive are refused, not ignored.
    let o = gma(&["simulate", "--trim-start", "0.1", "--out", out.to_str().unwrap()]);
    refused(&o, &["--drive"], "--trim-start without --drive");
    assert!(!out.exists(), "a refused run wrote its output");
}
