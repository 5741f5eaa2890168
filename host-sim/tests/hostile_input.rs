//! Hostile input and hostile environments, as a tester would try them against the `gma` binary:
//! pipes and FIFOs, outputs that are inputs, links or devices, files without line breaks, absurd
//! options, concurrent runs, signals, and `--json` on failure. Each case must give the right
//! result or a clear error with a non-zero exit — no panic, no hang, no file lost.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{err, gma, refused};

const GMA: &str = env!("CARGO_BIN_EXE_gma");

/// Runs gma with `input` on its standard input.
fn gma_stdin(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(GMA)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let bytes = input.to_vec();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(&bytes);
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    out
}

fn json(o: &Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(text.trim().lines().count(), 1, "stdout must be one JSON object:\n{text}");
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("{e}: {text}"))
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// A B–H loop measured in oersted (the unit header matters: losing it reads Oe as A/m).
fn oe_loop() -> Vec<u8> {
    let mut s = String::from("H(Oe),B(T)\n");
    for k in 0..100 {
        let th = 2.0 * std::f64::consts::PI * k as f64 / 100.0;
        let h = 200.0 * th.cos();
        let b = 0.8 * (h / 60.0 + if th.sin() > 0.0 { 0.5 } else { -0.5 }).tanh();
        s.push_str(&format!("{h:.4},{b:.5}\n"));
    }
    s.into_bytes()
}

/// A 50 Hz recording, 40 ms (two cycles), `time_s,current_A,displacement_um`.
fn recording() -> Vec<u8> {
    let mut s = String::from("time_s,current_A,displacement_um\n");
    for k in 0..400 {
        let t = k as f64 * 1e-4;
        let i = 1.0 + (2.0 * std::f64::consts::PI * 50.0 * t).sin();
        s.push_str(&format!("{t:.4},{i:.6},{:.6}\n", 10.0 * i * i));
    }
    s.into_bytes()
}

#[test]
fn a_loop_file_through_stdin_a_pipe_or_a_fifo_fits_exactly_as_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "oe.csv", &oe_loop());
    let args = |input: &'static str| ["fit", "--model", "ja", "--json", "--effort", "1", input];
    let from_file = json(&gma(&["fit", "--model", "ja", "--json", "--effort", "1", path(&file)]));
    let from_dash = json(&gma_stdin(&args("-"), &oe_loop()));
    let from_dev_stdin = json(&gma_stdin(&args("/dev/stdin"), &oe_loop()));
    assert!(from_file["params"]["a_a_per_m"].as_f64().unwrap() > 1000.0, "Oe header lost: {from_file}");
    assert_eq!(from_file["params"], from_dash["params"]);
    assert_eq!(from_file["params"], from_dev_stdin["params"]);
    // A FIFO: opened once, read once (a second open would wait forever for a writer).
    let fifo = dir.path().join("loop.fifo");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::write(fifo, oe_loop()).unwrap())
    };
    let mut child = Command::new(GMA)
        .args(["fit", "--model", "ja", "--json", "--effort", "1", path(&fifo)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("gma hung on a FIFO");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    writer.join().unwrap();
    let from_fifo = json(&child.wait_with_output().unwrap());
    assert_eq!(from_file["params"], from_fifo["params"]);
    // Standard input can be read once only.
    refused(&gma_stdin(&["fit", "--model", "ja", "-", "-"], &oe_loop()), &["more than once"], "- twice");
}

#[test]
fn an_output_that_is_an_input_a_link_or_a_device_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let rec = write(dir.path(), "rig.csv", &recording());
    let params = dir.path().join("p.toml");
    assert!(gma(&["fit", "--model", "ja", "--effort", "0.2", "--params-out", path(&params), path(&rec)])
        .status
        .success());
    let (rec_bytes, params_bytes) = (std::fs::read(&rec).unwrap(), std::fs::read(&params).unwrap());
    let stream = write(dir.path(), "stream.bin", &[0u8; 64]);
    for (args, what) in [
        (vec!["fit", "--model", "ja", "--params-out", path(&rec), path(&rec)], "fit --params-out = input"),
        (
            vec![
                "fit",
                "--model",
                "ja",
                "--params",
                path(&params),
                "--params-out",
                path(&params),
                path(&rec),
            ],
            "fit --params-out = --params",
        ),
        (
            vec!["fit", "--model", "ja", "--val", path(&rec), "--params-out", path(&rec), path(&rec)],
            "fit --params-out = --val",
        ),
        (vec!["report", "--model", "ja", "-o", path(&rec), path(&rec)], "report -o = input"),
        (vec!["simulate", "--params", path(&params), "--out", path(&params)], "simulate --out = --params"),
        (vec!["record", "-i", path(&stream), "-o", path(&stream)], "record -o = -i"),
    ] {
        let t0 = Instant::now();
        refused(&gma(&args), &["cannot write", "input"], what);
        assert!(t0.elapsed() < Duration::from_secs(10), "{what}: refused only after the work");
    }
    assert_eq!(std::fs::read(&rec).unwrap(), rec_bytes, "an input was changed");
    assert_eq!(std::fs::read(&params).unwrap(), params_bytes, "an input was changed");

    // A symbolic link as output: refused, the link and its target untouched.
    let target = write(dir.path(), "target.toml", b"# mine\n");
    let link = dir.path().join("link.toml");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    refused(
        &gma(&["fit", "--model", "ja", "--effort", "0.2", "--params-out", path(&link), path(&rec)]),
        &["symbolic link"],
        "output is a link",
    );
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"# mine\n");
    // A device: /dev/null stays a character device, even for root.
    refused(&gma(&["simulate", "--out", "/dev/null"]), &["not a regular file"], "output is /dev/null");
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    // A folder that takes no files (as root, permissions do not stop writes; /proc does):
    // refused before the fit, not after it.
    let o = gma(&["fit", "--model", "ja", "--params-out", "/proc/gma-test.toml", path(&rec)]);
    refused(&o, &["cannot create a file in /proc"], "unwritable folder");
    assert!(!err(&o).contains("evaluations"), "the fit ran before the output was checked:\n{}", err(&o));
}

/// Issue 78: an output path that names an existing measurement (not one of the command's
/// inputs) is refused before any work, the measurement kept; an output of the command's own kind
/// is replaced, and `simulate`, whose output has a measurement's columns, replaces a file only
/// when told to (`--overwrite`).
#[test]
fn a_measurement_named_as_an_output_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let rec = write(dir.path(), "rig.csv", &recording());
    let measured = recording();
    let meas = write(dir.path(), "meas.csv", &measured);
    let kept =
        |why: &str| assert_eq!(std::fs::read(&meas).unwrap(), measured, "{why}: the measurement changed");

    let o = gma(&["simulate", "--model", "ja", "--duration-s", "0.01", "-o", path(&meas)]);
    refused(&o, &["--out", "meas.csv", "--overwrite"], "simulate -o onto a measurement");
    kept("simulate -o");
    let o = gma(&["compare", "--model", "ja", path(&rec), "--out-csv", path(&meas)]);
    refused(&o, &["--out-csv", "meas.csv", "not a table"], "compare --out-csv onto a measurement");
    kept("compare --out-csv");
    let o = gma(&["report", "--model", "ja", path(&rec), "-o", path(&meas)]);
    refused(&o, &["--out", "meas.csv", "not an HTML page"], "report -o onto a measurement");
    kept("report -o");

    // Outputs of the command's own kind are replaced; `simulate`'s only with `--overwrite`.
    let table = dir.path().join("cmp.csv");
    for run in 0..2 {
        let o = gma(&["compare", "--model", "ja", path(&rec), "--out-csv", path(&table)]);
        assert!(o.status.success(), "compare --out-csv, run {run}: {}", err(&o));
    }
    let o = gma(&["simulate", "--model", "ja", "--duration-s", "0.01", "--overwrite", "-o", path(&meas)]);
    assert!(o.status.success(), "simulate --overwrite: {}", err(&o));
    assert_ne!(std::fs::read(&meas).unwrap(), measured, "--overwrite did not replace the file");
}

#[test]
fn a_failed_fit_never_replaces_a_good_parameter_file_and_json_gets_only_the_error() {
    let dir = tempfile::tempdir().unwrap();
    // A rectangular loop: J–A reaches it only in its multivalued region (α·M_s/3a ≥ 1). The fit
    // searches the mean-field ratio below 1, so it ends valid, at the ratio's edge, and says so.
    let mut s = String::from("H(A/m),B(T)\n");
    for k in 0..200 {
        let h = -80e3 + 160e3 * k as f64 / 199.0;
        s.push_str(&format!("{h},{}\n", 1.2 * ((h - 40e3) / 2e3).tanh()));
    }
    for k in 0..200 {
        let h = 80e3 - 160e3 * k as f64 / 199.0;
        s.push_str(&format!("{h},{}\n", 1.2 * ((h + 40e3) / 2e3).tanh()));
    }
    let square = write(dir.path(), "square.csv", s.as_bytes());
    let o = gma(&["fit", "--model", "ja", "--json", path(&square)]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let j = json(&o);
    let p = &j["params"];
    let ratio = p["alpha"].as_f64().unwrap() * p["ms_a_per_m"].as_f64().unwrap()
        / (3.0 * p["a_a_per_m"].as_f64().unwrap());
    assert!(ratio < 1.0, "the loop fit ended in the multivalued region: α·M_s/(3a) = {ratio}");
    let at_edge = j["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|w| w.as_str())
        .any(|w| w.starts_with("`α·M_s/(3a)`") && w.contains("ended at the edge of its search range"));
    assert!(at_edge, "no warning at the ratio's edge, named as the ratio: {j}");

    // A fit that fails (the second loop file is malformed far into it) leaves the good file alone
    // and prints only the error object.
    let mut bad = s.clone();
    bad.push_str("1.0,x\n");
    let bad = write(dir.path(), "bad.csv", bad.as_bytes());
    let good = write(dir.path(), "good.toml", b"# a good parameter file\n");
    let o = gma(&["fit", "--model", "ja", "--json", "--params-out", path(&good), path(&square), path(&bad)]);
    refused(&o, &["bad.csv:402"], "malformed second loop file");
    let j = json(&o);
    assert!(j.get("params").is_none(), "a failed fit printed its result as JSON: {j}");
    assert_eq!(j["error"]["exit_code"], 1);
    assert_eq!(std::fs::read(&good).unwrap(), b"# a good parameter file\n");

    // `--params-out` given a recording's name (one slot early): refused, the recording kept.
    let other = write(dir.path(), "other.csv", s.as_bytes());
    let o = gma(&["fit", "--model", "ja", "--params-out", path(&square), path(&other)]);
    refused(&o, &["--params-out", "square.csv", "not a parameter file"], "a recording as --params-out");
    assert_eq!(std::fs::read_to_string(&square).unwrap(), s);
}

#[test]
fn json_errors_are_one_object_that_points_into_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from_utf8(recording()).unwrap();
    text = text.replacen("0.0005,", "0.0005x,", 1);
    let bad = write(dir.path(), "bad.csv", text.as_bytes());
    for cmd in ["fit", "diagnose", "report"] {
        let out = dir.path().join("r.html");
        let mut args = vec![cmd, "--model", "ja", "--json", path(&bad)];
        if cmd == "report" {
            args.extend(["-o", path(&out)]);
        }
        let o = gma(&args);
        refused(&o, &["bad.csv:7:1"], cmd);
        let e = &json(&o)["error"];
        assert_eq!(e["file"], path(&bad), "{cmd}: {e}");
        assert_eq!((e["line"].as_u64(), e["column"].as_u64()), (Some(7), Some(1)), "{cmd}: {e}");
        assert!(e["message"].as_str().unwrap().contains("is not a number"), "{cmd}: {e}");
    }
    let o =
        gma(&["compare", "--model", "ja", "--json", "--out-dir", path(&dir.path().join("c")), path(&bad)]);
    assert_eq!(json(&o)["error"]["line"], 7);
    // A file that cannot be opened, or is a folder, is the error's `file` too (it was null).
    let missing = dir.path().join("nope.csv");
    for (input, says) in [(path(&missing), "cannot read"), (path(dir.path()), "is a folder")] {
        let e = &json(&gma(&["fit", "--model", "ja", "--json", input]))["error"];
        assert_eq!((&e["file"], e["line"].as_u64()), (&input.into(), None), "{e}");
        assert!(e["message"].as_str().unwrap().starts_with(&format!("{input}: {says}")), "{e}");
    }
    // A usage error with --json: the error object too, with clap's exit status 2.
    let o = gma(&["fit", "--model", "ja", "--json", "--no-such-option", path(&bad)]);
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(json(&o)["error"]["exit_code"], 2);
    // Help is not an error.
    assert!(gma(&["fit", "--help", "--json"]).status.success());
}

/// A usage error with `--json`: the error object's message says what is wrong with the command
/// line (the missing argument's name, the unknown option), not only clap's first line.
#[test]
fn a_json_usage_error_names_the_missing_or_unknown_argument() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "r.csv", &recording());
    for (args, expected) in [
        (vec!["fit", "--json", path(&file)], "the following required arguments were not provided: --model <"),
        (vec!["fit", "--model", "ja", "--json", "--no-such-option", path(&file)], "'--no-such-option'"),
        (vec!["diagnose", "--json", "--model", "ja"], "required arguments were not provided: <"),
    ] {
        let o = gma(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let e = &json(&o)["error"];
        assert_eq!(e["exit_code"], 2, "{args:?}: {e}");
        let message = e["message"].as_str().unwrap();
        assert!(message.contains(expected), "{args:?}: message lacks `{expected}`: {e}");
        assert!(!message.contains('\n') && !message.contains("Usage:") && !message.contains("--help"), "{e}");
    }
}

#[test]
fn control_characters_from_a_file_never_reach_the_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let text = String::from_utf8(recording()).unwrap().replacen("0.0005,", "\u{1b}[2J\u{7}bell,", 1);
    let bad = write(dir.path(), "esc.csv", text.as_bytes());
    let o = gma(&["fit", "--model", "ja", path(&bad)]);
    refused(&o, &["esc.csv:7:1", "\\u{1b}[2J\\u{7}bell"], "ESC/BEL cell");
    assert!(!o.stderr.iter().any(|&b| b == 0x1b || b == 0x07), "raw control bytes on stderr");
    // A very long cell is cut in the message.
    let long =
        String::from_utf8(recording()).unwrap().replacen("0.0005,", &format!("{},", "9x".repeat(5000)), 1);
    let bad = write(dir.path(), "long.csv", long.as_bytes());
    let o = gma(&["fit", "--model", "ja", path(&bad)]);
    refused(&o, &["long.csv:7:1", "…"], "long cell");
    assert!(o.stderr.len() < 2000, "{} bytes of message", o.stderr.len());
}

#[test]
fn inputs_without_line_breaks_are_refused_at_once_in_bounded_memory() {
    for input in ["/dev/zero", "/dev/urandom"] {
        let t0 = Instant::now();
        let o = Command::new("/usr/bin/time")
            .args(["-f", "maxrss_kb=%M", GMA, "fit", "--model", "ja", input])
            .output()
            .unwrap();
        let e = err(&o);
        assert_eq!(o.status.code(), Some(1), "{input}: {e}");
        assert!(e.contains(&format!("{input}:")) && !e.contains("panicked"), "{input}: {e}");
        assert!(t0.elapsed() < Duration::from_secs(20), "{input}: {:?}", t0.elapsed());
        let rss: u64 = e.rsplit("maxrss_kb=").next().unwrap().trim().parse().unwrap();
        assert!(rss < 100_000, "{input}: peak RSS {rss} kB");
        assert!(o.stderr.len() < 2000, "{input}: the message echoes the input");
    }
    // A first line that reads as a loop file's header, then an endless binary stream: refused at
    // line 2, not after the loop reader's 256 MB cap (random bytes hold a line break every ~256
    // bytes, so the line bound alone does not stop it).
    let mut child = Command::new("/usr/bin/time")
        .args(["-f", "maxrss_kb=%M", GMA, "fit", "--model", "ja", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || {
        let mut block = vec![0u8; 1 << 16];
        let mut x = 0x2545_f491_4f6c_dd1d_u64;
        let _ = stdin.write_all(b"H [A/m],B [T]\n");
        for _ in 0..(512 << 20) / block.len() {
            for b in block.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *b = (x >> 56) as u8;
            }
            if stdin.write_all(&block).is_err() {
                break; // refused: the reader went away
            }
        }
    });
    let o = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    refused(&o, &["<stdin>:2:", "not UTF-8"], "binary after a loop header");
    let e = err(&o);
    let rss: u64 = e.rsplit("maxrss_kb=").next().unwrap().trim().parse().unwrap();
    assert!(rss < 100_000, "binary after a loop header: peak RSS {rss} kB");
    // A one-row file of 10 MB.
    let dir = tempfile::tempdir().unwrap();
    let row = write(dir.path(), "row.csv", &vec![b'7'; 10 << 20]);
    refused(
        &gma(&["compare", "--model", "ja", "--out-dir", path(&dir.path().join("c")), path(&row)]),
        &["row.csv:1: line longer than 64 KiB"],
        "one long row",
    );
}

#[test]
fn absurd_numbers_are_refused_with_the_option_or_parameter_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.csv");
    for (args, fragment) in [
        (vec!["--duration-s", "1e20"], "--duration-s"),
        (vec!["--duration-s", "1e12"], "--duration-s"),
        (vec!["--duration-s", "1e-9"], "at least 3"),
        (vec!["--oversample", "0"], "--oversample"),
        (vec!["--oversample", "100000"], "--oversample"),
        (vec!["--freq-hz", "1e9"], "Nyquist"),
        (vec!["--offset-um", "1e300"], "--offset-um"),
        (vec!["--noise-um", "1e300"], "--noise-um"),
    ] {
        let mut a = vec!["simulate", "--out", path(&out)];
        a.extend(&args);
        refused(&gma(&a), &[fragment], &format!("simulate {args:?}"));
        assert!(!out.exists());
    }
    // A parameter file with an absurd sample period.
    let p = dir.path().join("p.toml");
    assert!(gma(&[
        "fit",
        "--model",
        "ja",
        "--effort",
        "0.2",
        "--params-out",
        path(&p),
        path(&write(dir.path(), "r.csv", &recording()))
    ])
    .status
    .success());
    let text = std::fs::read_to_string(&p).unwrap();
    let line = text.lines().find(|l| l.starts_with("dt_s")).unwrap().to_string();
    let tiny = write(dir.path(), "tiny.toml", text.replace(&line, "dt_s = 1e-30").as_bytes());
    refused(
        &gma(&["simulate", "--params", path(&tiny), "--out", path(&out)]),
        &["tiny.toml", "dt_s", "1e-7"],
        "dt_s 1e-30",
    );
    for (opt, v) in
        [("--time-limit", "0"), ("--time-limit", "nan"), ("--time-limit", "1e12"), ("--max-samples", "2")]
    {
        refused(&gma(&["fit", "--model", "ja", opt, v, path(&p)]), &[opt], opt);
    }
    refused(
        &gma(&["record", "-i", "/dev/null", "-o", path(&out), "--tick-s", "1e-30"]),
        &["--tick-s"],
        "tick",
    );
}

#[test]
fn data_too_small_to_mean_anything_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // A displacement of 1e-308 µm: below any sensor.
    let mut s = String::from("time_s,current_A,displacement_um\n");
    for k in 0..400 {
        let t = k as f64 * 1e-4;
        s.push_str(&format!("{t:.4},{},{:e}\n", (300.0 * t).sin(), 1e-308 * (300.0 * t).sin()));
    }
    let tiny = write(dir.path(), "tiny.csv", s.as_bytes());
    refused(&gma(&["fit", "--model", "ja", path(&tiny)]), &["tiny.csv", "resolution"], "1e-308 µm");
    // Five samples that happen to cover a cycle: no verdict from that.
    let mut s = String::from("time_s,current_A,displacement_um\n");
    for (k, i) in [0.0, 2.0, -1.0, 2.0, -2.0].iter().enumerate() {
        s.push_str(&format!("{},{i},{}\n", k as f64 * 1e-4, i * i));
    }
    let five = write(dir.path(), "five.csv", s.as_bytes());
    refused(
        &gma(&["diagnose", "--model", "ja", path(&five)]),
        &["five.csv", "5 samples", "at least 200"],
        "5 samples",
    );
}

#[test]
fn plots_of_inputs_with_the_same_name_do_not_overwrite_each_other() {
    let dir = tempfile::tempdir().unwrap();
    for sub in ["a", "b"] {
        std::fs::create_dir(dir.path().join(sub)).unwrap();
        write(&dir.path().join(sub), "rig.csv", &recording());
    }
    let out = dir.path().join("plots");
    let (a, b) = (dir.path().join("a/rig.csv"), dir.path().join("b/rig.csv"));
    let o = gma(&["compare", "--model", "ja", "--json", "--out-dir", path(&out), path(&a), path(&b)]);
    assert!(o.status.success(), "{}", err(&o));
    let j = json(&o);
    let plots: Vec<String> = j["files"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|f| f["plots"].as_array().cloned().unwrap_or_default())
        .map(|p| p.as_str().unwrap().to_string())
        .collect();
    assert_eq!(plots.len(), 12, "{plots:?}");
    let mut unique = plots.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), 12, "{plots:?}");
    assert!(plots.iter().all(|p| Path::new(p).exists()));
}

#[test]
fn concurrent_png_comparisons_into_one_folder_all_succeed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("plots");
    let inputs: Vec<PathBuf> =
        (0..10).map(|k| write(dir.path(), &format!("r{k}.csv"), &recording())).collect();
    let children: Vec<_> = inputs
        .iter()
        .map(|p| {
            Command::new(GMA)
                .args(["compare", "--model", "ja", "--format", "png", "--out-dir", path(&out), path(p)])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let o = c.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", err(&o));
    }
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert_eq!(names.iter().filter(|n| n.ends_with(".png")).count(), 60, "{names:?}");
    assert!(names.iter().all(|n| !n.starts_with('.')), "temporary files left: {names:?}");
}

#[test]
fn a_live_record_ended_by_sigint_or_sigterm_writes_its_csv_and_summary() {
    use gma_control::telemetry::{Frame, MAX_ENCODED};
    for signal in ["INT", "TERM"] {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("uart.fifo");
        assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let out = dir.path().join("rec.csv");
        let child = Command::new(GMA)
            .args(["record", "--json", "-i", path(&fifo), "-o", path(&out)])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The board: 500 frames, then a quiet line that stays open (no end of stream).
        let mut w = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
        for seq in 0..500u32 {
            let f = Frame {
                seq,
                reference_um: 1.0,
                command_v: 0.5,
                current_a: 0.25,
                displacement_um: 3.0,
                faults: 0,
            };
            let mut buf = [0u8; MAX_ENCODED];
            let n = f.encode(&mut buf);
            w.write_all(&buf[..n]).unwrap();
        }
        w.flush().unwrap();
        std::thread::sleep(Duration::from_millis(500));
        assert!(Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap()
            .success());
        let t0 = Instant::now();
        let o = child.wait_with_output().unwrap();
        drop(w);
        assert!(t0.elapsed() < Duration::from_secs(10));
        assert!(o.status.success(), "SIG{signal}: {}", err(&o));
        let j = json(&o);
        assert_eq!(j["frames"], 500, "{j}");
        assert_eq!(j["stopped_by_signal"], true);
        let text = std::fs::read_to_string(&out).unwrap();
        assert_eq!(text.lines().count(), 501, "header + 500 rows");
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .filter(|n| n.ends_with(".partial"))
            .collect();
        assert!(left.is_empty(), "SIG{signal}: {left:?}");
    }
}

#[test]
fn long_work_is_bounded_by_time_limit_and_reports_progress_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("long.csv");
    let o = gma(&[
        "simulate",
        "--model",
        "ja+mech",
        "--duration-s",
        "8",
        "--noise-um",
        "0.05",
        "--out",
        path(&rec),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    let p = dir.path().join("p.toml");
    let t0 = Instant::now();
    let o = gma(&[
        "fit",
        "--model",
        "ja+mech",
        "--json",
        "--effort",
        "10",
        "--time-limit",
        "2",
        "--params-out",
        path(&p),
        path(&rec),
    ]);
    let took = t0.elapsed();
    assert!(o.status.success(), "{}", err(&o));
    let j = json(&o);
    assert_eq!(j["time_limit_reached"], true, "{j}");
    assert!(j["nrmse_fit"].as_f64().unwrap().is_finite());
    assert!(err(&o).contains("the time limit of 2 s was reached"), "{}", err(&o));
    assert_eq!(err(&o).matches("the time limit of 2 s was reached").count(), 1, "said once: {}", err(&o));
    let listed = j["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w.as_str().unwrap().contains("the time limit of 2 s was reached"));
    assert!(listed, "the JSON's warnings lack the time limit: {j}");
    assert!(std::fs::read_to_string(&p).unwrap().contains("stopped by --time-limit"));
    // Off a terminal, progress is a line log (stderr is a pipe here).
    assert!(err(&o).contains("gma: fitting ja+mech: about"), "{}", err(&o));
    // Generous: the limit stops the search; what remains is reading, one final evaluation, writing.
    assert!(took < Duration::from_secs(30), "took {took:?} with --time-limit 2");
}

#[test]
fn loop_files_honour_max_samples_and_a_byte_order_mark() {
    let dir = tempfile::tempdir().unwrap();
    let mut bom = b"\xEF\xBB\xBF".to_vec();
    bom.extend(oe_loop());
    let f = write(dir.path(), "excel.csv", &bom);
    let o = gma(&["fit", "--model", "ja", "--effort", "0.2", "--max-samples", "50", "--json", path(&f)]);
    assert!(o.status.success(), "{}", err(&o));
    assert!(err(&o).contains("100 points; using the first 50"), "{}", err(&o));
}

#[test]
fn what_record_and_simulate_write_fit_reads_back() {
    use gma_control::telemetry::{Frame, MAX_ENCODED};
    let dir = tempfile::tempdir().unwrap();
    // A 150 kHz tick (6.6666667 µs) and a frame with an absurd value in the middle.
    let mut bytes = Vec::new();
    for seq in 0..400u32 {
        let d = if seq == 200 { 3e38 } else { 10.0 + (seq as f32 * 0.05).sin() };
        let f = Frame {
            seq,
            reference_um: 1.0,
            command_v: 0.5,
            current_a: (seq as f32 * 0.05).sin(),
            displacement_um: d,
            faults: 0,
        };
        let mut buf = [0u8; MAX_ENCODED];
        let n = f.encode(&mut buf);
        bytes.extend_from_slice(&buf[..n]);
    }
    let stream = write(dir.path(), "s.bin", &bytes);
    let out = dir.path().join("rec.csv");
    let o = gma(&["record", "--json", "--tick-s", "6.6666667e-6", "-i", path(&stream), "-o", path(&out)]);
    assert!(o.status.success(), "{}", err(&o));
    let j = json(&o);
    assert_eq!(j["invalid"], 1, "the 3e38 µm frame must be counted, not written: {j}");
    for f in j["files"].as_array().unwrap() {
        let r = host_sim::recording::Recording::read(Path::new(f.as_str().unwrap())).unwrap();
        // Time is written to 0.1 % of the step (`recording::time_decimals`).
        assert!((r.dt_s() / 6.6666667e-6 - 1.0).abs() < 1e-3, "{}", r.dt_s());
    }
}

#[test]
fn a_reader_that_goes_away_ends_the_command_quietly() {
    // `gma mechanics | head -1`, with the reader gone before the first line.
    let mut child =
        Command::new(GMA).arg("mechanics").stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success() && !err(&o).contains("panicked"), "{:?}: {}", o.status, err(&o));
}

/// Every continuous parameter fixed (displacement and loop fits, with and without an integer
/// delay to scan): nothing to search, so the fit scores the set as it stands — no panic in the
/// optimiser or the covariance, exit 0, the same NRMSE `compare` gives.
#[test]
fn a_fit_with_every_parameter_fixed_scores_the_set_as_it_stands() {
    let dir = tempfile::tempdir().unwrap();
    let rec = write(dir.path(), "rec.csv", &recording());
    let fix = [
        "--fix",
        "linear.offset_a_per_m",
        "--fix",
        "linear.susceptibility",
        "--fix",
        "magnetostriction.lambda_s",
    ];
    for model in ["linear", "linear+delay"] {
        let mut args = vec!["fit", "--model", model, "--json", path(&rec)];
        args.extend(fix);
        let o = gma(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{model}: {err}");
        assert!(!err.contains("panicked"), "{model}: {err}");
        let j = json(&o);
        let fitted = j["nrmse_fit"].as_f64().unwrap();
        assert!(fitted.is_finite() && fitted > 0.0, "{model}: {j}");
        if model == "linear" {
            let c = json(&gma(&[
                "compare",
                "--model",
                "linear",
                "--json",
                "--out-dir",
                path(dir.path()),
                path(&rec),
            ]));
            assert!((c["nrmse"].as_f64().unwrap() - fitted).abs() < 1e-9, "fit {fitted} vs compare {c}");
        }
    }
    let lp = write(dir.path(), "loop.csv", &oe_loop());
    let mut args = vec!["fit", "--model", "ja", "--json", path(&lp)];
    for p in ["ja.ms_a_per_m", "ja.a_a_per_m", "ja.alpha", "ja.k_a_per_m", "ja.c"] {
        args.extend(["--fix", p]);
    }
    let o = gma(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "loop fit: {err}");
}
