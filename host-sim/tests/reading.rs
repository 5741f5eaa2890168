//! How a rig's recordings are read where a plain reading gives a plausible wrong answer, through
//! the `gma` binary: Unix-epoch time stamps, loop columns logged beside a recording, thousands
//! separators in a decimal-comma export, columns under names the reader does not take, and a
//! time axis in ms under `time_s`. Each file must give what its plain twin gives, or be refused
//! (or warned about) with the row, the column and the `--column` that reads it.

use std::path::{Path, PathBuf};
use std::process::Output;

mod common;
use common::{err, gma, refused};

fn json(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "gma failed:\n{}", err(o));
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("{e}: {text}"))
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `gma demo` in `dir`: its files.
fn demo(dir: &Path) -> PathBuf {
    let out = dir.join("demo");
    let o = gma(&["demo", "--out-dir", path(&out)]);
    assert!(o.status.success(), "{}", err(&o));
    out
}

/// The rows of a CSV (header first), split at commas.
fn rows(p: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(p).unwrap().lines().map(|l| l.split(',').map(str::to_string).collect()).collect()
}

/// `gma compare --json` of `files` with the model and parameter file, plots in `dir/out`.
fn compare(dir: &Path, model: &str, params: &Path, files: &[&Path], extra: &[&str]) -> Output {
    let out = dir.join("out");
    let mut args =
        vec!["compare", "--model", model, "--params", path(params), "--json", "--out-dir", path(&out)];
    args.extend(extra);
    args.extend(files.iter().map(|f| path(f)));
    gma(&args)
}

fn warnings(j: &serde_json::Value) -> Vec<String> {
    j["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect()
}

/// A decimal time text (`0.0001000`) in units of 1e-11 s.
fn units_1e11(t: &str) -> u128 {
    let (int, frac) = t.split_once('.').unwrap_or((t, ""));
    let frac = format!("{frac:0<11}");
    int.parse::<u128>().unwrap() * 100_000_000_000 + frac[..11].parse::<u128>().unwrap()
}

/// 1e-11 s units as a decimal text with `decimals` decimals (truncated).
fn text_1e11(u: u128, decimals: usize) -> String {
    let frac = format!("{:011}", u % 100_000_000_000);
    format!("{}.{}", u / 100_000_000_000, &frac[..decimals])
}

/// `src` with its time axis scaled by 1/`slower` (10: a 10 kHz file made a 100 kHz one) and
/// started at `origin` (1e-11 s units), written with `decimals` decimals.
fn retimed(src: &Path, out: &Path, slower: u128, origin: u128, decimals: usize) {
    let rows = rows(src);
    let mut text = rows[0].join(",") + "\n";
    for r in &rows[1..] {
        let t = origin + units_1e11(&r[0]) / slower;
        text += &format!("{},{}\n", text_1e11(t, decimals), r[1..].join(","));
    }
    std::fs::write(out, text).unwrap();
}

/// Unix-epoch seconds (2025-12-02) and a fraction, in 1e-11 s units.
const EPOCH: u128 = 176_463_360_000_012_340_000;

#[test]
fn epoch_time_stamps_give_the_period_and_result_of_stamps_from_zero() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-1-ja_mech.toml");
    for (slower, decimals) in [(1, 10), (10, 11)] {
        let (zero, epoch) = (dir.path().join("zero.csv"), dir.path().join("epoch.csv"));
        retimed(&d.join("demo-val1.csv"), &zero, slower, 0, decimals);
        retimed(&d.join("demo-val1.csv"), &epoch, slower, EPOCH, decimals);
        let a = json(&compare(dir.path(), "ja+mech", &params, &[&zero], &[]));
        let o = compare(dir.path(), "ja+mech", &params, &[&epoch], &[]);
        let b = json(&o);
        assert_eq!(a["nrmse"], b["nrmse"], "{slower}× faster: {}", err(&o));
        let said = "time stamps read as offsets from the first, 1764633600.0001234";
        assert!(warnings(&b).iter().any(|w| w.contains(said)), "{:?}", warnings(&b));
        assert!(err(&o).contains(&format!("gma: note: {}: {said}", path(&epoch))), "{}", err(&o));
    }
    // Stamps with fewer decimals than the step needs are refused at the row, and say why.
    let coarse = dir.path().join("coarse.csv");
    retimed(&d.join("demo-val1.csv"), &coarse, 10, EPOCH, 4);
    let o = compare(dir.path(), "ja+mech", &params, &[&coarse], &[]);
    refused(
        &o,
        &[&format!("{}:3:1", path(&coarse)), "does not increase", "too coarse", "more decimals"],
        "coarse",
    );
}

/// A clock far from zero but well within what a 64-bit float resolves (101 s and 1000 s at
/// 10 kHz: 1e6 and 1e7 steps) is read as written, and what `gma` writes keeps its stamps:
/// `simulate --drive`'s rows and `compare --out-csv`'s (issue 78: a clock at 101 s came back
/// from both from 0, one at 99 s with its stamps, and a note said the float could not resolve
/// the period).
#[test]
fn a_clock_far_from_zero_keeps_its_stamps_in_what_gma_writes() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-1-ja_mech.toml");
    for (origin_s, first) in [(101u128, "101.0000"), (1000, "1000.0000")] {
        let file = dir.path().join(format!("clock{origin_s}.csv"));
        retimed(&d.join("demo-val1.csv"), &file, 1, origin_s * 100_000_000_000, 6);
        let sim = dir.path().join(format!("sim{origin_s}.csv"));
        let o = gma(&[
            "simulate",
            "--model",
            "ja+mech",
            "--params",
            path(&params),
            "--drive",
            path(&file),
            "-o",
            path(&sim),
        ]);
        assert!(o.status.success(), "{}", err(&o));
        assert!(!err(&o).contains("offsets from the first"), "{}", err(&o));
        let written = rows(&sim);
        assert!(written[1][0].starts_with(first), "simulate --drive: first stamp {}", written[1][0]);
        let series = dir.path().join(format!("series{origin_s}.csv"));
        let o = compare(dir.path(), "ja+mech", &params, &[&file], &["--out-csv", path(&series)]);
        let j = json(&o);
        assert!(!warnings(&j).iter().any(|w| w.contains("offsets from the first")), "{:?}", warnings(&j));
        let written = rows(&series);
        let t: f64 = written[1][1].parse().unwrap();
        assert!((t - origin_s as f64).abs() < 1e-9, "compare --out-csv: first stamp {}", written[1][1]);
    }
}

/// `gma simulate` of a search-coil rig (`time_s,current_A,displacement_um,flux_density_T`), its
/// header and columns rewritten by `header` and `row` (cells in that order).
fn search_coil_rig(dir: &Path, d: &Path, name: &str, header: &str, row: fn(&[String]) -> String) -> PathBuf {
    let sc = dir.join("sc.csv");
    let params = d.join("params-2-eddy_ja_mech.toml");
    let o = gma(&[
        "simulate",
        "--model",
        "eddy+ja+mech",
        "--params",
        path(&params),
        "--search-coil",
        "--overwrite",
        "--freq-hz",
        "100",
        "--duration-s",
        "0.05",
        "--bias",
        "0.5",
        "-o",
        path(&sc),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let rows = rows(&sc);
    assert_eq!(rows[0].join(","), "time_s,current_A,displacement_um,flux_density_T");
    let mut text = format!("{header}\n");
    for r in &rows[1..] {
        text += &(row(r) + "\n");
    }
    let out = dir.join(name);
    std::fs::write(&out, text).unwrap();
    out
}

/// A rig's field column as it would log it: H = 20000 A/m + 13541.7 A/m per A.
fn with_field(r: &[String]) -> String {
    let i: f64 = r[1].parse().unwrap();
    format!("{},{},{:.6},{},{}", r[0], r[1], 20000.0 + 13541.7 * i, r[3], r[2])
}

#[test]
fn a_recording_that_logs_the_field_too_is_read_as_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-2-eddy_ja_mech.toml");
    // The displacement under a documented header form, beside the rig's field column.
    let header = "time_s,current_A,field_A_per_m,flux_density_T,Displacement (um)";
    let rig = search_coil_rig(dir.path(), &d, "rig.csv", header, with_field);
    let plain = search_coil_rig(
        dir.path(),
        &d,
        "plain.csv",
        "time_s,current_A,displacement_um,flux_density_T",
        |r| r.join(","),
    );
    let a = json(&compare(dir.path(), "eddy+ja+mech", &params, &[&plain], &[]));
    let o = compare(dir.path(), "eddy+ja+mech", &params, &[&rig], &[]);
    let b = json(&o);
    assert_eq!(a["nrmse"], b["nrmse"], "{}", err(&o));
    assert!(b["files"][0]["channel"] == a["files"][0]["channel"], "{b:#}");
    let unused = format!("{}: column not used: `field_A_per_m`", path(&rig));
    assert!(warnings(&b).iter().any(|w| w.starts_with(&unused)), "{:?}", warnings(&b));
    // diagnose takes it as the recording it is (no "works on displacement recordings").
    let o = gma(&[
        "diagnose",
        "--model",
        "ja",
        "--params",
        path(&params),
        "--time-limit",
        "1",
        "--json",
        path(&rig),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    // A displacement only a `--column` can name: either reading is possible, so it is refused
    // naming both, and the option that picks the recording reads it.
    let header = "time_s,current_A,field_A_per_m,flux_density_T,x_um";
    let two = search_coil_rig(dir.path(), &d, "two.csv", header, with_field);
    let o = compare(dir.path(), "eddy+ja+mech", &params, &[&two], &[]);
    refused(
        &o,
        &[
            &format!("{}:1:", path(&two)),
            "magnetization loop (`field_A_per_m`, `flux_density_T`)",
            "`x_um`",
            "--column displacement_um=x_um",
        ],
        "ambiguous",
    );
    let o = compare(dir.path(), "eddy+ja+mech", &params, &[&two], &["--column", "displacement_um=x_um"]);
    assert_eq!(json(&o)["nrmse"], a["nrmse"], "{}", err(&o));
    // A loop file with a time axis is still a loop file.
    let lp = dir.path().join("loop.csv");
    let mut text = String::from("time_s,field_A_per_m,magnetization_A_per_m\n");
    for k in 0..=40 {
        let h = -4e4 + 2e3 * k as f64;
        text += &format!("{},{h},{}\n", k as f64 * 1e-3, 7e5 * (h / 2e4).tanh());
    }
    std::fs::write(&lp, text).unwrap();
    let o = gma(&["diagnose", "--model", "ja", "--json", path(&lp)]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["error"]["file"], path(&lp), "{j:#}");
}

/// `src` as a German spreadsheet exports it: `;` between cells, decimal commas, and the
/// displacement in nm with `.` grouping thousands (`35.580` is 35 580 nm).
fn german(src: &Path, out: &Path) {
    let rows = rows(src);
    let mut text = String::from("time_s;current_A;Displacement (nm)\n");
    for r in &rows[1..] {
        let nm = (r[2].parse::<f64>().unwrap() * 1000.0).round() as i64;
        let grouped =
            if nm.abs() >= 1000 { format!("{}.{:03}", nm / 1000, (nm % 1000).abs()) } else { nm.to_string() };
        text += &format!("{};{};{grouped}\n", r[0].replace('.', ","), r[1].replace('.', ","));
    }
    std::fs::write(out, text).unwrap();
}

#[test]
fn a_point_in_a_decimal_comma_export_groups_thousands() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-1-ja_mech.toml");
    let de = dir.path().join("de.csv");
    german(&d.join("demo-val1.csv"), &de);
    // Its twin in nm without separators: the same numbers.
    let nm = dir.path().join("nm.csv");
    let text = std::fs::read_to_string(&de).unwrap();
    let mut twin = String::from("time_s,current_A,displacement_um\n");
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(';').collect();
        let x: f64 = c[2].replace('.', "").parse().unwrap();
        twin += &format!("{},{},{}\n", c[0].replace(',', "."), c[1].replace(',', "."), x / 1000.0);
    }
    std::fs::write(&nm, twin).unwrap();
    // Some displacement reaches a thousand nm: its cell groups the thousands with a point.
    let grouped = |cell: &str| cell.split_once('.').is_some_and(|(_, frac)| frac.len() == 3);
    assert!(text.lines().skip(1).any(|l| l.rsplit(';').next().is_some_and(grouped)), "{}", &text[..200]);
    let a = json(&compare(dir.path(), "ja+mech", &params, &[&nm], &[]));
    let b = json(&compare(dir.path(), "ja+mech", &params, &[&de], &[]));
    assert_eq!(a["nrmse"], b["nrmse"]);
    // A `.` that groups no thousands in such a file is refused at its cell, never read as a point.
    let bad = dir.path().join("bad.csv");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let at = lines.iter().skip(1).position(|l| l.rsplit(';').next().is_some_and(grouped)).unwrap() + 1;
    lines[at].pop(); // 35.580 → 35.58: a point that groups no thousands
    let cell = lines[at].rsplit(';').next().unwrap().to_string();
    std::fs::write(&bad, lines.join("\n") + "\n").unwrap();
    let o = compare(dir.path(), "ja+mech", &params, &[&bad], &[]);
    refused(
        &o,
        &[&format!("{}:{}:3", path(&bad), at + 1), &format!("`{cell}`"), "mixes decimal marks"],
        &cell,
    );
    // The mirror: a tab-separated export with decimal points and `,` grouping thousands.
    let en = dir.path().join("en.csv");
    let (head, body) = text.split_once('\n').unwrap();
    let en_body = body.replace(';', "\t").replace('.', "_").replace(',', ".").replace('_', ",");
    std::fs::write(&en, format!("{}\n{en_body}", head.replace(';', "\t"))).unwrap();
    assert_eq!(json(&compare(dir.path(), "ja+mech", &params, &[&en], &[]))["nrmse"], a["nrmse"]);
}

#[test]
fn columns_not_read_are_named_and_look_alikes_get_their_mapping() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-1-ja_mech.toml");
    let rows = rows(&d.join("demo-val1.csv"));
    let temps = dir.path().join("temps.csv");
    let mut text = format!("{},T_coil (°C),coil_temp_C,Temperature (kelvin)\n", rows[0].join(","));
    for (k, r) in rows[1..].iter().enumerate() {
        let t = 25.0 + k as f64 * 1e-3;
        text += &format!("{},{t},{t},{}\n", r.join(","), t + 273.15);
    }
    std::fs::write(&temps, text).unwrap();
    let o = compare(dir.path(), "ja+mech", &params, &[&temps], &[]);
    let w = warnings(&json(&o));
    let e = err(&o);
    let f = path(&temps);
    let unused = format!("{f}: columns not used: `T_coil (°C)`, `coil_temp_C`, `Temperature (kelvin)`");
    assert!(w.iter().any(|w| w.starts_with(&unused)), "{w:?}");
    assert!(e.contains(&format!("gma: note: {unused}")), "{e}");
    for (header, option) in [
        ("T_coil (°C)", "--column 'temperature_C=T_coil (°C)'"),
        ("coil_temp_C", "--column temperature_C=coil_temp_C"),
        ("Temperature (kelvin)", "--column 'temperature_C=Temperature (kelvin):K'"),
    ] {
        let said = format!("{f}: `{header}` looks like the coil temperature but is not read");
        let found = w.iter().find(|w| w.starts_with(&said)).unwrap_or_else(|| panic!("{said}: {w:?}"));
        assert!(found.contains(option) && found.contains("one of °C, C, K"), "{found}");
        assert!(e.contains(&format!("gma: warning: {said}")), "{e}");
    }
    // The proposed mapping reads it, and then it is neither unused nor a look-alike.
    let o = compare(dir.path(), "ja+mech", &params, &[&temps], &["--column", "temperature_C=coil_temp_C"]);
    let w = warnings(&json(&o));
    assert!(!w.iter().any(|w| w.contains("`coil_temp_C`,") || w.contains("`coil_temp_C` looks")), "{w:?}");
    assert!(w.iter().any(|w| w.contains("`T_coil (°C)` looks like the coil temperature but is not read (`temperature_C` is read from `coil_temp_C`)")), "{w:?}");
}

#[test]
fn a_time_axis_in_ms_is_warned_about_for_every_model() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-2-eddy_ja_mech.toml");
    let ms = dir.path().join("ms.csv");
    let rows = rows(&d.join("demo-val1.csv"));
    let mut text = rows[0].join(",") + "\n";
    for r in &rows[1..] {
        text += &format!("{:.4},{}\n", r[0].parse::<f64>().unwrap() * 1000.0, r[1..].join(","));
    }
    std::fs::write(&ms, text).unwrap();
    for model in ["eddy+ja", "ja+thermal", "ja+aftereffect", "ja"] {
        let o = compare(dir.path(), model, &params, &[&ms], &[]);
        let w = warnings(&json(&o));
        let said = format!("{}: the time axis is implausible for an actuator rig", path(&ms));
        let found = w.iter().find(|w| w.starts_with(&said)).unwrap_or_else(|| panic!("{model}: {w:?}"));
        assert!(found.contains("--column time_s=time_s:ms"), "{found}");
        assert!(err(&o).contains(&format!("gma: warning: {said}")), "{}", err(&o));
        // The fix it names reads the file as the rig logged it: no doubt left.
        let fixed = compare(dir.path(), model, &params, &[&ms], &["--column", "time_s=time_s:ms"]);
        assert!(!warnings(&json(&fixed)).iter().any(|w| w.contains("implausible")), "{model}");
    }
    // The demo's own files are not doubted.
    for f in ["demo-fit1.csv", "demo-fit2.csv", "demo-fit3.csv", "demo-val1.csv", "demo-val2.csv"] {
        let w = warnings(&json(&compare(dir.path(), "ja", &params, &[&d.join(f)], &[])));
        assert!(!w.iter().any(|w| w.contains("implausible")), "{f}: {w:?}");
    }
}

/// Issue 78 item 8: the opposite slip, a file in seconds read as milliseconds (`--column
/// time_s=time_s:ms`: 10 MHz sampling, a 50 kHz drive), scored with no word; it is said, with
/// the advice to drop the unit, and the file read as it is is not doubted.
#[test]
fn a_time_axis_in_seconds_read_as_ms_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let d = demo(dir.path());
    let params = d.join("params-2-eddy_ja_mech.toml");
    let file = d.join("demo-val1.csv");
    let o = compare(dir.path(), "ja", &params, &[&file], &["--column", "time_s=time_s:ms"]);
    let w = warnings(&json(&o));
    let said = format!("{}: the time axis is implausible for an actuator rig: a sample rate of", path(&file));
    let found = w.iter().find(|w| w.starts_with(&said)).unwrap_or_else(|| panic!("{w:?}"));
    assert!(found.contains("mapped with `:ms`") && found.contains("map it without a unit"), "{found}");
    assert!(!found.contains("is read with `--column time_s=HEADER:ms`"), "advice that damages data: {found}");
    let plain = compare(dir.path(), "ja", &params, &[&file], &[]);
    assert!(!warnings(&json(&plain)).iter().any(|w| w.contains("implausible")), "the file as logged");
}
