//! Columns as users have them: `--column CANONICAL=HEADER[:UNIT]`, `--resample linear` and
//! `--trim-start SECONDS` on fit, compare, diagnose and report, through the `gma` binary. A
//! file in other names and units must give exactly what its SI twin gives; jittered time stamps
//! are refused unless resampling is asked for; bad options are refused with the option named.

use std::path::{Path, PathBuf};
use std::process::Output;

mod common;
use common::{err, gma, refused};

/// The one JSON object on stdout of a successful run.
fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "gma failed:\n{}", err(o));
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("{e}: {text}"))
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `gma simulate --model ja --duration-s 0.1`: 1000 samples of `time_s,current_A,displacement_um`.
fn simulated(dir: &Path) -> PathBuf {
    let out = dir.join("sim.csv");
    let o = gma(&["simulate", "--model", "ja", "--duration-s", "0.1", "--out", path(&out)]);
    assert!(o.status.success(), "{}", err(&o));
    out
}

/// The rows of a CSV file (header first), split into cells.
fn rows(p: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

fn write_rows(p: &Path, rows: &[Vec<String>]) {
    let text: String = rows.iter().map(|r| r.join(",") + "\n").collect();
    std::fs::write(p, text).unwrap();
}

/// A decimal cell times 10^`pow10`, written as a plain decimal, exactly (digits moved, never
/// rounded): how a spreadsheet holding the same numbers in other units would write them.
fn shift_decimal(cell: &str, pow10: i32) -> String {
    let (mantissa, exp) = match cell.find(['e', 'E']) {
        Some(i) => (&cell[..i], cell[i + 1..].parse::<i32>().unwrap()),
        None => (cell, 0),
    };
    let (sign, mantissa) = match mantissa.strip_prefix('-') {
        Some(m) => ("-", m),
        None => ("", mantissa.trim_start_matches('+')),
    };
    let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    let digits = format!("{int}{frac}");
    // value = digits × 10^(exp + pow10 − frac.len()); `point` digits stand before the point.
    let point = digits.len() as i32 + exp + pow10 - frac.len() as i32;
    let plain = if point <= 0 {
        format!("0.{}{digits}", "0".repeat(-point as usize))
    } else if point as usize >= digits.len() {
        format!("{digits}{}", "0".repeat(point as usize - digits.len()))
    } else {
        format!("{}.{}", &digits[..point as usize], &digits[point as usize..])
    };
    format!("{sign}{plain}")
}

/// The simulated file with time in ms, current in mA and displacement in mm, columns renamed and
/// reordered: `displacement_mm,time_ms,current_mA`.
fn in_other_units(si: &Path, out: &Path) {
    let mut converted = vec![vec!["displacement_mm".into(), "time_ms".into(), "current_mA".into()]];
    let r = rows(si);
    assert_eq!(r[0], ["time_s", "current_A", "displacement_um"]);
    for row in &r[1..] {
        converted.push(vec![
            shift_decimal(&row[2], -3),
            shift_decimal(&row[0], 3),
            shift_decimal(&row[1], 3),
        ]);
    }
    write_rows(out, &converted);
}

const MAPPING: [&str; 6] = [
    "--column",
    "time_s=time_ms:ms",
    "--column",
    "displacement_um=displacement_mm:mm",
    "--column",
    "current_A=current_mA:mA",
];

fn args<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
    base.iter().chain(extra).copied().collect()
}

/// Every number of `a` within 1e-9 relative of `b` (same keys).
fn same_numbers(a: &serde_json::Value, b: &serde_json::Value, what: &str) {
    let (a, b) = (a.as_object().unwrap(), b.as_object().unwrap());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{what}");
    for (k, x) in a {
        let (x, y) = (x.as_f64().unwrap(), b[k].as_f64().unwrap());
        assert!((x - y).abs() <= 1e-9 * y.abs().max(1e-300), "{what}: `{k}` {x} vs {y}");
    }
}

#[test]
fn a_file_in_ms_ma_and_mm_fits_exactly_as_its_si_twin() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let (mm, mm_val, si_val) =
        (dir.path().join("mm.csv"), dir.path().join("mm-val.csv"), dir.path().join("si-val.csv"));
    in_other_units(&si, &mm);
    std::fs::copy(&mm, &mm_val).unwrap();
    std::fs::copy(&si, &si_val).unwrap();
    let text = std::fs::read_to_string(&mm).unwrap();
    assert!(text.starts_with("displacement_mm,time_ms,current_mA\n0.0"), "{}", &text[..80]);

    // Without the mapping the file is refused, and the message says how to map it.
    refused(
        &gma(&["fit", "--model", "ja", path(&mm)]),
        &["mm.csv:1:", "no `time_s` column", "--column"],
        "unmapped",
    );

    // fit (fit and validation file alike): the same parameters, NRMSE and offsets.
    let twin = json(&gma(&["fit", "--model", "ja", "--json", path(&si), "--val", path(&si_val)]));
    let mapped =
        json(&gma(&args(&["fit", "--model", "ja", "--json", path(&mm), "--val", path(&mm_val)], &MAPPING)));
    same_numbers(&mapped["params"], &twin["params"], "fit params");
    for key in ["nrmse_fit", "nrmse_val"] {
        assert_eq!(mapped[key], twin[key], "{key}");
    }
    for (m, t) in mapped["files"].as_array().unwrap().iter().zip(twin["files"].as_array().unwrap()) {
        assert_eq!((&m["nrmse"], &m["offset_um"], &m["split"]), (&t["nrmse"], &t["offset_um"], &t["split"]));
    }

    // compare, diagnose and report read the mapped file as the twin too.
    let out = |name: &str| dir.path().join(name);
    let (c1, c2) = (out("c1"), out("c2"));
    let a = json(&gma(&["compare", "--model", "ja", "--json", "--out-dir", path(&c1), path(&si)]));
    let b = json(&gma(&args(
        &["compare", "--model", "ja", "--json", "--out-dir", path(&c2), path(&mm)],
        &MAPPING,
    )));
    assert_eq!(a["nrmse"], b["nrmse"]);
    assert_eq!(a["files"][0]["offset_um"], b["files"][0]["offset_um"]);
    let a = json(&gma(&["diagnose", "--model", "linear", "--json", path(&si)]));
    let b = json(&gma(&args(&["diagnose", "--model", "linear", "--json", path(&mm)], &MAPPING)));
    assert_eq!((&a["nrmse_fit"], &a["verdict"]), (&b["nrmse_fit"], &b["verdict"]));
    assert_eq!(a["verdict"], "hysteresis");
    let (r1, r2) = (out("r1.html"), out("r2.html"));
    let a = json(&gma(&["report", "--model", "linear", "--json", "-o", path(&r1), path(&si)]));
    let b =
        json(&gma(&args(&["report", "--model", "linear", "--json", "-o", path(&r2), path(&mm)], &MAPPING)));
    assert_eq!(a["ladder"], b["ladder"]);
}

/// A displacement column in other units is refused with the file's columns listed and the
/// `--column` that reads it; following that hint reads the file as its SI twin.
#[test]
fn a_displacement_in_other_units_is_refused_with_the_column_option_that_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let mm = dir.path().join("mm.csv");
    let mut r = rows(&si);
    r[0][2] = "displacement_mm".into();
    for row in &mut r[1..] {
        row[2] = shift_decimal(&row[2], -3);
    }
    write_rows(&mm, &r);
    let cmp = dir.path().join("c");
    let base = ["compare", "--model", "ja", "--json", "--out-dir", path(&cmp)];
    let o = gma(&args(&base, &[path(&mm)]));
    let hint = "`--column displacement_um=displacement_mm:mm`";
    refused(
        &o,
        &["mm.csv:1: no `displacement_um` column", "header has: time_s, current_A, displacement_mm", hint],
        "mm",
    );
    let e: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(e["error"]["line"].as_u64(), Some(1), "{e}");
    let option = hint.trim_matches('`').split_once(' ').unwrap();
    let twin = json(&gma(&args(&base, &[path(&si)])));
    let read = json(&gma(&args(&base, &[option.0, option.1, path(&mm)])));
    assert_eq!(
        (&read["nrmse"], &read["files"][0]["offset_um"]),
        (&twin["nrmse"], &twin["files"][0]["offset_um"])
    );
}

#[test]
fn mapped_values_are_checked_after_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    // Displacements of 18–100 "m" are 1.8e7 µm and more: beyond the plausibility limit.
    let o = gma(&["fit", "--model", "ja", "--column", "displacement_um=displacement_um:m", path(&si)]);
    refused(
        &o,
        &["sim.csv:2:3:", "`displacement_um` (read as `displacement_um`, m → µm)", "not a plausible"],
        "m",
    );
    // A plain rename (no unit): the canonical unit.
    let renamed = dir.path().join("renamed.csv");
    let mut r = rows(&si);
    r[0] = vec!["t".into(), "I".into(), "x".into()];
    write_rows(&renamed, &r);
    let twin = json(&gma(&["fit", "--model", "ja", "--json", path(&si)]));
    let o = gma(&[
        "fit",
        "--model",
        "ja",
        "--json",
        "--column",
        "time_s=t",
        "--column",
        "current_A=I",
        "--column",
        "displacement_um=x",
        path(&renamed),
    ]);
    same_numbers(&json(&o)["params"], &twin["params"], "renamed");
}

/// The simulated file with every time stamp moved by up to ±2 % of the step (deterministic).
fn jittered(si: &Path, out: &Path) {
    let mut r = rows(si);
    for (k, row) in r.iter_mut().enumerate().skip(2) {
        let t: f64 = row[0].parse().unwrap();
        let u = ((k as f64 * 12.9898).sin() * 43758.5453).fract(); // in (−1, 1)
        row[0] = format!("{:.10}", t + 0.02 * 1e-4 * u);
    }
    write_rows(out, &r);
}

#[test]
fn two_percent_jitter_is_refused_unless_resampled_and_then_fits() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let jit = dir.path().join("jitter.csv");
    jittered(&si, &jit);

    let o = gma(&["fit", "--model", "ja", path(&jit)]);
    refused(&o, &["jitter.csv:", "median step", "by more than 1 %", "--resample linear"], "no --resample");

    let twin = json(&gma(&["fit", "--model", "ja", "--json", path(&si)]));
    let fit = json(&gma(&["fit", "--model", "ja", "--json", "--resample", "linear", path(&jit)]));
    let nrmse = fit["nrmse_fit"].as_f64().unwrap();
    assert!(nrmse < 0.005, "resampled fit NRMSE {nrmse}");
    for (k, v) in twin["params"].as_object().unwrap() {
        let (a, b) = (v.as_f64().unwrap(), fit["params"][k].as_f64().unwrap());
        assert!((a - b).abs() <= 0.02 * a.abs(), "`{k}`: {b} resampled vs {a}");
    }
    // compare, diagnose and report take it too; resampling a uniform file changes next to nothing.
    let c = json(&gma(&[
        "compare",
        "--model",
        "ja",
        "--json",
        "--resample",
        "linear",
        "--out-dir",
        path(&dir.path().join("c")),
        path(&jit),
        path(&si),
    ]));
    let (e_jit, e_si) = (c["files"][0]["nrmse"].as_f64().unwrap(), c["files"][1]["nrmse"].as_f64().unwrap());
    let plain = json(&gma(&[
        "compare",
        "--model",
        "ja",
        "--json",
        "--out-dir",
        path(&dir.path().join("d")),
        path(&si),
    ]));
    let e_plain = plain["nrmse"].as_f64().unwrap();
    // The jittered file within 5 % of the plain one's error, or 0.01 % of the range where the
    // model is the plant and that error next to 0 (its resampling's interpolation then shows).
    assert!(
        (e_si - e_plain).abs() < 1e-4 * e_plain && (e_jit - e_plain).abs() < 0.05 * e_plain + 1e-4,
        "{c}"
    );
    let d = json(&gma(&["diagnose", "--model", "linear", "--json", "--resample", "linear", path(&jit)]));
    assert_eq!(d["verdict"], "hysteresis");

    // A gap of 10 steps is not bridged, even with --resample.
    let gap = dir.path().join("gap.csv");
    let mut r = rows(&jit);
    r.drain(500..510);
    write_rows(&gap, &r);
    let o = gma(&["fit", "--model", "ja", "--resample", "linear", path(&gap)]);
    refused(&o, &["gap.csv:501:1:", "more than 5 median steps", "--resample does not bridge"], "gap");
}

/// Samples `--resample linear` fills in across a gap are said with their count; a file without
/// gaps gets no such note.
#[test]
fn samples_filled_in_across_gaps_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let gap = dir.path().join("gap.csv");
    let mut r = rows(&si);
    r.drain(101..104); // three samples missing (data rows 100–102)
    write_rows(&gap, &r);
    let note = |file: &Path| {
        let o = gma(&["compare", "--model", "ja", "--json", "--resample", "linear", path(file)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).lines().find(|l| l.contains("filled in")).map(str::to_string)
    };
    let said = note(&gap).expect("a note for the gap");
    assert!(said.contains("gap.csv") && said.contains(": 3 were filled in"), "{said}");
    assert_eq!(note(&si), None);
}

#[test]
fn trim_start_drops_the_start_as_cutting_the_rows_would() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let cut = dir.path().join("cut.csv");
    let r = rows(&si);
    let kept: Vec<Vec<String>> = r[..1]
        .iter()
        .chain(r[1..].iter().filter(|row| row[0].parse::<f64>().unwrap() >= 0.03))
        .cloned()
        .collect();
    assert_eq!(kept.len(), 1 + 700);
    write_rows(&cut, &kept);

    let compare = |extra: &[&str], file: &Path, out: &str| {
        let out = dir.path().join(out);
        let base = ["compare", "--model", "ja", "--json", "--out-dir", path(&out), path(file)];
        json(&gma(&args(&base, extra)))
    };
    let trimmed = compare(&["--trim-start", "0.03"], &si, "a");
    let by_hand = compare(&[], &cut, "b");
    let whole = compare(&[], &si, "c");
    assert_eq!(trimmed["nrmse"], by_hand["nrmse"]);
    assert_eq!(trimmed["files"][0]["offset_um"], by_hand["files"][0]["offset_um"]);
    assert_ne!(trimmed["nrmse"], whole["nrmse"]);
    // --trim-start 0 keeps everything.
    assert_eq!(compare(&["--trim-start", "0"], &si, "d")["nrmse"], whole["nrmse"]);

    // fit trims its fit and validation files alike; --max-samples counts after the trim.
    let fit = |extra: &[&str], fit: &Path, val: &Path| {
        json(&gma(&args(&["fit", "--model", "ja", "--json", path(fit), "--val", path(val)], extra)))
    };
    let a = fit(&["--trim-start", "0.03"], &si, &si);
    let b = fit(&[], &cut, &cut);
    same_numbers(&a["params"], &b["params"], "trimmed fit");
    assert_eq!((&a["nrmse_fit"], &a["nrmse_val"]), (&b["nrmse_fit"], &b["nrmse_val"]));
    let o = gma(&["fit", "--model", "ja", "--trim-start", "0.03", "--max-samples", "600", path(&si)]);
    assert!(o.status.success(), "{}", err(&o));
    assert!(err(&o).contains("700 samples after --trim-start; using the first 600"), "{}", err(&o));
}

#[test]
fn a_trim_past_the_end_is_refused_with_the_number_as_typed() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    for (typed, shown) in [("1e308", "1.000000e308 s leaves 0"), ("5", "--trim-start 5 s leaves 0")] {
        let o = gma(&["compare", "--model", "ja", "--trim-start", typed, path(&si)]);
        assert_eq!(o.status.code(), Some(1), "{}", err(&o));
        let e = err(&o);
        assert!(e.contains(shown) && e.lines().all(|l| l.len() < 400), "{e}");
    }
}

#[test]
fn bad_options_are_refused_with_the_option_named_on_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let mm = dir.path().join("mm.csv");
    in_other_units(&si, &mm);
    let report = dir.path().join("r.html");
    let cmp = dir.path().join("cmp");
    let cases: Vec<(Vec<&str>, &Path, Vec<&str>)> = vec![
        (
            vec!["--column", "time=t:ms"],
            &si,
            vec!["--column `time=t:ms`", "unknown column `time`", "time_s, command_V"],
        ),
        (
            vec!["--column", "time_s=time_ms:h"],
            &mm,
            vec!["--column `time_s=time_ms:h`", "unknown unit `h`", "s, ms, us"],
        ),
        (
            vec!["--column", "current_A=current_mA:mm"],
            &mm,
            vec!["unknown unit `mm` for `current_A`", "A, mA"],
        ),
        (
            vec!["--column", "displacement_um"],
            &si,
            vec!["--column `displacement_um`", "CANONICAL=HEADER[:UNIT]"],
        ),
        (
            vec!["--column", "time_s=a:ms", "--column", "time_s=b"],
            &si,
            vec!["--column `time_s=b`", "already mapped"],
        ),
        (
            vec!["--column", "time_s=time_ms:ms", "--column", "displacement_um=x_um:mm"],
            &mm,
            vec![
                "mm.csv:1:",
                "--column `displacement_um=x_um:mm`",
                "no column `x_um`",
                "header has: displacement_mm, time_ms, current_mA",
            ],
        ),
        (
            // A header that names its unit is not read as µm unsaid (it was: NRMSE 27 000 %).
            vec!["--column", "time_s=time_ms:ms", "--column", "displacement_um=displacement_mm"],
            &mm,
            vec![
                "--column `displacement_um=displacement_mm`",
                "the header `displacement_mm` names mm, but no unit is given",
                "`displacement_um=displacement_mm:mm` converts it",
            ],
        ),
        (vec!["--resample", "cubic"], &si, vec!["--resample `cubic`", "`linear`"]),
        (vec!["--trim-start", "-0.01"], &si, vec!["--trim-start", "≥ 0"]),
        (
            vec!["--trim-start", "0.0999"],
            &si,
            vec!["sim.csv:", "--trim-start 0.0999 s leaves 1 of the file's 1000 samples", "at least 3"],
        ),
    ];
    for (opts, file, fragments) in &cases {
        for command in [
            vec!["fit", "--model", "ja"],
            vec!["compare", "--model", "ja", "--out-dir", path(&cmp)],
            vec!["diagnose", "--model", "ja"],
            vec!["report", "--model", "ja", "-o", path(&report)],
        ] {
            let a: Vec<&str> = command.iter().chain(opts).copied().chain([path(file)]).collect();
            refused(&gma(&a), fragments, &format!("{a:?}"));
        }
    }
    assert!(!report.exists());

    // With --json the error object points into the file.
    let o = gma(&["fit", "--model", "ja", "--json", "--column", "time_s=t:ms", path(&mm)]);
    let e: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((e["error"]["line"].as_u64(), e["error"]["exit_code"].as_u64()), (Some(1), Some(1)), "{e}");
    assert!(e["error"]["file"].as_str().unwrap().ends_with("mm.csv"), "{e}");

    // The options are for recordings; a magnetization-loop file refuses them.
    let lp = dir.path().join("loop.csv");
    let mut text = String::from("H(A/m),B(T)\n");
    for k in 0..50 {
        let h = 2e4 * (k as f64 * 0.2).cos();
        text.push_str(&format!("{h},{}\n", (h / 5e3).tanh()));
    }
    std::fs::write(&lp, text).unwrap();
    let o = gma(&["fit", "--model", "ja", "--trim-start", "0.1", path(&lp)]);
    refused(&o, &["--trim-start", "magnetization-loop files"], "loop file");
}

#[test]
fn without_the_options_files_read_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let si = simulated(dir.path());
    let jit = dir.path().join("jitter.csv");
    jittered(&si, &jit);
    refused(&gma(&["fit", "--model", "ja", path(&jit)]), &["jitter.csv:", "median step"], "jitter");
    let a = json(&gma(&["fit", "--model", "ja", "--json", path(&si)]));
    let b = json(&gma(&["fit", "--model", "ja", "--json", "--trim-start", "0", path(&si)]));
    assert_eq!(a["params"], b["params"]);
}
