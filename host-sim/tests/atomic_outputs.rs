//! Outputs are written to a temporary file and renamed: a run killed at any moment leaves the
//! previous file intact or the complete new one, never a truncated file under the final name.

use std::process::{Command, Stdio};
use std::time::Instant;

const GMA: &str = env!("CARGO_BIN_EXE_gma");

#[test]
fn a_killed_simulate_never_leaves_a_truncated_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rig.csv");
    let args = ["simulate", "--duration-s", "60", "--out", out.to_str().unwrap()];
    // One full run to learn how long it takes (computing, then writing ~18 MB).
    let t0 = Instant::now();
    assert!(Command::new(GMA).args(args).stderr(Stdio::null()).status().unwrap().success());
    let full = t0.elapsed();
    let complete = std::fs::read(&out).unwrap();
    let lines = complete.iter().filter(|b| **b == b'\n').count();
    assert_eq!(lines, 600_001);
    let old = b"time_s,current_A,displacement_um\n0,0,0\n0.0001,0,0\n0.0002,0,0\n";
    let (mut kept_old, mut complete_new) = (0, 0);
    // Kill it at 20 moments spread over (and a little beyond) a run.
    for k in 0..20u32 {
        std::fs::write(&out, old).unwrap();
        let mut child = Command::new(GMA).args(args).stderr(Stdio::null()).spawn().unwrap();
        std::thread::sleep(full.mul_f64(0.1 + 1.5 * k as f64 / 20.0));
        let _ = child.kill(); // SIGKILL: no destructors, no cleanup
        let _ = child.wait();
        let now = std::fs::read(&out).unwrap();
        if now == old {
            kept_old += 1;
        } else {
            assert_eq!(now.len(), complete.len(), "kill {k}: a truncated file under the final name");
            assert_eq!(now, complete, "kill {k}: a different file under the final name");
            complete_new += 1;
        }
    }
    println!(
        "20 kills over {:.0} ms: {kept_old} left the old file, {complete_new} the complete new one",
        full.as_secs_f64() * 1e3
    );
    // Leftovers of killed writes are hidden `.gma-*.partial` files, never the result's name.
    for e in std::fs::read_dir(dir.path()).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().to_string();
        assert!(name == "rig.csv" || (name.starts_with(".gma-") && name.ends_with(".partial")), "{name}");
    }
}

/// A short SIMULATED recording `good.csv` in `dir`.
fn simulated(dir: &std::path::Path) -> std::path::PathBuf {
    let good = dir.join("good.csv");
    let o = Command::new(GMA)
        .args(["simulate", "--model", "ja", "--duration-s", "0.04", "--out", good.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success());
    good
}

#[test]
fn a_failed_run_leaves_the_previous_parameter_file_and_report_alone() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulated(dir.path());
    let bad = dir.path().join("bad.csv");
    let mut text = std::fs::read_to_string(&good).unwrap();
    text.push_str("0.0400,abc,1\n");
    std::fs::write(&bad, text).unwrap();
    let params = dir.path().join("p.toml");
    let report = dir.path().join("r.html");
    std::fs::write(&params, "# previous parameters\n").unwrap();
    std::fs::write(&report, "<p>previous report</p>").unwrap();
    for args in [
        vec![
            "fit",
            "--model",
            "ja",
            "--params-out",
            params.to_str().unwrap(),
            good.to_str().unwrap(),
            bad.to_str().unwrap(),
        ],
        vec![
            "report",
            "--model",
            "ja",
            "--out",
            report.to_str().unwrap(),
            good.to_str().unwrap(),
            bad.to_str().unwrap(),
        ],
    ] {
        let o = Command::new(GMA).args(&args).output().unwrap();
        assert!(!o.status.success());
    }
    assert_eq!(std::fs::read_to_string(&params).unwrap(), "# previous parameters\n");
    assert_eq!(std::fs::read_to_string(&report).unwrap(), "<p>previous report</p>");
}

/// `compare` makes its `--out-dir` (with any missing parents) before it reads the inputs; when
/// an input is bad it removes what it made and still empty, and keeps a folder that existed.
#[test]
fn a_failed_compare_leaves_no_empty_plot_folder() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulated(dir.path());
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "time_s,current_A,displacement_um\n0,1,x\n").unwrap();
    let existing = dir.path().join("existing");
    std::fs::create_dir(&existing).unwrap();
    let nested = dir.path().join("new").join("plots");
    for out in [&nested, &existing] {
        let o = Command::new(GMA)
            .args(["compare", "--model", "ja", "--out-dir", out.to_str().unwrap()])
            .args([good.to_str().unwrap(), bad.to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stderr).contains("bad.csv:2:"));
    }
    assert!(!dir.path().join("new").exists(), "the folders compare made are left behind");
    assert!(existing.is_dir() && std::fs::read_dir(&existing).unwrap().next().is_none());
    let o = Command::new(GMA)
        .args(["compare", "--model", "ja", "--out-dir", nested.to_str().unwrap(), good.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(nested.join("good-loop.svg").is_file());
}

/// Large files stream: reading is bounded by `--max-samples`, not by the file. A 60 MB CSV is
/// read to its end with a small window; the old whole-file reader needed over 100 MB for it.
/// (A 1.1 GB file: 31 MB with `--max-samples 200000`, 270 MB at the default 2 000 000, before
/// compare had its residual and frequency analysis, which adds about 110 MB at 2 million samples.)
#[test]
fn a_large_csv_streams_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.csv");
    let o = Command::new(GMA)
        .args(["simulate", "--duration-s", "200", "--out", big.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success());
    let size_mb = std::fs::metadata(&big).unwrap().len() as f64 / 1e6;
    let o = Command::new("/usr/bin/time")
        .args(["-f", "peak_rss_kb=%M", GMA, "compare", "--model", "ja+mech", "--max-samples", "20000"])
        .args(["--out-dir", dir.path().join("plots").to_str().unwrap(), big.to_str().unwrap()])
        .output()
        .expect("GNU time (/usr/bin/time; scripts/setup-firmware-toolchain installs it)");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("2000000 samples; using the first 20000"), "{err}");
    let kb: f64 = err.split("peak_rss_kb=").nth(1).and_then(|s| s.trim().parse().ok()).expect("peak RSS");
    println!("compare on a {size_mb:.0} MB CSV, 20 000-sample window: peak RSS {:.1} MB", kb / 1e3);
    assert!(size_mb > 55.0);
    assert!(kb / 1e3 < 30.0, "peak RSS {:.1} MB", kb / 1e3);
}

/// The start time of process `pid` in clock ticks after boot (`/proc/PID/stat`, field 22), as
/// gma names its partial files.
#[cfg(target_os = "linux")]
fn start_time(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    stat.rsplit_once(')').unwrap().1.split_whitespace().nth(19).unwrap().parse().unwrap()
}

/// A run killed between writing and renaming leaves its partial; the next write into that folder
/// removes it. Never a live writer's partial (this test process plays one), never a file that is
/// not a gma partial, never a partial of a dead writer that was touched just now.
#[cfg(target_os = "linux")]
#[test]
fn the_next_write_removes_a_killed_runs_partial_and_keeps_a_live_ones() {
    let dir = tempfile::tempdir().unwrap();
    // A pid that has certainly ended: a child, waited for (so reaped).
    let mut child = Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let me = std::process::id();
    let an_hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    let file = |name: &str, old: bool| {
        let path = dir.path().join(name);
        let f = std::fs::File::create(&path).unwrap();
        if old {
            f.set_modified(an_hour_ago).unwrap();
        }
        name.to_string()
    };
    let stale = file(&format!(".gma-{dead}-12345-aB3xY9.partial"), true);
    let stale_png = file(&format!(".gma-{dead}-12345-Qw9Er7.partial.png"), true);
    // This process's pid with another start time: the pid reused, the writer gone.
    let reused = file(&format!(".gma-{me}-{}-Zx8Cv6.partial", start_time(me) + 1), true);
    let kept = [
        file(&format!(".gma-{me}-{}-Lm4Nb2.partial", start_time(me)), true), // a live writer
        file(&format!(".gma-{dead}-12345-Fresh1.partial"), false),           // touched just now
        file(".gma-aB3xY9.partial", true),                                   // an older gma's
        file(&format!(".gma-{dead}-12345-aB3xY9.partial.bak"), true),        // not a partial name
        file(&format!("gma-{dead}-12345-aB3xY9.partial"), true),             // not hidden
    ];
    let out = dir.path().join("rig.csv");
    let o = Command::new(GMA)
        .args(["simulate", "--model", "ja", "--duration-s", "0.01", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let left: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    for gone in [&stale, &stale_png, &reused] {
        assert!(!left.contains(gone), "{gone} was left: {left:?}");
    }
    for stays in &kept {
        assert!(left.contains(stays), "{stays} was removed: {left:?}");
    }
    assert_eq!(left.len(), kept.len() + 1, "{left:?}");
}
