//! What goes where: an output path `-` is standard output (stdout then holds only the data, the
//! text goes to stderr), and the text of fit, compare and diagnose opens with the result and its
//! heaviest warning.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::{err, refused};

/// Runs `gma` in `dir` (where a file named `-` would appear).
fn gma_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gma")).current_dir(dir).args(args).output().expect("run gma")
}

/// `gma` in `dir` with stdout and stderr into one stream, as a terminal shows them.
fn gma_merged(dir: &Path, args: &[&str]) -> String {
    let log = dir.join("merged.log");
    let f = std::fs::File::create(&log).unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_gma"))
        .current_dir(dir)
        .args(args)
        .stdout(f.try_clone().unwrap())
        .stderr(f)
        .status()
        .unwrap();
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{text}");
    // Without the notes and the progress lines (`gma: fitting …`): the result and its warnings.
    let kept = |l: &&str| !l.starts_with("gma: ") || l.starts_with("gma: warning: ");
    text.lines().filter(kept).map(|l| format!("{l}\n")).collect()
}

fn ok(o: &Output) -> &Output {
    assert!(o.status.success(), "{}", err(o));
    o
}

/// A short SIMULATED `ja` recording `rig.csv` in `dir`.
fn rig(dir: &Path) {
    ok(&gma_in(dir, &["simulate", "--model", "ja", "--duration-s", "0.04", "--out", "rig.csv"]));
}

#[test]
fn dash_as_an_output_is_standard_output_with_the_text_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    rig(d);
    // simulate: the CSV on stdout, byte for byte the file's.
    let o = gma_in(d, &["simulate", "--model", "ja", "--duration-s", "0.04", "--out", "-"]);
    assert_eq!(ok(&o).stdout, std::fs::read(d.join("rig.csv")).unwrap());
    assert!(err(&o).contains("to standard output"), "{}", err(&o));
    // fit --params-out -: the parameter file on stdout, the fit's text on stderr.
    let o = gma_in(d, &["fit", "--model", "ja", "--params-out", "-", "rig.csv"]);
    let toml_text = String::from_utf8(ok(&o).stdout.clone()).unwrap();
    let table: toml::Table = toml_text.parse().unwrap_or_else(|e| panic!("{e}\n{toml_text}"));
    assert!(table.contains_key("ja") && table.contains_key("magnetostriction"), "{toml_text}");
    assert!(err(&o).contains("mean fit NRMSE") && err(&o).contains("parameters written to standard output"));
    ok(&gma_in(d, &["fit", "--model", "ja", "--params-out", "p.toml", "rig.csv"]));
    let from_file: toml::Table = std::fs::read_to_string(d.join("p.toml")).unwrap().parse().unwrap();
    assert_eq!(table, from_file, "the same parameter file either way");
    // compare --out-csv -: the time series on stdout, the summary on stderr.
    let o = gma_in(d, &["compare", "--model", "ja", "--out-dir", "plots", "--out-csv", "-", "rig.csv"]);
    ok(&gma_in(d, &["compare", "--model", "ja", "--out-dir", "plots", "--out-csv", "t.csv", "rig.csv"]));
    assert_eq!(ok(&o).stdout, std::fs::read(d.join("t.csv")).unwrap());
    assert!(err(&o).contains("mean NRMSE") && err(&o).contains("time series written to standard output"));
    // report -o -: the one page on stdout.
    let o = gma_in(d, &["report", "--model", "ja", "-o", "-", "rig.csv"]);
    let page = String::from_utf8(ok(&o).stdout.clone()).unwrap();
    assert!(page.starts_with("<!doctype html>") && page.trim_end().ends_with("</html>"), "{}", &page[..200]);
    assert!(err(&o).contains("report written to standard output"), "{}", err(&o));
    assert!(!d.join("-").exists(), "a file named `-` was written");
}

#[test]
fn dash_with_json_or_for_a_folder_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    rig(d);
    for (args, option) in [
        (&["simulate", "--out", "-", "--json"][..], "--out -"),
        (&["fit", "--model", "ja", "--params-out", "-", "--json", "rig.csv"][..], "--params-out -"),
        (&["compare", "--model", "ja", "--out-csv", "-", "--json", "rig.csv"][..], "--out-csv -"),
        (&["report", "--model", "ja", "-o", "-", "--json", "rig.csv"][..], "--out -"),
    ] {
        let o = gma_in(d, args);
        refused(&o, &[option, "--json"], &args.join(" "));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object on stdout");
        assert!(
            j["error"]["message"].as_str().unwrap().contains("standard output carries the --json object"),
            "{j}"
        );
    }
    for (args, option) in [
        (&["compare", "--model", "ja", "--out-dir", "-", "rig.csv"][..], "--out-dir -"),
        (&["report", "--model", "ja", "--params-out-dir", "-", "rig.csv"][..], "--params-out-dir -"),
        (&["demo", "--out-dir", "-"][..], "--out-dir -"),
        (&["record", "-i", "rig.csv", "-o", "-"][..], "--out -"),
    ] {
        refused(&gma_in(d, args), &[option, "a single document"], &args.join(" "));
    }
    let left: Vec<_> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, ["rig.csv"], "nothing written");
}

/// The first lines say the result (the fit's NRMSE, the verdict) and its heaviest doubt: here
/// the displacement read in the wrong unit (µm as nm), which the strain-scale warning names,
/// ahead of the correlated pairs (which the same fit also warns of).
#[test]
fn text_opens_with_the_result_and_a_unit_warning_before_correlations() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    rig(d);
    ok(&gma_in(
        d,
        &["simulate", "--model", "ja", "--freq-hz", "20", "--duration-s", "0.1", "--out", "rig2.csv"],
    ));
    let nm = "displacement_um=displacement_um:nm";
    let fit = gma_merged(d, &["fit", "--model", "ja", "--column", nm, "rig.csv", "rig2.csv"]);
    let lines: Vec<&str> = fit.lines().collect();
    assert!(lines[0].starts_with("model `ja`") && lines[0].contains("mean fit NRMSE"), "{fit}");
    // The unit doubt: the displacement's scale against the model's before the fit, or the
    // fitted strain's against the materials' after it; both name the reading.
    let unit_doubt = |line: &str| {
        line.starts_with("gma: warning: ")
            && (line.contains("the range of magnetostrictive materials")
                || line.contains("reads 1000× small"))
    };
    assert!(unit_doubt(lines[1]), "{fit}");
    // A correlation note, where the fit has one, comes after it.
    let unit = fit.find("the range of magnetostrictive materials").unwrap();
    if let Some(correlated) = fit.find("are correlated") {
        assert!(unit < correlated, "{fit}");
    }
    let compare = gma_merged(d, &["compare", "--model", "ja", "--out-dir", "plots", "rig.csv"]);
    let first = compare.lines().next().unwrap_or_default();
    assert!(first.starts_with("model `ja`: mean NRMSE"), "{compare}");
    let diagnose = gma_merged(d, &["diagnose", "--model", "ja", "--column", nm, "rig.csv", "rig2.csv"]);
    let lines: Vec<&str> = diagnose.lines().collect();
    assert!(lines[0].starts_with("verdict: "), "{diagnose}");
    assert!(lines.iter().any(|l| l.starts_with("model `ja`: fit NRMSE")), "{diagnose}");
    let first_warning = lines.iter().find(|l| l.starts_with("gma: warning: ")).unwrap();
    assert!(unit_doubt(first_warning), "the unit doubt first: {diagnose}");
}
