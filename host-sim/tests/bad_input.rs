//! Bad input, command by command: every case is a real file (or argument) given to the `gma`
//! binary, and must end in a non-zero exit with a message naming the file and line (and column
//! or parameter) — never a panic, never a silently dropped row, never an output file.

use std::path::{Path, PathBuf};

mod common;
use common::{err as stderr, gma, refused};

/// A 50 Hz, 40 ms sine recording (two cycles) as rows of `time_s,current_A,displacement_um`.
fn good_rows() -> Vec<String> {
    (0..400)
        .map(|k| {
            let t = k as f64 * 1e-4;
            let i = 1.0 + (2.0 * std::f64::consts::PI * 50.0 * t).sin();
            format!("{t:.4},{i:.6},{:.6}", 10.0 * i * i)
        })
        .collect()
}

fn csv(header: &str, rows: &[String]) -> Vec<u8> {
    let mut s = format!("{header}\n");
    for r in rows {
        s.push_str(r);
        s.push('\n');
    }
    s.into_bytes()
}

/// Replaces row `k` (0-based data row; the file line is k + 2).
fn with_row(k: usize, row: &str) -> Vec<String> {
    let mut rows = good_rows();
    rows[k] = row.to_string();
    rows
}

const HEADER: &str = "time_s,current_A,displacement_um";

/// Every malformed measurement file, with the fragments its message must contain.
fn bad_csvs() -> Vec<(&'static str, Vec<u8>, Vec<&'static str>)> {
    let mut junk = vec![0xFF, 0xFE, 0x00, 0x81];
    junk.extend((0..2000u32).map(|k| (k.wrapping_mul(2_654_435_761) >> 24) as u8));
    vec![
        ("empty.csv", Vec::new(), vec!["empty.csv:1:", "empty file"]),
        ("blank_line.csv", b"   \n".to_vec(), vec!["blank_line.csv: ", "only blank lines"]),
        ("blank_lines.csv", b"\n\n".to_vec(), vec!["blank_lines.csv:", "only blank lines"]),
        (
            "blank_then_commas.csv",
            b"\n,,\n0,0.1,1.0\n".to_vec(),
            vec!["blank_then_commas.csv:2:", "names no columns"],
        ),
        // Not empty: its rows are there, its header names nothing.
        (
            "commas_header.csv",
            b",,\n0,0.1,1.0\n".to_vec(),
            vec!["commas_header.csv:1:", "the header line names no columns"],
        ),
        ("header_only.csv", csv(HEADER, &[]), vec!["header_only.csv:", "0 data rows"]),
        ("one_sample.csv", csv(HEADER, &good_rows()[..1]), vec!["one_sample.csv:", "1 data row;"]),
        ("junk.csv", junk, vec!["junk.csv:1:", "not UTF-8"]),
        (
            "no_time.csv",
            csv("t,current_A,displacement_um", &good_rows()),
            vec!["no_time.csv:1:", "no `time_s` column"],
        ),
        (
            "no_drive.csv",
            csv("time_s,voltage,displacement_um", &good_rows()),
            vec!["no_drive.csv:1:", "drive column"],
        ),
        (
            "no_displacement.csv",
            csv("time_s,current_A,x_um", &good_rows()),
            vec![
                "no_displacement.csv:1: no `displacement_um` column (header has: time_s, current_A, x_um)",
                "if `x_um` is the displacement, read it with `--column displacement_um=x_um:um`",
            ],
        ),
        (
            // A header with a space and brackets: the `--column` shown is quoted for the shell.
            "spaced_displacement.csv",
            csv("time_s,current_A,x [mm]", &good_rows()),
            vec!["if `x [mm]` is the displacement, read it with `--column 'displacement_um=x [mm]:mm'`"],
        ),
        (
            "other_displacement.csv",
            csv("time_s,current_A,y", &good_rows()),
            vec![
                "other_displacement.csv:1: no `displacement_um` column (header has: time_s, current_A, y)",
                "`--column displacement_um=HEADER:UNIT` (UNIT: um, µm, m, mm, nm)",
            ],
        ),
        (
            "duplicate.csv",
            csv("time_s,current_A,current_A", &good_rows()),
            vec!["duplicate.csv:1:", "`current_A` appears twice", "columns 2 and 3"],
        ),
        ("short_row.csv", csv(HEADER, &with_row(5, "0.0005,1.0")), vec!["short_row.csv:7:", "2 fields"]),
        (
            "long_row.csv",
            csv(HEADER, &with_row(5, "0.0005,1.0,2.0,3.0")),
            vec!["long_row.csv:7:", "4 fields"],
        ),
        (
            "nan.csv",
            csv(HEADER, &with_row(9, "0.0009,NaN,1.0")),
            vec!["nan.csv:11:2:", "`NaN` is not a finite number"],
        ),
        (
            "inf.csv",
            csv(HEADER, &with_row(9, "0.0009,1.0,-inf")),
            vec!["inf.csv:11:3:", "`-inf` is not a finite number"],
        ),
        (
            "text.csv",
            csv(HEADER, &with_row(9, "0.0009,1.0,abc")),
            vec!["text.csv:11:3:", "`abc` is not a number"],
        ),
        (
            "blank_cell.csv",
            csv(HEADER, &with_row(9, "0.0009,,1.0")),
            vec!["blank_cell.csv:11:2:", "is empty"],
        ),
        (
            "backwards.csv",
            csv(HEADER, &with_row(20, "0.0010,1.0,1.0")),
            vec!["backwards.csv:22:1:", "time_s does not increase"],
        ),
        (
            "jitter.csv",
            csv(HEADER, &with_row(20, "0.00205,1.0,1.0")),
            vec!["jitter.csv:22:1:", "median step"],
        ),
        (
            "absurd_current.csv",
            csv(HEADER, &with_row(30, "0.0030,2.5e7,1.0")),
            vec!["absurd_current.csv:32:2:", "beyond ±1e3 A"],
        ),
        (
            "absurd_displacement.csv",
            csv(HEADER, &with_row(30, "0.0030,1.0,4e9")),
            vec!["absurd_displacement.csv:32:3:", "beyond ±1e6 µm"],
        ),
        (
            "constant_drive.csv",
            csv(
                HEADER,
                &(0..400).map(|k| format!("{:.4},1.0,{}", k as f64 * 1e-4, k % 7)).collect::<Vec<_>>(),
            ),
            vec!["constant_drive.csv", "the drive column `current_A` never changes"],
        ),
        (
            "zero_displacement.csv",
            csv(
                HEADER,
                &good_rows()
                    .iter()
                    .map(|r| format!("{},0.0", r.rsplit_once(',').unwrap().0))
                    .collect::<Vec<_>>(),
            ),
            vec!["zero_displacement.csv", "displacement never changes"],
        ),
    ]
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p.to_str().unwrap().to_string()
}

/// The four commands that read recordings, each with its outputs inside `dir`.
fn reading_commands(dir: &Path) -> Vec<Vec<String>> {
    let d = |n: &str| dir.join(n).to_str().unwrap().to_string();
    vec![
        vec!["fit".into(), "--model".into(), "ja".into(), "--params-out".into(), d("out.toml")],
        vec!["compare".into(), "--model".into(), "ja".into(), "--out-dir".into(), d("plots")],
        vec!["diagnose".into(), "--model".into(), "ja".into()],
        vec!["report".into(), "--model".into(), "ja".into(), "--out".into(), d("out.html")],
    ]
}

fn no_outputs(dir: &Path, what: &str) {
    for n in ["out.toml", "out.html"] {
        assert!(!dir.join(n).exists(), "{what}: wrote {n} although it failed");
    }
    let plots = dir.join("plots");
    let count = std::fs::read_dir(&plots).map(|d| d.count()).unwrap_or(0);
    assert_eq!(count, 0, "{what}: wrote plots although it failed");
}

#[test]
fn every_malformed_recording_is_refused_by_every_command_with_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    for (name, bytes, expected) in bad_csvs() {
        let bad = write(dir.path(), name, &bytes);
        for cmd in reading_commands(dir.path()) {
            let what = format!("{} on {name}", cmd[0]);
            // As the only file, and after a good one (the bad one must still be named).
            for files in [vec![bad.clone()], vec![good.clone(), bad.clone()]] {
                let mut args: Vec<&str> = cmd.iter().map(String::as_str).collect();
                args.extend(files.iter().map(String::as_str));
                refused(&gma(&args), &expected, &what);
                no_outputs(dir.path(), &what);
            }
        }
        // As a validation file too.
        let o = gma(&["fit", "--model", "ja", &good, "--val", &bad]);
        refused(&o, &expected, &format!("fit --val {name}"));
    }
}

#[test]
fn less_than_one_period_is_refused_by_diagnose_instead_of_guessed() {
    let dir = tempfile::tempdir().unwrap();
    // 6 ms of a 50 Hz sine: not even one reversal.
    let short = write(dir.path(), "short.csv", &csv(HEADER, &good_rows()[..60]));
    let o = gma(&["diagnose", "--model", "ja", &short]);
    refused(&o, &["short.csv", "less than one cycle", "0 reversals"], "diagnose on 6 ms");
    // As a validation file: scored after its first cycle, it would have had none to burn in.
    let long = write(dir.path(), "long.csv", &csv(HEADER, &good_rows()));
    let o = gma(&["diagnose", "--model", "ja", &long, "--val", &short]);
    refused(&o, &["short.csv", "less than one cycle"], "diagnose --val on 6 ms");
    let o = gma(&["report", "--model", "ja", "--out", dir.path().join("r.html").to_str().unwrap(), &short]);
    refused(&o, &["short.csv", "less than one cycle"], "report on 6 ms");
    assert!(!dir.path().join("r.html").exists());
}

#[test]
fn model_spec_typos_are_named_with_the_nearest_effect_by_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let out = dir.path().join("x").to_str().unwrap().to_string();
    for (spec, word, hint) in [
        ("ja+mehc", "mehc", "`mech`"),
        ("hysterisis", "hysterisis", "`hysteresis`"),
        ("ja+eddy_curent", "eddy_curent", "`eddy_current`"),
        ("saturation+termal", "termal", "`thermal`"),
        // Another separator: the nearest single word (`mech`) would drop `ja`.
        ("ja,mech", "ja,mech", "`ja+mech`"),
        ("eddy ja", "eddy ja", "`eddy+ja`"),
        ("ja + mech, eddy", "mech, eddy", "`ja+mech+eddy`"),
    ] {
        let msg = [format!("unknown effect `{word}`"), format!("did you mean {hint}?")];
        let exp: Vec<&str> = msg.iter().map(String::as_str).collect();
        for args in [
            vec!["fit", "--model", spec, &good],
            vec!["compare", "--model", spec, "--out-dir", &out, &good],
            vec!["diagnose", "--model", spec, &good],
            vec!["report", "--model", spec, "--out", &out, &good],
            vec!["simulate", "--model", spec, "--out", &out],
            vec!["drive", "load", "--params", "p.toml", "--model", spec, "--out", &out],
        ] {
            refused(&gma(&args), &exp, &format!("{} --model {spec}", args[0]));
        }
    }
    // An effect named twice is read once (the documented rule), with a warning naming both
    // words: most often it is a typo for another effect.
    for (spec, words) in [
        ("ja+mech+mech", "(`mech` at byte 3, `mech` at byte 8)"),
        ("ja+anhysteretic", "(`ja` at byte 0, `anhysteretic` at byte 3)"),
    ] {
        let o = gma(&["simulate", "--model", spec, "--out", &out]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{spec}: {err}");
        assert!(
            err.contains("warning") && err.contains("named twice") && err.contains(words),
            "{spec}: {err}"
        );
        std::fs::remove_file(&out).unwrap();
    }
    let o = gma(&["simulate", "--model", "hysteresis+saturation", "--out", &out]);
    assert!(
        o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("twice"),
        "implied is not named"
    );
    std::fs::remove_file(&out).unwrap();
    for (spec, expected) in [("", "empty"), ("ja+preisach", "preisach"), ("ja++mech", "mech")] {
        refused(&gma(&["simulate", "--model", spec, "--out", &out]), &[expected], spec);
    }
    assert!(!Path::new(&out).exists());
}

/// A valid parameter file (the demo set) with one line replaced.
fn params_with(dir: &Path, name: &str, edit: impl Fn(&str) -> String) -> String {
    let text = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    write(dir, name, edit(&text).as_bytes())
}

/// [`replace_line`] within `[table]`.
fn replace_in_table(text: &str, table: &str, key: &str, new: &str) -> String {
    let header = format!("[{table}]");
    let start = text.find(&header).unwrap_or_else(|| panic!("no {header}"));
    format!("{}{}", &text[..start], replace_line(&text[start..], key, new))
}

fn replace_line(text: &str, key: &str, new: &str) -> String {
    let mut seen = false;
    let out: Vec<String> = text
        .lines()
        .filter_map(|l| {
            if !seen && l.starts_with(&format!("{key} =")) {
                seen = true;
                (!new.is_empty()).then(|| new.to_string())
            } else {
                Some(l.to_string())
            }
        })
        .collect();
    assert!(seen, "no `{key}` line");
    out.join("\n")
}

#[test]
fn bad_parameter_files_name_the_file_line_and_parameter_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    // A value out of range is pointed at by its line (the edits keep every line's number).
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let at = |file: &str, key: &str| {
        let line = demo.lines().position(|l| l.starts_with(&format!("{key} ="))).unwrap() + 1;
        format!("{file}:{line}: ")
    };
    let (negative_at, ppm_at, nan_at) =
        (at("negative.toml", "k_a_per_m"), at("ppm.toml", "lambda_s"), at("nan.toml", "alpha"));
    let huge_at = at("huge.toml", "k_a_per_m");
    let strain_ms_line = {
        let table = demo.lines().position(|l| l == "[magnetostriction]").unwrap();
        table + demo.lines().skip(table).position(|l| l.starts_with("ms_a_per_m =")).unwrap() + 1
    };
    let two_ms_at = format!("two_ms.toml:{strain_ms_line}: ");
    let cases: Vec<(String, Vec<&str>)> = vec![
        (
            // One rod, one M_s: the strain's half the law's (issue 78: the strain reached 3.3× its
            // saturation, a fit answered λ_s a quarter of the truth).
            params_with(dir.path(), "two_ms.toml", |t| {
                replace_in_table(t, "magnetostriction", "ms_a_per_m", "ms_a_per_m = 300000.0")
            }),
            vec![
                &two_ms_at,
                "`magnetostriction.ms_a_per_m` is out of range",
                "the magnetization law's own M_s",
                "found `300000.0`",
            ],
        ),
        (
            params_with(dir.path(), "missing.toml", |t| replace_line(t, "k_a_per_m", "")),
            vec!["missing.toml:", "parameter `ja.k_a_per_m` is missing"],
        ),
        (
            params_with(dir.path(), "negative.toml", |t| replace_line(t, "k_a_per_m", "k_a_per_m = -4000.0")),
            vec![&negative_at, "`ja.k_a_per_m` is out of range", "[1, 1e7]", "found `-4000.0`"],
        ),
        (
            params_with(dir.path(), "ppm.toml", |t| replace_line(t, "lambda_s", "lambda_s = 1000.0")),
            vec![&ppm_at, "`magnetostriction.lambda_s` is out of range", "not ppm", "found `1000.0`"],
        ),
        (
            params_with(dir.path(), "nan.toml", |t| replace_line(t, "alpha", "alpha = nan")),
            vec![&nan_at, "`ja.alpha` is not a finite number", "found `nan`"],
        ),
        (
            // Finite, but not in f32: said so, not "not a finite number".
            params_with(dir.path(), "huge.toml", |t| replace_line(t, "k_a_per_m", "k_a_per_m = 1e40")),
            vec![&huge_at, "`ja.k_a_per_m` = 1e40 is beyond the range of f32"],
        ),
        (
            params_with(dir.path(), "text.toml", |t| replace_line(t, "c", "c = \"0.2\"")),
            vec!["text.toml:", "parameter `ja.c`", "invalid type"],
        ),
        (
            params_with(dir.path(), "unknown.toml", |t| replace_line(t, "c", "c = 0.2\nk_a_perm = 3.0")),
            vec!["unknown.toml:", "unknown field `k_a_perm`"],
        ),
        (
            // A top-level key at the end of the file lands in the last table: said where it goes.
            params_with(dir.path(), "late_key.toml", |t| {
                format!("{}\neddy_tau_s = 1e-4\n", replace_line(t, "eddy_tau_s", ""))
            }),
            vec![
                "late_key.toml:",
                "unknown field `eddy_tau_s`",
                "is a top-level key: move it above the first `[table]` line",
            ],
        ),
        (params_with(dir.path(), "syntax.toml", |t| format!("{t}\n[ja\n")), vec!["syntax.toml:"]),
        (
            write(dir.path(), "binary.toml", &[0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10]),
            vec!["binary.toml:1:", "not UTF-8"],
        ),
        (write(dir.path(), "empty.toml", b""), vec!["empty.toml:", "is missing"]),
    ];
    let out = dir.path().join("x").to_str().unwrap().to_string();
    for (p, expected) in &cases {
        for args in [
            vec!["fit", "--model", "ja", "--params", p, &good],
            vec!["compare", "--model", "ja", "--params", p, "--out-dir", &out, &good],
            vec!["diagnose", "--model", "ja", "--params", p, &good],
            vec!["report", "--model", "ja", "--params", p, "--out", &out, &good],
            vec!["simulate", "--model", "ja", "--params", p, "--out", &out],
        ] {
            refused(&gma(&args), expected, &format!("{} --params {p}", args[0]));
        }
    }
    // The board's loader too: the frames it would send are never written.
    let frames = dir.path().join("frames.bin");
    let two_ms = &cases[0];
    refused(
        &gma(&["drive", "load", "--params", &two_ms.0, "--model", "ja", "--out", frames.to_str().unwrap()]),
        &two_ms.1,
        "drive load --params two_ms.toml",
    );
    assert!(!frames.exists(), "drive load wrote frames of a self-contradicting set");
    let missing = dir.path().join("nope.toml");
    refused(
        &gma(&["simulate", "--params", missing.to_str().unwrap(), "--out", &out]),
        &["nope.toml: cannot read"],
        "missing file",
    );
    assert!(!Path::new(&out).exists());
}

/// Every parameter file gma writes starts with a comment and `format_version`: an error after
/// them keeps its line, column, quoted text and parameter, in the message and in `--json`'s
/// fields (LF or CRLF line endings alike).
#[test]
fn errors_after_the_format_version_line_point_at_the_right_place_and_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.csv").to_str().unwrap().to_string();
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let written = format!("# written by gma fit\nformat_version = 2\n{demo}");
    let alpha = replace_line(&written, "alpha", "alpha = \"0.1\"");
    let alpha_line = alpha.lines().position(|l| l.starts_with("alpha")).unwrap() + 1;
    let cases = [
        (
            "typo.toml",
            "format_version = 2\n[mech]\nnatural_frequency_hz = 1200\ndamping_ratoi = 0.3\n".to_string(),
            "ja+mech",
            (4, 1),
            "unknown field `damping_ratoi`".to_string(),
            "(at `damping_ratoi`)".to_string(),
        ),
        (
            "alpha.toml",
            alpha,
            "ja",
            (alpha_line, 9),
            "parameter `ja.alpha`: invalid type: string \"0.1\"".to_string(),
            "(found `\"0.1\"`)".to_string(),
        ),
    ];
    for (name, text, model, (line, col), what, quoted) in cases {
        for (eol, text) in [("LF", text.clone()), ("CRLF", text.replace('\n', "\r\n"))] {
            let p = write(dir.path(), name, text.as_bytes());
            let o = gma(&["simulate", "--model", model, "--params", &p, "--out", &out, "--json"]);
            let place = format!("{name}:{line}:{col}: ");
            refused(&o, &[&place, &what, &quoted], &format!("{name} ({eol})"));
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let e = &j["error"];
            assert_eq!((e["line"].as_u64(), e["column"].as_u64()), (Some(line as u64), Some(col)), "{e}");
        }
    }
    assert!(!Path::new(&out).exists());
}

/// NaN and ±inf are refused everywhere (docs/formats.md), also in a table the model does not
/// use: read as given, such a value went on into `fit --params-out`, to break the next command
/// that uses the stage. A number beyond f32's range (1e39) is as infinite as `inf`, and said so.
#[test]
fn a_non_finite_value_in_a_table_the_model_does_not_use_is_refused_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let line_of = |key: &str| demo.lines().position(|l| l.starts_with(&format!("{key} ="))).unwrap() + 1;
    let out = dir.path().join("out.toml").to_str().unwrap().to_string();
    let sim = dir.path().join("x.csv").to_str().unwrap().to_string();
    for (name, key, value, param) in [
        ("nan_mech.toml", "natural_frequency_hz", "nan", "mech.natural_frequency_hz"),
        ("inf_damping.toml", "damping_ratio", "-inf", "mech.damping_ratio"),
        ("huge_eddy.toml", "eddy_tau_s", "1e39", "eddy_tau_s"),
    ] {
        let p = params_with(dir.path(), name, |t| replace_line(t, key, &format!("{key} = {value}")));
        let place = format!("{name}:{}: ", line_of(key));
        let what = match value {
            "1e39" => format!("parameter `{param}` = 1e39 is beyond the range of f32"),
            _ => format!("parameter `{param}` is not a finite number"),
        };
        for args in [
            vec!["fit", "--model", "ja", "--params", &p, "--params-out", &out, &good],
            vec![
                "compare",
                "--model",
                "ja",
                "--params",
                &p,
                "--out-dir",
                dir.path().to_str().unwrap(),
                &good,
            ],
            vec!["simulate", "--model", "ja", "--params", &p, "--out", &sim],
        ] {
            refused(&gma(&args), &[&place, &what], &format!("{} --params {name}", args[0]));
        }
        assert!(!Path::new(&out).exists() && !Path::new(&sim).exists(), "{name}: wrote an output");
    }
}

/// A recording too short to estimate the uncertainty (5 samples for `linear`'s 3 parameters and
/// an offset: one more than the unknowns, too few for a covariance) is fitted, but the doubt goes
/// where `--json` readers look: its `warnings`, not only stderr.
#[test]
fn a_fit_without_an_uncertainty_says_so_in_its_json_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let short = write(dir.path(), "short.csv", &csv(HEADER, &good_rows()[..5]));
    let o = gma(&["fit", "--model", "linear", "--json", &short]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j.get("uncertainty").is_none(), "{j}");
    let said = j["warnings"].as_array().unwrap().iter().any(|w| {
        let w = w.as_str().unwrap();
        w.starts_with("no parameter uncertainty") && w.contains("5 residuals for 3 parameters")
    });
    assert!(said, "{:#}", j["warnings"]);
}

/// Through no more samples than unknowns any model passes: 3 samples for `ja`'s 4 free
/// parameters, λ_s, the file's initial magnetic state and its offset were fitted to 0.18 % NRMSE
/// and the values printed as identified, exit 0. Refused, with the count and the way out; so is a loop of 5 points for
/// the 5 parameters of a J–A loop.
#[test]
fn a_fit_through_no_more_samples_than_unknowns_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let short = write(dir.path(), "short.csv", &csv(HEADER, &good_rows()[..3]));
    let what =
        "for 7 unknowns of `ja` (4 free parameters, λ_s, an initial magnetic state and an offset per file)";
    let o = gma(&["fit", "--model", "ja", &short]);
    refused(&o, &["3 samples in all (", "short.csv: 3)", what, "record more samples"], "3-sample fit");
    // Cut by --max-samples, the way out names it.
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let o = gma(&["fit", "--model", "ja", "--max-samples", "5", &good]);
    refused(&o, &["5 samples in all (", "good.csv: 5)", "raise --max-samples"], "--max-samples 5");
    let points = "H_A_per_m,M_A_per_m\n0,0\n1000,10000\n2000,30000\n1000,25000\n0,10000\n";
    let tiny = write(dir.path(), "tiny-loop.csv", points.as_bytes());
    refused(
        &gma(&["fit", "--model", "ja", &tiny]),
        &[
            "5 loop points in all (",
            "tiny-loop.csv: 5) for the 5 parameters of the law",
            "give the whole loop",
        ],
        "5-point loop",
    );
}

/// With every parameter of a hysteretic law held by `--fix`, only each file's initial magnetic
/// state (and λ_s) is left to search, dimensions the swarm holds: the swarm got none and the fit
/// panicked in argmin (exit 101). Now the local searches run from the held values.
#[test]
fn fixing_every_law_parameter_leaves_the_initial_state_to_the_local_search() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let law = ["--fix", "ja.a_a_per_m", "--fix", "ja.alpha", "--fix", "ja.k_a_per_m", "--fix", "ja.c"];
    for lambda in [&[][..], &["--fix", "magnetostriction.lambda_s"][..]] {
        let o = gma(&[&["fit", "--model", "ja", "--json"][..], &law, lambda, &[&good]].concat());
        assert!(o.status.success(), "{:?}: {}", lambda, stderr(&o));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert!(j["nrmse_fit"].as_f64().is_some_and(f64::is_finite), "{j}");
    }
}

/// A `--fix` value or `--bound` range inside its registry range can still make the set invalid
/// with the parameter file's other values (a Preisach coercive field beyond the plane's
/// extent): refused naming the option, not as a bare parameter error the user cannot place.
#[test]
fn a_fix_or_bound_that_invalidates_the_start_set_is_refused_naming_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let p = params_with(dir.path(), "narrow-plane.toml", |t| {
        replace_line(t, "h_max_a_per_m", "h_max_a_per_m = 20000.0")
    });
    for (opt, arg) in
        [("--fix", "preisach.coercive_a_per_m=25000"), ("--bound", "preisach.coercive_a_per_m=21000:29000")]
    {
        let o = gma(&["fit", "--model", "preisach", "--params", &p, opt, arg, &good]);
        refused(
            &o,
            &[&format!("{opt} preisach.coercive_a_per_m"), "must be below preisach.h_max_a_per_m"],
            &format!("{opt} {arg}"),
        );
    }
}

/// A channel the model is scored on (or driven by) that never changes is refused, naming the
/// file and the column: the drive the model actually takes (`command_V` with an amplifier model,
/// though `current_A` varies), and a constant measured current, flux density or temperature,
/// whose NRMSE's span is 0 (it was floored at 1e-12: a 1e10 NRMSE that swamped the fit's cost).
#[test]
fn a_constant_channel_the_model_uses_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let with = |column: &str, value: &dyn Fn(usize, &str) -> String| -> Vec<u8> {
        let rows: Vec<String> =
            good_rows().iter().enumerate().map(|(k, r)| format!("{r},{}", value(k, r))).collect();
        csv(&format!("{HEADER},{column}"), &rows)
    };
    let dead_current: Vec<String> = good_rows()
        .iter()
        .map(|r| {
            let f: Vec<&str> = r.split(',').collect();
            format!("{},0.0,{},{}", f[0], f[2], f[1])
        })
        .collect();
    let cases: [(&str, Vec<u8>, &str, &str); 4] = [
        ("flat_command.csv", with("command_V", &|_, _| "0.5".into()), "amp+ja", "`command_V` never changes"),
        (
            "dead_current.csv",
            csv("time_s,current_A,displacement_um,command_V", &dead_current),
            "amp+ja",
            "`current_A` never changes",
        ),
        (
            "flat_flux.csv",
            with("flux_density_T", &|_, _| "0.5".into()),
            "ja",
            "`flux_density_T` never changes",
        ),
        (
            "flat_temperature.csv",
            with("temperature_C", &|_, _| "23.0".into()),
            "ja+thermal",
            "`temperature_C` never changes",
        ),
    ];
    let out = dir.path().join("plots").to_str().unwrap().to_string();
    for (name, bytes, model, what) in cases {
        let file = write(dir.path(), name, &bytes);
        for args in [
            vec!["fit", "--model", model, &file],
            vec!["compare", "--model", model, "--out-dir", &out, &file],
        ] {
            refused(&gma(&args), &[name, what], &format!("{} --model {model} {name}", args[0]));
        }
        // The whole file's fault: `--json` names it as the error's `file` (it was null).
        let o = gma(&["fit", "--model", model, "--json", &file]);
        let e: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(
            (&e["error"]["file"], &e["error"]["line"]),
            (&file.as_str().into(), &serde_json::Value::Null),
            "{e}"
        );
    }
}

/// A fit file given twice (or a copy) weighs twice in the fit: said in the warnings, as `compare`
/// says it of its mean; the same for a validation file given twice.
#[test]
fn a_fit_file_given_twice_is_said_to_count_twice() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let copy = write(dir.path(), "copy.csv", &csv(HEADER, &good_rows()));
    let o = gma(&["fit", "--model", "ja", "--time-limit", "5", "--json", &good, &copy]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let warned = |what: &str| {
        j["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|w| w.as_str())
            .any(|w| w.contains(&format!("{copy} has the same content as {good}")) && w.contains(what))
    };
    assert!(warned("counts twice in the fit's cost"), "{:#}", j["warnings"]);
    assert!(stderr(&o).contains("counts twice in the fit's cost"), "{}", stderr(&o));
}

/// A candidate whose refit cannot run (coil heating on a file whose temperature never changes:
/// the refit refuses that channel) is said in a finding, not dropped without a word.
#[test]
fn diagnose_says_which_candidate_refits_could_not_run() {
    let dir = tempfile::tempdir().unwrap();
    let rows: Vec<String> = good_rows().iter().map(|r| format!("{r},23.0")).collect();
    let file = write(dir.path(), "flat_temperature.csv", &csv(&format!("{HEADER},temperature_C"), &rows));
    let o = gma(&["diagnose", "--model", "ja", "--time-limit", "20", "--json", &file]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let said = j["findings"].as_array().unwrap().iter().filter_map(|f| f.as_str()).any(|f| {
        f.starts_with("refits that could not be run")
            && f.contains("`thermal_drift`")
            && f.contains("`temperature_C` never changes")
    });
    assert!(said, "{:#}", j["findings"]);
}

/// `amp.gain_a_per_v` is the ideal amplifier's gain whenever a file gives the command but not the
/// current, with or without `amplifier_dynamics` (docs/formats.md: (0, 1e3]); a model without
/// that effect did not check it, and ran a command-only file through a gain of 0 or −2. The
/// refusal names the file, in `--json` too.
#[test]
fn an_ideal_amplifier_gain_out_of_range_is_refused_for_a_command_only_file() {
    let dir = tempfile::tempdir().unwrap();
    let command_only =
        write(dir.path(), "command.csv", &csv("time_s,command_V,displacement_um", &good_rows()));
    let sim = dir.path().join("x.csv").to_str().unwrap().to_string();
    for gain in ["0.0", "-2.0"] {
        let name = format!("gain{gain}.toml");
        let p = params_with(dir.path(), &name, |t| {
            replace_line(t, "gain_a_per_v", &format!("gain_a_per_v = {gain}"))
        });
        for args in [
            vec![
                "compare",
                "--model",
                "ja",
                "--params",
                &p,
                "--out-dir",
                dir.path().to_str().unwrap(),
                &command_only,
            ],
            vec!["simulate", "--model", "ja", "--params", &p, "--drive", &command_only, "--out", &sim],
        ] {
            refused(
                &gma(&args),
                &["command.csv", "`amp.gain_a_per_v`", "(0, 1e3]"],
                &format!("{} with gain {gain}", args[0]),
            );
        }
        assert!(!Path::new(&sim).exists());
        // `--json` names the file the gain would drive as the error's `file` (it was null).
        let o = gma(&["compare", "--model", "ja", "--params", &p, "--json", &command_only]);
        let e: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(e["error"]["file"], command_only.as_str(), "gain {gain}: {e}");
    }
}

/// A `format_version` that is not an integer is a typing mistake, not a file from a newer gma:
/// said so, with its line.
#[test]
fn a_format_version_that_is_not_an_integer_is_named_as_such_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let out = dir.path().join("x.csv").to_str().unwrap().to_string();
    for (name, value, what) in [
        ("text.toml", "\"2\"", "it is not an integer"),
        ("float.toml", "2.0", "it is not an integer"),
        ("newer.toml", "99", "a newer gma wrote it?"),
    ] {
        let p = write(dir.path(), name, format!("# a comment\nformat_version = {value}\n{demo}").as_bytes());
        let o = gma(&["simulate", "--model", "ja", "--params", &p, "--out", &out]);
        refused(&o, &[&format!("{name}:2: format_version = {value}"), what], name);
        if what == "it is not an integer" {
            assert!(!stderr(&o).contains("newer gma"), "{name}: {}", stderr(&o));
        }
    }
}

/// The loop checks hold for the points kept: a loop whose first points are flat, cut there by
/// `--max-samples`, is refused like a flat file (it was fitted to a 5e15 NRMSE and exit 0).
#[test]
fn a_loop_cut_by_max_samples_to_flat_points_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let rows: String = (0..20)
        .map(|k| if k < 6 { format!("{},1000\n", k * 100) } else { format!("{},{}\n", k * 1000, k * 20000) })
        .collect();
    let f = write(dir.path(), "flat-start.csv", format!("H(A/m),M(A/m)\n{rows}").as_bytes());
    let out = dir.path().join("out.toml").to_str().unwrap().to_string();
    let o = gma(&["fit", "--model", "anhysteretic", "--max-samples", "5", "--params-out", &out, &f]);
    refused(&o, &["flat-start.csv", "M does not vary", "--max-samples"], "a flat head");
    assert!(!Path::new(&out).exists());
    // The whole file fits.
    assert!(gma(&["fit", "--model", "anhysteretic", "--effort", "0.2", &f]).status.success());
}

#[test]
fn out_of_range_arguments_are_refused_with_the_option_named() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let out = dir.path().join("x.csv").to_str().unwrap().to_string();
    for (args, expected) in [
        (vec!["simulate", "--duration-s", "0", "--out", &out], "--duration-s"),
        (vec!["simulate", "--freq-hz", "nan", "--out", &out], "--freq-hz"),
        (vec!["simulate", "--noise-um", "-1", "--out", &out], "--noise-um"),
        (vec!["simulate", "--amplitude", "1e9", "--out", &out], "--amplitude"),
        (vec!["mechanics", "--sample-rate-hz", "0"], "--sample-rate-hz"),
        (vec!["mechanics", "--mass-kg", "inf"], "--mass-kg"),
        (vec!["fit", "--model", "ja", "--effort", "0", &good], "--effort"),
        (vec!["fit", "--model", "ja", "--max-samples", "2", &good], "--max-samples"),
        (vec!["record", "--input", &good, "--out", &out, "--tick-s", "-1"], "--tick-s"),
    ] {
        refused(&gma(&args), &[expected], &args.join(" "));
    }
    assert!(!Path::new(&out).exists());
    // A number beyond f32's range is refused as typed, not as the inf it would round to.
    let o = gma(&["mechanics", "--mass-kg", "1e39"]);
    assert!(!o.status.success());
    for said in ["--mass-kg", "1e39 is beyond single precision"] {
        assert!(stderr(&o).contains(said), "{}", stderr(&o));
    }
    // Outputs that cannot be written are refused before any work.
    let nodir = dir.path().join("no/such/dir/p.toml").to_str().unwrap().to_string();
    let a_file = good.clone();
    for args in [
        vec!["fit", "--model", "ja", "--params-out", &nodir, &good],
        vec!["report", "--model", "ja", "--out", &nodir, &good],
        vec!["simulate", "--out", &nodir],
        vec!["record", "--input", &good, "--out", &nodir],
        vec!["compare", "--model", "ja", "--out-dir", &a_file, &good],
        vec!["demo", "--out-dir", &a_file],
    ] {
        refused(&gma(&args), &["cannot"], &args.join(" "));
    }
    // Missing files are named.
    let nope = dir.path().join("nope.csv").to_str().unwrap().to_string();
    for args in [vec!["fit", "--model", "ja", &nope], vec!["record", "--input", &nope, "--out", &out]] {
        refused(&gma(&args), &["nope.csv: cannot read"], &args.join(" "));
    }
}

/// Limits that come from the parameter set's sample period are said in the numbers the file
/// states (dt_s = 1e-4 s, Nyquist 5000 Hz), not in the digits of its f32 image
/// (9.999999747378752e-5 s, 5000.000126310628 Hz).
#[test]
fn simulate_says_its_sample_period_limits_in_the_stated_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.csv").to_str().unwrap().to_string();
    for (args, expected) in [
        (
            vec!["simulate", "--freq-hz", "6000", "--out", &out],
            "above the Nyquist frequency 5000 Hz of the sample period dt_s = 1e-4 s",
        ),
        (vec!["simulate", "--duration-s", "1e-4", "--out", &out], "gives 1 sample at dt_s = 1e-4 s"),
        (
            vec!["simulate", "--duration-s", "3000", "--out", &out],
            "at dt_s = 1e-4 s; at most 2e7 (2000 s) per run",
        ),
    ] {
        let o = gma(&args);
        refused(&o, &[expected], &args.join(" "));
        assert!(!stderr(&o).contains("99999"), "{}", stderr(&o));
    }
    assert!(!Path::new(&out).exists());
}

/// `demo` checks its outputs before the simulation and the fits, as every command does: a
/// folder or a link where a file goes is refused at once, by name, and nothing is written.
#[test]
fn demo_refuses_an_output_it_cannot_write_before_any_work() {
    for (name, make) in [
        ("report.html", (|p: &Path| std::fs::create_dir(p).unwrap()) as fn(&Path)),
        ("demo-val2.csv", |p: &Path| std::fs::create_dir(p).unwrap()),
        ("demo-fit1.csv", |p: &Path| {
            let target = p.with_file_name("elsewhere.csv");
            std::fs::write(&target, "kept\n").unwrap();
            std::os::unix::fs::symlink(&target, p).unwrap();
        }),
    ] {
        let dir = tempfile::tempdir().unwrap();
        make(&dir.path().join(name));
        let t = std::time::Instant::now();
        let o = gma(&["demo", "--out-dir", dir.path().to_str().unwrap()]);
        let e = stderr(&o);
        refused(
            &o,
            &[&format!("cannot write {}", dir.path().join(name).display())],
            &format!("demo, {name}"),
        );
        // Said once, plainly (not the temporary file's error twice).
        assert!(!e.contains("persist") && e.matches("os error").count() <= 1, "{e}");
        assert!(t.elapsed().as_secs_f64() < 5.0, "refused only after the work: {:?}", t.elapsed());
        let written: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|d| d.unwrap().file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with("demo-") || n.starts_with("params-") || n.starts_with(".gma-"))
            .filter(|n| n != name)
            .collect();
        assert!(written.is_empty(), "demo, {name}: wrote {written:?} although it failed");
        assert_eq!(
            std::fs::read_to_string(dir.path().join("elsewhere.csv")).ok().as_deref().unwrap_or("kept\n"),
            "kept\n"
        );
    }
}

#[test]
fn a_file_longer_than_max_samples_is_checked_to_the_end_and_the_cut_is_announced() {
    let dir = tempfile::tempdir().unwrap();
    let rows = good_rows();
    let long = write(dir.path(), "long.csv", &csv(HEADER, &rows));
    let o = gma(&[
        "compare",
        "--model",
        "ja",
        "--max-samples",
        "250",
        "--out-dir",
        dir.path().join("p").to_str().unwrap(),
        &long,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cut = "long.csv: 400 samples; using the first 250";
    assert!(stderr(&o).contains(cut), "{}", stderr(&o));
    // Scripts read it in the JSON too, with the other doubts about a result, in both commands
    // that list them; said once on stderr.
    for command in [
        &["compare", "--model", "ja", "--out-dir", dir.path().join("q").to_str().unwrap()][..],
        &["fit", "--model", "linear"],
    ] {
        let o = gma(&[command, &["--json", "--max-samples", "250", &long]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let listed =
            j["warnings"].as_array().unwrap().iter().filter(|w| w.as_str().unwrap().contains(cut)).count();
        assert_eq!(listed, 1, "{command:?}: {}", j["warnings"]);
        assert_eq!(stderr(&o).matches(cut).count(), 1, "{command:?}: {}", stderr(&o));
    }
    // A bad row beyond the window is still found.
    let bad = write(dir.path(), "bad_tail.csv", &csv(HEADER, &with_row(390, "0.0390,1.0,xyz")));
    let o = gma(&[
        "compare",
        "--model",
        "ja",
        "--max-samples",
        "250",
        "--out-dir",
        dir.path().join("p").to_str().unwrap(),
        &bad,
    ]);
    refused(&o, &["bad_tail.csv:392:3:", "`xyz` is not a number"], "bad row after the window");
}

#[test]
fn malformed_loop_files_are_refused_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    for (name, text, expected) in [
        ("few.csv", "H [kA/m],B [T]\n1,0.1\n2,0.2\n", vec!["few.csv:", "at least 5"]),
        (
            "units.csv",
            "H [furlong],B [T]\n1,0.1\n2,0.2\n",
            vec!["units.csv:1:1: header `H [furlong]`: unit `furlong` of H is not one of A/m, kA/m, Oe"],
        ),
        // A unit outside brackets is a unit: never passed over as A/m or T.
        (
            "slash_units.csv",
            "H/kOe,B/T\n1,0.1\n2,0.2\n",
            vec!["slash_units.csv:1:1: header `H/kOe`: unit `kOe` of H is not one of A/m, kA/m, Oe"],
        ),
        (
            "named_b.csv",
            "H(A/m),B_meas\n1,0.1\n2,0.2\n",
            vec!["named_b.csv:1:2: header `B_meas`: unit `meas` of B is not one of T, mT, G"],
        ),
        (
            "nan.csv",
            "H [kA/m],B [T]\n1,0.1\n2,nan\n3,0.3\n4,0.4\n5,0.5\n",
            vec!["nan.csv:3:2:", "not a finite number"],
        ),
        ("ragged.csv", "H [kA/m],B [T]\n1,0.1\n2\n3,0.3\n4,0.4\n5,0.5\n", vec!["ragged.csv:3:", "1 fields"]),
        // Semicolons (a spreadsheet's export in some locales): said, not `no time_s column`.
        (
            "semicolon.csv",
            "H(Oe);B(T)\n1;0.1\n2;0.2\n3;0.3\n4;0.4\n5;0.5\n",
            vec!["semicolon.csv:1: the file seems to separate columns with `;`", "comma- or tab-separated"],
        ),
        (
            "semicolon_named.csv",
            "field_A_per_m;flux_density_T\n1;0.1\n2;0.2\n3;0.3\n4;0.4\n5;0.5\n",
            vec!["semicolon_named.csv:1: the file seems to separate columns with `;`"],
        ),
        (
            "semicolon_unnamed.csv",
            "-40000;-0.95\n1;0.1\n2;0.2\n3;0.3\n4;0.4\n5;0.5\n",
            vec!["semicolon_unnamed.csv:1: the file seems to separate columns with `;`"],
        ),
    ] {
        let p = write(dir.path(), name, text.as_bytes());
        refused(&gma(&["fit", "--model", "ja", &p]), &expected, name);
    }
}

/// A symmetric loop whose B is offset (a search coil integrator's) is fitted with a warning that
/// names the offset, first among the warnings; centred, nothing is said.
#[test]
fn an_off_centre_loop_is_said_with_its_offset() {
    let dir = tempfile::tempdir().unwrap();
    let loop_with = |offset_t: f64| -> String {
        let mut s = String::from("H(A/m),B(T)\n");
        for up in [true, false] {
            for k in 0..60 {
                let h = if up { -10e3 + 20e3 * k as f64 / 59.0 } else { 10e3 - 20e3 * k as f64 / 59.0 };
                let b = 1.5 * ((h + if up { -800.0 } else { 800.0 }) / 2e3).tanh()
                    + 4e-7 * std::f64::consts::PI * h;
                s.push_str(&format!("{h},{}\n", b + offset_t));
            }
        }
        s
    };
    let warnings = |name: &str, offset: f64| -> Vec<String> {
        let p = write(dir.path(), name, loop_with(offset).as_bytes());
        let o = gma(&["fit", "--model", "ja", "--time-limit", "3", "--json", &p]);
        assert!(o.status.success(), "{}", stderr(&o));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        j["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect()
    };
    let w = warnings("offset.csv", 0.12);
    assert!(w.first().is_some_and(|w| w.contains("not centred (B offset by 0.1200 T")), "{w:?}");
    let w = warnings("centred.csv", 0.0);
    assert!(!w.iter().any(|w| w.contains("not centred")), "{w:?}");
}

/// A loop in the wrong unit, without variation or with its sign reversed is refused by every
/// command that reads it, with what looks wrong (never fitted to a NaN or a 1e13 % NRMSE).
#[test]
fn implausible_loop_files_are_refused_with_the_likely_mistake() {
    let dir = tempfile::tempdir().unwrap();
    // A steel-like loop: H ±10 kA/m, B = 1.5 tanh((H ∓ 500)/2000) T, 40 points a branch.
    let branch = |up: bool| -> Vec<(f64, f64)> {
        (0..40)
            .map(|k| {
                let h = if up { -10e3 + 20e3 * k as f64 / 39.0 } else { 10e3 - 20e3 * k as f64 / 39.0 };
                (h, 1.5 * ((h + if up { -500.0 } else { 500.0 }) / 2e3).tanh())
            })
            .collect()
    };
    let points: Vec<(f64, f64)> = branch(true).into_iter().chain(branch(false)).collect();
    let file = |header: &str, f: &dyn Fn(f64, f64) -> (f64, f64)| -> String {
        let mut s = format!("{header}\n");
        for &(h, b) in &points {
            let (x, y) = f(h, b);
            s.push_str(&format!("{x},{y}\n"));
        }
        s
    };
    let good = write(dir.path(), "good.csv", file("H(A/m),B(T)", &|h, b| (h, b)).as_bytes());
    let o = gma(&["fit", "--model", "anhysteretic", "--time-limit", "5", &good]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.path().join("plots");
    for (name, text, expected) in [
        (
            "mT.csv",
            file("H(A/m),B(T)", &|h, b| (h, b * 1e3)),
            vec!["mT.csv:2:", "not a plausible flux density", "B(mT)"],
        ),
        (
            "m_small_mT.csv",
            file("field_A_per_m,flux_density_T", &|h, b| (h, b * 30.0)),
            vec!["m_small_mT.csv:2:", "M = B/μ0 − H", "more than any material"],
        ),
        (
            "h_in_ma.csv",
            file("H(A/m),B(T)", &|h, b| (h * 1e5, b)),
            vec!["h_in_ma.csv:2:", "not a plausible field"],
        ),
        ("flat.csv", file("H(A/m),B(T)", &|h, _| (h, 1.0)), vec!["flat.csv:", "B does not vary"]),
        (
            "reversed.csv",
            file("H(A/m),B(T)", &|h, b| (h, -b)),
            vec!["reversed.csv:", "M falls as H rises", "negate B"],
        ),
        (
            "twice.csv",
            file("field_A_per_m,field_A_per_m", &|h, b| (h, b)),
            vec!["twice.csv:1:2:", "appears twice"],
        ),
        (
            "three.csv",
            file("H(A/m),B(T),T(C)", &|h, b| (h, b)),
            vec!["three.csv:1:", "if this is a magnetization loop"],
        ),
        ("swapped.csv", file("B(T),H(A/m)", &|h, b| (b, h)), vec!["swapped.csv:1:", "H then B or M"]),
    ] {
        let p = write(dir.path(), name, text.as_bytes());
        refused(&gma(&["fit", "--model", "ja", &p]), &expected, name);
        refused(&gma(&["compare", "--model", "ja", "--out-dir", out.to_str().unwrap(), &p]), &expected, name);
    }
}

fn frame_bytes(seq: u32, displacement_um: f32) -> Vec<u8> {
    use gma_control::telemetry::{Frame, MAX_ENCODED};
    let f = Frame { seq, reference_um: 1.0, command_v: 2.0, current_a: 0.5, displacement_um, faults: 0 };
    let mut buf = [0u8; MAX_ENCODED];
    let n = f.encode(&mut buf);
    buf[..n].to_vec()
}

#[test]
fn record_counts_every_fault_in_the_stream_and_never_writes_a_bad_row() {
    let dir = tempfile::tempdir().unwrap();
    let mut stream = Vec::new();
    // 0..100 clean; 100..103 lost; one NaN frame at 150; a corrupted frame at 180; line noise;
    // a board reset (sequence back to 0) after 250; a 2-frame segment at the end.
    for seq in 0..250u32 {
        if (100..103).contains(&seq) {
            continue;
        }
        let mut b = frame_bytes(seq, if seq == 150 { f32::NAN } else { seq as f32 * 0.01 });
        if seq == 180 {
            b[3] ^= 0x40;
        }
        stream.extend(b);
        if seq == 200 {
            stream.extend([0x13, 0x37, 0xFF, 0x00]);
        }
    }
    for seq in 0..50u32 {
        stream.extend(frame_bytes(seq, 5.0));
    }
    stream.extend(frame_bytes(60, 5.0));
    stream.extend(frame_bytes(61, 5.0));
    let input = write(dir.path(), "stream.bin", &stream);
    let out = dir.path().join("rig.csv");
    let o = gma(&["record", "--input", &input, "--out", out.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["lost"], 3 + 1 + 10, "{j}"); // 100..103, the corrupted 180, 50..60 after the reset
    assert_eq!(j["corrupt"], 2, "{j}"); // the flipped frame and the line noise
    assert_eq!(j["invalid"], 1, "{j}");
    assert_eq!(j["restarts"], 1, "{j}");
    assert_eq!(j["short"], 2, "{j}");
    let files: Vec<PathBuf> =
        j["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().into()).collect();
    // Segments: 0..100, 103..150, 151..180, 181..250, the 50 after the reset.
    assert_eq!(files.len(), 5, "{j}");
    let mut rows = 0;
    for f in &files {
        let r = host_sim::recording::Recording::read(f).unwrap_or_else(|e| panic!("{e:#}"));
        assert!((r.dt_s() - 1e-4).abs() < 1e-12);
        assert!(r.displacement_um.as_ref().unwrap().iter().all(|v| v.is_finite()));
        rows += r.len();
    }
    assert_eq!(rows, 100 + 47 + 29 + 69 + 50);
    assert!(stderr(&o).contains("warning"), "{}", stderr(&o));
    // Nothing but the segments (no temporary files) is left in the folder.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert_eq!(names.len(), 1 + files.len(), "{names:?}");
    // A stream without a single frame is an error, not an empty file.
    let junk = write(dir.path(), "junk.bin", &[0x55; 4000]);
    let o = gma(&["record", "--input", &junk, "--out", dir.path().join("none.csv").to_str().unwrap()]);
    refused(&o, &["junk.bin", "no recording in the stream"], "record on junk");
    assert!(!dir.path().join("none.csv").exists());
}

#[test]
fn fit_on_data_no_model_can_follow_gives_finite_parameters_or_says_so() {
    let dir = tempfile::tempdir().unwrap();
    // Displacement that falls when the current rises (a sign-inverted probe), and pure noise.
    let inverted: Vec<String> = good_rows()
        .iter()
        .map(|r| {
            let (head, y) = r.rsplit_once(',').unwrap();
            format!("{head},{}", -y.parse::<f64>().unwrap())
        })
        .collect();
    let noise: Vec<String> = good_rows()
        .iter()
        .enumerate()
        .map(|(k, r)| format!("{},{}", r.rsplit_once(',').unwrap().0, ((k * 7919) % 101) as f64 * 0.01))
        .collect();
    // The inverted file is refused before any fit, with the `--column` that negates it.
    let o = gma(&["fit", "--model", "ja", &write(dir.path(), "inverted.csv", &csv(HEADER, &inverted))]);
    refused(&o, &["inverted.csv: ", "displacement_um=-displacement_um"], "inverted.csv");
    let name = "noise.csv";
    let f = write(dir.path(), name, &csv(HEADER, &noise));
    let out = dir.path().join("p.toml");
    let o = gma(&["fit", "--model", "ja", "--json", "--params-out", out.to_str().unwrap(), &f]);
    let err = stderr(&o);
    assert!(!err.contains("panicked"), "{name}: {err}");
    if o.status.success() {
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let params = j["params"].as_object().expect("params");
        assert!(params.values().all(|v| v.as_f64().is_some_and(f64::is_finite)), "{name}: {j}");
        let spec = model_core::ModelSpec::parse("ja").unwrap();
        let p = host_sim::params::parse("p.toml", &std::fs::read_to_string(&out).unwrap(), spec).unwrap();
        model_core::Actuator::new(spec, &p).unwrap();
    } else {
        refused(&o, &["the fit"], name);
        assert!(!out.exists());
    }
    println!("{name}: {}", if o.status.success() { "finite parameters".into() } else { err });
}

/// `diagnose --laws` refits the structure with the other hysteresis law from the same parameter
/// file, so the file is checked for that structure too, before any fit: a `[preisach]` value out
/// of range is refused with its line (it ended the run after the whole diagnosis, without the
/// file's name), and a file without `[preisach]` says that the demo set's values stand in (they
/// did, without a word).
#[test]
fn laws_checks_the_parameter_file_for_the_other_law_before_any_fit() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &good_rows()));
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let line = demo.lines().position(|l| l.starts_with("h_max_a_per_m =")).unwrap() + 1;
    let bad = params_with(dir.path(), "bad_plane.toml", |t| {
        replace_line(t, "h_max_a_per_m", "h_max_a_per_m = -1.0")
    });
    let o = gma(&["diagnose", "--model", "ja", "--laws", "--params", &bad, &good]);
    let at = format!("bad_plane.toml:{line}: ");
    refused(&o, &[&at, "`preisach.h_max_a_per_m` is out of range", "preisach"], "--laws, bad [preisach]");
    assert!(!stderr(&o).contains("fitting the given model"), "refused after a fit:\n{}", stderr(&o));

    let without: String = {
        let start = demo.find("[preisach]").unwrap();
        let end = demo[start + 1..].find("\n[").map_or(demo.len(), |k| start + 1 + k + 1);
        format!("{}{}", &demo[..start], &demo[end..])
    };
    let p = write(dir.path(), "no_plane.toml", without.as_bytes());
    let o = gma(&["diagnose", "--model", "ja", "--laws", "--json", "--params", &p, &good]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["parameters_defaulted"], serde_json::json!(["preisach"]), "{j:#}");
    assert!(stderr(&o).contains("no_plane.toml has no `preisach`"), "{}", stderr(&o));
    // Without --laws the table is not used, and not said.
    let o = gma(&["diagnose", "--model", "ja", "--json", "--params", &p, &good]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["parameters_defaulted"], serde_json::json!([]), "{j:#}");
}

/// `good_rows()` with the current column scaled by `i_scale` and the displacement by `y_scale`.
fn scaled_rows(i_scale: f64, y_scale: f64) -> Vec<String> {
    good_rows()
        .iter()
        .map(|r| {
            let v: Vec<f64> = r.split(',').map(|c| c.parse().unwrap()).collect();
            format!("{:.4},{},{}", v[0], v[1] * i_scale, v[2] * y_scale)
        })
        .collect()
}

/// `compare --json`'s mean NRMSE on `args`, or the run's stderr.
fn compare_nrmse(args: &[&str]) -> Result<f64, String> {
    let mut all = vec!["compare", "--model", "ja", "--json"];
    all.extend(args);
    let o = gma(&all);
    if !o.status.success() {
        return Err(stderr(&o));
    }
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    Ok(j["nrmse"].as_f64().unwrap_or_else(|| panic!("no nrmse: {j}")))
}

/// A displacement probe wired the other way round (the column negated) gave a fit of nothing
/// and a diagnosis of a missing effect, exit 0. Terfenol-D elongates with the field's
/// magnitude, so a displacement that falls where the model's strain rises is refused, with the
/// `--column` that negates it; read with it, the file scores as its twin. Not on a file with a
/// negative bias (where the strain rises as the current falls), nor on one the other commands
/// would take.
#[test]
fn a_displacement_against_the_drive_is_refused_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(dir.path(), "good.csv", &csv(HEADER, &scaled_rows(1.0, 1.0)));
    let negated = write(dir.path(), "negated.csv", &csv(HEADER, &scaled_rows(1.0, -1.0)));
    let fix = "`--column displacement_um=-displacement_um`";
    for cmd in [&["compare", "--model", "ja"][..], &["diagnose", "--model", "ja"], &["fit", "--model", "ja"]]
    {
        let mut args = cmd.to_vec();
        args.push(&negated);
        refused(&gma(&args), &["negated.csv: ", "falls where the model's strain rises", fix], cmd[0]);
    }
    let o = gma(&["compare", "--model", "ja", "--json", &negated]);
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["error"]["message"].as_str().unwrap().contains(fix), "{j}");
    let twin = compare_nrmse(&[&good]).unwrap();
    let fixed = compare_nrmse(&["--column", "displacement_um=-displacement_um", &negated]).unwrap();
    assert_eq!(fixed, twin);
    // A negative bias: the rod's field grows as the current goes negative, and so does the strain.
    let mirrored = write(dir.path(), "mirrored.csv", &csv(HEADER, &scaled_rows(-1.0, 1.0)));
    let p = params_with(dir.path(), "negative_bias.toml", |t| {
        replace_line(t, "bias_a_per_m", "bias_a_per_m = -20000.0")
    });
    compare_nrmse(&["--params", &p, &mirrored]).unwrap();
}

/// A current logged in mA under `current_A` drove the model to ~1e7 A/m, every parameter ended
/// at a range's end and the verdict was "nothing missing", exit 0. A field beyond any actuator
/// coil's (2 M_s) is refused with the unit that brings it into range and the `--column` that
/// reads it so; read with it, the file scores as its twin in A.
#[test]
fn a_current_in_milliamperes_under_current_a_is_refused_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    // 0 to 0.9 A: in mA, below the 1e3 A plausibility limit a cell must pass.
    let good = write(dir.path(), "good.csv", &csv(HEADER, &scaled_rows(0.45, 1.0)));
    let ma = write(dir.path(), "ma.csv", &csv(HEADER, &scaled_rows(450.0, 1.0)));
    let fix = "`--column current_A=current_A:mA`";
    for cmd in [&["compare", "--model", "ja"][..], &["diagnose", "--model", "ja"], &["fit", "--model", "ja"]]
    {
        let mut args = cmd.to_vec();
        args.push(&ma);
        refused(&gma(&args), &["ma.csv: ", "A/m", "coil.turns_per_m", fix], cmd[0]);
    }
    let twin = compare_nrmse(&[&good]).unwrap();
    let fixed = compare_nrmse(&["--column", "current_A=current_A:mA", &ma]).unwrap();
    assert_eq!(fixed, twin);
    // In µA (a 0.9 mA coil current): the fix names µA.
    let ua = write(dir.path(), "ua.csv", &csv(HEADER, &scaled_rows(450.0, 1.0)));
    let p =
        params_with(dir.path(), "many_turns.toml", |t| replace_line(t, "turns_per_m", "turns_per_m = 1e7"));
    let o = gma(&["compare", "--model", "ja", "--params", &p, &ua]);
    refused(&o, &["ua.csv: ", "`--column current_A=current_A:uA`"], "µA");
}

/// A gap of exactly 5 steps was refused as "more than 5 median steps" (the step's rounding in
/// the time stamps' last digit); `--resample linear` bridges it, as the docs say.
#[test]
fn resample_bridges_a_gap_of_exactly_five_steps() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows = good_rows();
    rows.drain(101..105);
    let f = write(dir.path(), "gap5.csv", &csv(HEADER, &rows));
    compare_nrmse(&["--resample", "linear", &f]).unwrap();
    // Six steps are still a gap.
    rows.remove(101);
    let f = write(dir.path(), "gap6.csv", &csv(HEADER, &rows));
    let o = gma(&["compare", "--model", "ja", "--resample", "linear", &f]);
    refused(&o, &["gap6.csv:103:1: ", "more than 5 median steps"], "a gap of 6 steps");
}

/// Blank lines are documented as skipped; a line of spaces (or a tab) is one, not a row of one
/// field.
#[test]
fn a_line_of_whitespace_is_a_blank_line() {
    let dir = tempfile::tempdir().unwrap();
    let twin = compare_nrmse(&[&write(dir.path(), "good.csv", &csv(HEADER, &good_rows()))]).unwrap();
    for (name, blank) in [("spaces.csv", "   "), ("tab.csv", "\t"), ("crlf.csv", " \r")] {
        let f =
            write(dir.path(), name, &csv(HEADER, &with_row(200, &format!("{blank}\n{}", good_rows()[200]))));
        assert_eq!(compare_nrmse(&[&f]), Ok(twin), "{name}");
    }
}

/// A recording with an extra `field_A_per_m` column (a rig that logs its field too) was read as
/// a magnetization loop: `fit` fitted a loop, `diagnose` refused it without naming the file. A
/// header with `displacement_um` is a recording's.
#[test]
fn a_recording_with_a_field_column_is_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let rows: Vec<String> = good_rows()
        .iter()
        .map(|r| {
            let i: f64 = r.split(',').nth(1).unwrap().parse().unwrap();
            format!("{r},{}", 13_541.7 * i + 20_000.0)
        })
        .collect();
    let f = write(dir.path(), "with_field.csv", &csv(&format!("{HEADER},field_A_per_m"), &rows));
    let twin = compare_nrmse(&[&write(dir.path(), "good.csv", &csv(HEADER, &good_rows()))]).unwrap();
    assert_eq!(compare_nrmse(&[&f]), Ok(twin));
}

/// A European spreadsheet export (`sep=;` first line, `;` between cells, decimal commas) and
/// headers with their unit in brackets or parentheses (`Time [s]`, `I (A)`) were refused with
/// no way to read them. Such a file is read as it is, each header mapped onto its canonical
/// column with a note, and scores as its twin; a tab-separated export too.
#[test]
fn spreadsheet_exports_are_read_as_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let twin = compare_nrmse(&[&write(dir.path(), "good.csv", &csv(HEADER, &good_rows()))]).unwrap();
    let euro: Vec<String> = good_rows().iter().map(|r| r.replace(',', ";").replace('.', ",")).collect();
    let text = [b"sep=;\n".to_vec(), csv("Time [s];I (A);Displacement (um)", &euro)].concat();
    let f = write(dir.path(), "excel.csv", &text);
    let o = gma(&["compare", "--model", "ja", "--json", &f]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["nrmse"].as_f64(), Some(twin), "{j}");
    let e = stderr(&o);
    assert!(e.contains("`Time [s]` read as `time_s`") && e.contains("`I (A)` read as `current_A`"), "{e}");
    let tabs: Vec<String> = good_rows().iter().map(|r| r.replace(',', "\t")).collect();
    let f = write(dir.path(), "tabs.tsv", &csv("time [s]\tcurrent (mA)\tdisplacement_um", &tabs));
    let o = gma(&["compare", "--model", "ja", "--json", &f]);
    assert!(o.status.success(), "{}", stderr(&o));
    // The unit named is applied: mA is not read as A.
    let e = stderr(&o);
    assert!(e.contains("`current (mA)` read as `current_A`, mA → A"), "{e}");
    // The canonical names with their units after them.
    let f =
        write(dir.path(), "units.csv", &csv("time_s [s],current_A (A),displacement_um (um)", &good_rows()));
    let o = gma(&["compare", "--model", "ja", "--json", &f]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["nrmse"].as_f64(), Some(twin), "{j}");
    assert!(stderr(&o).contains("`current_A (A)` read as `current_A`"), "{}", stderr(&o));
}

/// After a `sep=` line the header is the second line, and a message about it says so.
#[test]
fn a_header_after_a_sep_line_is_on_line_two() {
    let dir = tempfile::tempdir().unwrap();
    let text = [b"sep=;\n".to_vec(), csv("t_ms;I (A);displacement_um", &good_rows())].concat();
    let f = write(dir.path(), "no_time.csv", &text);
    refused(&gma(&["compare", "--model", "ja", &f]), &["no_time.csv:2: no `time_s` column"], "sep= line");
}

/// Header names that differ only in look-alike characters (µ U+00B5 and μ U+03BC, a zero-width
/// space, a Cyrillic а) printed identical: "no column `x/µm` (header has … x/μm)". Messages
/// write those characters as escapes.
#[test]
fn look_alike_characters_in_names_are_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(dir.path(), "greek.csv", &csv("time_s,current_A,x/\u{3bc}m", &good_rows()));
    let o = gma(&["compare", "--model", "ja", "--column", "displacement_um=x/µm", &f]);
    refused(&o, &["no column `x/µm`", "x/\\u{3bc}m"], "Greek mu");
    let f = write(dir.path(), "zws.csv", &csv("time_s\u{200b},current_A,displacement_um", &good_rows()));
    refused(&gma(&["compare", "--model", "ja", &f]), &["time_s\\u{200b}"], "zero-width space");
    let f = write(dir.path(), "cyrillic.csv", &csv("time_s,current_A,displ\u{430}cement_um", &good_rows()));
    refused(&gma(&["compare", "--model", "ja", &f]), &["displ\\u{430}cement_um"], "Cyrillic a");
}
