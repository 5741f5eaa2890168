//! Recordings that read plausibly but are wrong in one way a rig gets wrong (a lone spike, a
//! current clamp on backwards, a reversed search coil, a delay counted at another rate, an
//! amplifier gain no file fitted): each must end in a refusal that names the fix, or a warning,
//! never a plausible figure with exit 0. The files are `gma simulate`'s, edited as the rig
//! would have spoilt them.

use std::path::{Path, PathBuf};

mod common;
use common::{err, gma, refused};

/// `gma simulate` with `args` into `dir/name`; its path.
fn simulate(dir: &Path, name: &str, args: &[&str]) -> String {
    let out = dir.join(name).display().to_string();
    // A name may be written again (the helper serves several rigs): `--overwrite`.
    let mut all = vec!["simulate", "--overwrite", "-o", &out];
    all.extend(args);
    let o = gma(&all);
    assert!(o.status.success(), "simulate {args:?}: {}", err(&o));
    out
}

/// `file` rewritten into `dir/name` with `edit(row index, cells)` applied to each data row
/// (the header kept, or replaced by `header` when given).
fn edited(
    dir: &Path,
    file: &str,
    name: &str,
    header: Option<&str>,
    edit: impl Fn(usize, &mut Vec<String>),
) -> String {
    let text = std::fs::read_to_string(file).unwrap();
    let mut lines = text.lines();
    let first = lines.next().unwrap();
    let mut out = format!("{}\n", header.unwrap_or(first));
    for (k, line) in lines.enumerate() {
        let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
        edit(k, &mut cells);
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    let path: PathBuf = dir.join(name);
    std::fs::write(&path, out).unwrap();
    path.display().to_string()
}

/// The column `name` of `file`'s header.
fn column(file: &str, name: &str) -> usize {
    let text = std::fs::read_to_string(file).unwrap();
    text.lines().next().unwrap().split(',').position(|c| c == name).unwrap_or_else(|| panic!("{name}"))
}

/// `cell` negated (or scaled), as text.
fn scaled(cell: &str, by: f64) -> String {
    format!("{}", cell.parse::<f64>().unwrap() * by)
}

/// `compare --json` on `args`: the JSON, or the run's stderr.
fn compare(args: &[&str]) -> Result<serde_json::Value, String> {
    let mut all = vec!["compare", "--json", "--out-dir"];
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().display().to_string();
    all.push(&out_dir);
    all.extend(args);
    let o = gma(&all);
    if !o.status.success() {
        return Err(err(&o));
    }
    Ok(serde_json::from_slice(&o.stdout).unwrap())
}

fn warnings(j: &serde_json::Value) -> Vec<String> {
    j["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect()
}

/// One probe over-range sample (9999.99 µm) or one dropout to 0 in 5000 set the NRMSE's range:
/// a wrong model read 1 % instead of 15 %, and `diagnose` said nothing was missing. Either is
/// refused, naming the file, the row's time and the value; the same recording without it, and
/// square-wave drives (steps in the current, a displacement that rings after each), are not.
#[test]
fn a_lone_spike_or_dropout_is_refused_naming_its_row() {
    let dir = tempfile::tempdir().unwrap();
    let sine = ["--freq-hz", "200", "--duration-s", "0.5", "--bias", "0.5", "--noise-um", "0.05"];
    let long = simulate(dir.path(), "long.csv", &sine);
    let y = column(&long, "displacement_um");
    compare(&["--model", "ja+mech", &long]).unwrap();
    // The dropout at the displacement's crest (far from 0, changing slowly).
    let text = std::fs::read_to_string(&long).unwrap();
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|c| c.parse().unwrap()).collect()).collect();
    let crest = (1000..rows.len() - 1).max_by(|a, b| rows[*a][y].total_cmp(&rows[*b][y])).unwrap();
    let time = |k: usize| rows[k][0];
    for (name, at, bad) in [("glitch.csv", 2500, "9999.99"), ("dropout.csv", crest, "0")] {
        let f = edited(dir.path(), &long, name, None, |k, c| {
            if k == at {
                c[y] = bad.to_string();
            }
        });
        for cmd in
            [&["compare", "--model", "ja"][..], &["diagnose", "--model", "ja"], &["fit", "--model", "ja"]]
        {
            let mut args = cmd.to_vec();
            args.push(&f);
            let value = format!("`displacement_um` = {bad} in the row at time_s = {}", time(at));
            refused(
                &gma(&args),
                &[&format!("{name}: "), &value, "spike or dropout", "remove the row"],
                cmd[0],
            );
        }
    }
    for model in ["ja+mech", "eddy+ja+mech"] {
        let square = simulate(
            dir.path(),
            "square.csv",
            &[
                "--model",
                model,
                "--waveform",
                "square",
                "--freq-hz",
                "100",
                "--noise-um",
                "0.02",
                "--search-coil",
            ],
        );
        compare(&["--model", model, &square]).unwrap();
    }
}

/// A current clamp on backwards (`current_A` negated) with a bias: the displacement falls as the
/// logged current rises, and the probe was blamed (`--column displacement_um=-displacement_um`),
/// whose fit is poor. The strain is even in the field, so with a bias the negated current puts
/// the operating point on the field's other side: the refusal names the current's fix, and the
/// file read with it scores as the original. A negated displacement is still the probe's.
#[test]
fn a_current_with_the_wrong_sign_is_told_from_a_reversed_probe() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulate(dir.path(), "good.csv", &["--freq-hz", "100", "--bias", "0.5", "--noise-um", "0.02"]);
    let (i, y) = (column(&good, "current_A"), column(&good, "displacement_um"));
    let clamp = edited(dir.path(), &good, "clamp.csv", None, |_, c| c[i] = scaled(&c[i], -1.0));
    let probe = edited(dir.path(), &good, "probe.csv", None, |_, c| c[y] = scaled(&c[y], -1.0));
    let (current_fix, probe_fix) =
        ("`--column current_A=-current_A`", "`--column displacement_um=-displacement_um`");
    let e = compare(&["--model", "ja+mech", &clamp]).unwrap_err();
    refused(&gma(&["compare", "--model", "ja+mech", &clamp]), &["clamp.csv: ", current_fix], "clamp");
    assert!(!e.contains(probe_fix), "{e}");
    let e = compare(&["--model", "ja+mech", &probe]).unwrap_err();
    assert!(e.contains(probe_fix) && !e.contains(current_fix), "{e}");
    let twin = compare(&["--model", "ja+mech", &good]).unwrap()["nrmse"].as_f64().unwrap();
    let fixed = compare(&["--model", "ja+mech", "--column", "current_A=-current_A", &clamp]).unwrap();
    assert!((fixed["nrmse"].as_f64().unwrap() - twin).abs() <= 1e-9 * twin, "{fixed} against {twin}");
}

/// A search coil wound (or its integrator wired) the other way round, or a column of flux
/// linkage N·A·B instead of B: the magnetization scale g sat at its bound unsaid. The reversed
/// coil is refused with the `--column` that negates it; a scale at its bound is a warning.
#[test]
fn a_reversed_search_coil_is_refused_and_a_flux_scale_at_its_bound_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let model = "eddy+ja+mech";
    let args = ["--model", model, "--search-coil", "--freq-hz", "100", "--bias", "0.5", "--noise-um", "0.02"];
    let good = simulate(dir.path(), "sc.csv", &args);
    let b = column(&good, "flux_density_T");
    let reversed = edited(dir.path(), &good, "sc_neg.csv", None, |_, c| c[b] = scaled(&c[b], -1.0));
    let linkage = edited(dir.path(), &good, "sc_wb.csv", None, |_, c| c[b] = scaled(&c[b], 0.01));
    refused(
        &gma(&["compare", "--model", model, &reversed]),
        &["sc_neg.csv: ", "flux density falls", "`--column flux_density_T=-flux_density_T`"],
        "reversed coil",
    );
    let at_bound =
        |j: &serde_json::Value| warnings(j).into_iter().find(|w| w.contains("ended at an end of its range"));
    let j = compare(&["--model", model, &good]).unwrap();
    assert_eq!(at_bound(&j), None, "{j}");
    let j = compare(&["--model", model, &linkage]).unwrap();
    let w = at_bound(&j).unwrap_or_else(|| panic!("no warning: {j}"));
    assert!(w.contains("sc_wb.csv") && w.contains("g = 0.1 ") && w.contains("flux linkage"), "{w}");
}

/// A parameter file whose `dt_s` is not the recording's step, with a sensor delay: the delay
/// keeps its time (`delay_samples` counts periods of `dt_s`, as documented), ten times the
/// recording's here, and the displacement fell against the model, so the probe was blamed. The
/// refusal names `dt_s` and the value that counts the delay in the recording's samples.
#[test]
fn a_delay_counted_at_another_dt_s_is_said_naming_dt_s() {
    let dir = tempfile::tempdir().unwrap();
    let model = "ja+mech+delay";
    let rec = simulate(dir.path(), "rec.csv", &["--model", model, "--freq-hz", "200", "--noise-um", "0.02"]);
    compare(&["--model", model, &rec]).unwrap();
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    assert!(demo.contains("dt_s = 0.0001\n"), "{demo}");
    let p = dir.path().join("p.toml");
    std::fs::write(&p, demo.replace("dt_s = 0.0001\n", "dt_s = 0.001\n")).unwrap();
    let o = gma(&["compare", "--model", model, "--params", &p.display().to_string(), &rec]);
    refused(&o, &["rec.csv: ", "`dt_s` = 0.001", "set `dt_s = 1e-4`"], "dt_s");
    assert!(!err(&o).contains("displacement_um=-displacement_um"), "{}", err(&o));
}

/// A fit on current-driven files left `[amp] gain_a_per_v` at its start value, unmarked, and
/// `compare` on a file that gives the command alone drove the model through it silently. The
/// fit's JSON and parameter file mark it not fitted, and the command-driven compare warns.
#[test]
fn an_amplifier_gain_no_file_fitted_is_marked_and_its_use_said() {
    let dir = tempfile::tempdir().unwrap();
    let rec =
        simulate(dir.path(), "rec.csv", &["--freq-hz", "100", "--duration-s", "0.05", "--noise-um", "0.02"]);
    let p = dir.path().join("p.toml").display().to_string();
    let o = gma(&["fit", "--model", "ja", "--json", "--time-limit", "20", "--params-out", &p, &rec]);
    assert!(o.status.success(), "{}", err(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["not_fitted"], serde_json::json!(["amp.gain_a_per_v"]), "{j}");
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(text.lines().any(|l| l.starts_with("gain_a_per_v = ") && l.contains("# not fitted:")), "{text}");
    // The same file as an amplifier's command at 1 A/V.
    let cmd = edited(dir.path(), &rec, "cmd.csv", Some("time_s,command_V,displacement_um"), |_, _| {});
    let unfitted =
        |j: &serde_json::Value| warnings(j).into_iter().find(|w| w.contains("marks as not fitted"));
    let j = compare(&["--model", "ja", "--params", &p, &cmd]).unwrap();
    let w = unfitted(&j).unwrap_or_else(|| panic!("no warning: {j}"));
    assert!(w.contains("cmd.csv") && w.contains("`amp.gain_a_per_v`"), "{w}");
    // The current-driven file does not use the gain.
    assert_eq!(unfitted(&compare(&["--model", "ja", "--params", &p, &rec]).unwrap()), None);
}

/// A recording cut from a running rig (its drive away from rest at the first sample) was run
/// as if the rig had been off before it: the model's start transient, absent from the data, bent
/// the fit (a mode above Nyquist, the eddy lag at its bound). Every run now starts at rest at
/// the file's first drive, as the rig was: the cut file scores as the whole one does.
#[test]
fn a_recording_cut_from_a_running_rig_starts_where_the_rig_was() {
    let dir = tempfile::tempdir().unwrap();
    let model = "eddy+ja+mech";
    let rec = simulate(
        dir.path(),
        "rec.csv",
        &["--model", model, "--freq-hz", "100", "--bias", "0.5", "--noise-um", "0.02"],
    );
    let whole = compare(&["--model", model, &rec]).unwrap()["nrmse"].as_f64().unwrap();
    let j = compare(&["--model", model, "--trim-start", "0.0023", &rec]).unwrap();
    let cut = j["nrmse"].as_f64().unwrap();
    assert!(cut < 1.5 * whole + 1e-4, "cut {cut} against whole {whole}: {j}");
}

/// The rows of `file` as numbers.
fn rows(file: &str) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(file).unwrap();
    text.lines().skip(1).map(|l| l.split(',').map(|c| c.parse().unwrap()).collect()).collect()
}

/// A probe that drops out for a few samples, or a file whose last row is a spike, set the NRMSE's
/// range as a lone spike does; a probe re-zeroed in the middle of a file steps the displacement
/// where the current does not. Each is refused naming its rows; the file without it is not.
#[test]
fn a_dropped_run_a_spiked_last_row_and_a_re_zeroed_probe_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let sine = ["--freq-hz", "50", "--duration-s", "0.5", "--bias", "0.5", "--noise-um", "0.05"];
    let good = simulate(dir.path(), "good.csv", &sine);
    let y = column(&good, "displacement_um");
    compare(&["--model", "ja+mech", &good]).unwrap();
    let all = rows(&good);
    let crest = (1000..all.len() - 10).max_by(|a, b| all[*a][y].total_cmp(&all[*b][y])).unwrap();
    let last = all.len() - 1;
    let run = edited(dir.path(), &good, "run.csv", None, |k, c| {
        if (crest..crest + 4).contains(&k) {
            c[y] = "0".to_string();
        }
    });
    let end = edited(dir.path(), &good, "end.csv", None, |k, c| {
        if k == last {
            c[y] = "9999.99".to_string();
        }
    });
    // Re-zeroed a third of the way in, by a quarter of the range.
    let span =
        all.iter().map(|r| r[y]).fold(f64::MIN, f64::max) - all.iter().map(|r| r[y]).fold(f64::MAX, f64::min);
    let step_at = all.len() / 3;
    let zeroed = edited(dir.path(), &good, "zeroed.csv", None, |k, c| {
        if k >= step_at {
            c[y] = format!("{}", c[y].parse::<f64>().unwrap() - 0.25 * span);
        }
    });
    let at = |k: usize| format!("time_s = {}", all[k][0]);
    for cmd in [&["compare", "--model", "ja"][..], &["fit", "--model", "ja"]] {
        let with = |f: &str| {
            let mut args = cmd.to_vec();
            args.push(f);
            gma(&args)
        };
        refused(&with(&run), &["run.csv: ", "the 4 rows from", &at(crest), "dropped samples"], cmd[0]);
        refused(&with(&end), &["end.csv: ", "= 9999.99 in the last row", "spike or dropout"], cmd[0]);
        refused(
            &with(&zeroed),
            &["zeroed.csv: ", "steps from", &at(step_at), "re-zeroed", "split the file"],
            cmd[0],
        );
    }
    // At 100 samples a period a quarter of the range is under 20× the mean change around it
    // (a tester's 40 µm re-zero on a 143 µm span went unsaid); it breaks the line its
    // neighbouring changes draw, which the drive's do not.
    let fast = simulate(
        dir.path(),
        "fast.csv",
        &["--freq-hz", "100", "--duration-s", "0.5", "--bias", "0.5", "--noise-um", "0.05"],
    );
    compare(&["--model", "ja+mech", &fast]).unwrap();
    let all = rows(&fast);
    let span =
        all.iter().map(|r| r[y]).fold(f64::MIN, f64::max) - all.iter().map(|r| r[y]).fold(f64::MAX, f64::min);
    let zeroed = edited(dir.path(), &fast, "fast-zeroed.csv", None, |k, c| {
        if k >= step_at {
            c[y] = format!("{}", c[y].parse::<f64>().unwrap() - 0.25 * span);
        }
    });
    refused(
        &gma(&["compare", "--model", "ja", &zeroed]),
        &["fast-zeroed.csv: ", "steps from", &format!("time_s = {}", all[step_at][0]), "re-zeroed"],
        "a re-zeroed probe at 100 samples a period",
    );
}

/// A probe clipped at its range (the displacement held at one value over the top of each
/// period), a current clamp clipped so (the current held while the rod moves) and a file whose current and displacement both read the other way round (with a
/// bias, the strain's curvature tells) are said as warnings that name the cause; a current a
/// thousand times too small (read as mA when it was A) is said with the units to check.
#[test]
fn a_clipped_probe_both_channels_negated_and_a_tiny_current_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulate(
        dir.path(),
        "good.csv",
        &["--freq-hz", "20", "--duration-s", "0.5", "--bias", "0.5", "--noise-um", "0.02"],
    );
    let (i, y) = (column(&good, "current_A"), column(&good, "displacement_um"));
    let all = rows(&good);
    let top = all.iter().map(|r| r[y]).fold(f64::MIN, f64::max);
    let bottom = all.iter().map(|r| r[y]).fold(f64::MAX, f64::min);
    let clip = top - 0.2 * (top - bottom);
    let clipped = edited(dir.path(), &good, "clipped.csv", None, |_, c| {
        if c[y].parse::<f64>().unwrap() > clip {
            c[y] = format!("{clip}");
        }
    });
    // Clipped over the top 4 % only: the current moves less than a quarter of its span in
    // each run (the lab's probe clipped a third of its samples so, unsaid).
    let shallow = top - 0.04 * (top - bottom);
    let grazed = edited(dir.path(), &good, "grazed.csv", None, |_, c| {
        if c[y].parse::<f64>().unwrap() > shallow {
            c[y] = format!("{shallow}");
        }
    });
    let both = edited(dir.path(), &good, "both.csv", None, |_, c| {
        c[i] = scaled(&c[i], -1.0);
        c[y] = scaled(&c[y], -1.0);
    });
    let tiny = edited(dir.path(), &good, "tiny.csv", None, |_, c| c[i] = scaled(&c[i], 1e-3));
    // A current clamp saturating at 80 % of the current's span: the current flat, the rod moving.
    let i_top = all.iter().map(|r| r[i]).fold(f64::MIN, f64::max);
    let i_bottom = all.iter().map(|r| r[i]).fold(f64::MAX, f64::min);
    let i_clip = i_bottom + 0.8 * (i_top - i_bottom);
    let clamp = edited(dir.path(), &good, "clamp.csv", None, |_, c| {
        if c[i].parse::<f64>().unwrap() > i_clip {
            c[i] = format!("{i_clip}");
        }
    });
    let said = |file: &str| warnings(&compare(&["--model", "ja+mech", file]).unwrap()).join("\n");
    let clean = said(&good);
    for needle in ["stays at exactly", "both negated", "the model's"] {
        assert!(!clean.contains(needle), "{needle} on the good file: {clean}");
    }
    let w = said(&clipped);
    assert!(
        w.contains("clipped.csv: `displacement_um` stays at exactly") && w.contains("clipped at its range"),
        "{w}"
    );
    let w = said(&grazed);
    assert!(w.contains("grazed.csv: `displacement_um` stays at exactly"), "{w}");
    let w = said(&clamp);
    assert!(
        w.contains("clamp.csv: `current_A` stays at exactly") && w.contains("current stood still"),
        "{w}"
    );
    let w = said(&both);
    assert!(
        w.contains("both.csv: ") && w.contains("both negated") && w.contains("--column current_A=-current_A"),
        "{w}"
    );
    let w = said(&tiny);
    assert!(
        w.contains("tiny.csv: the displacement's rms spread") && w.contains("more than the model's"),
        "{w}"
    );
}

/// The same delay five times too long at 50 Hz leaves the displacement rising with the model's
/// (no refusal), 20 % off: the delay counted at another rate is said as a warning naming `dt_s`;
/// with the recording's own `dt_s` it is not.
#[test]
fn a_delay_counted_at_another_dt_s_that_still_correlates_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let model = "ja+mech+delay";
    let rec = simulate(dir.path(), "rec.csv", &["--model", model, "--freq-hz", "50", "--noise-um", "0.02"]);
    let demo = toml::to_string(&model_core::ActuatorParams::TERFENOL_DEMO).unwrap();
    let p = dir.path().join("p.toml");
    std::fs::write(&p, demo.replace("dt_s = 0.0001\n", "dt_s = 0.0005\n")).unwrap();
    let w = warnings(&compare(&["--model", model, "--params", &p.display().to_string(), &rec]).unwrap())
        .join("\n");
    assert!(
        w.contains("rec.csv: `delay_samples` = 3 counts periods") && w.contains("set `dt_s = 1e-4`"),
        "{w}"
    );
    let w = warnings(&compare(&["--model", model, &rec]).unwrap()).join("\n");
    assert!(!w.contains("counts periods"), "{w}");
}

/// A file whose samples are reversed under its rising time column: the displacement's loop
/// runs the other way round from the model's, said as a warning; the file as recorded is not.
#[test]
fn a_file_in_reverse_time_order_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulate(
        dir.path(),
        "good.csv",
        &["--freq-hz", "20", "--duration-s", "0.5", "--bias", "0.5", "--noise-um", "0.02"],
    );
    let all = rows(&good);
    let n = all.len();
    let reversed = edited(dir.path(), &good, "reversed.csv", None, |k, c| {
        for (j, cell) in c.iter_mut().enumerate().skip(1) {
            *cell = format!("{}", all[n - 1 - k][j]);
        }
    });
    let said = |file: &str| warnings(&compare(&["--model", "ja+mech", file]).unwrap()).join("\n");
    assert!(!said(&good).contains("runs the other way round"), "{}", said(&good));
    let w = said(&reversed);
    assert!(
        w.contains("reversed.csv: the displacement's loop against `current_A` runs the other way round"),
        "{w}"
    );
}

/// A `gma simulate` recording (20 Hz, 0.5 A bias) with a `temperature_C` column that starts at
/// `first` and creeps up, written as `name`; its path.
fn with_thermometer(dir: &std::path::Path, name: &str, first: f64) -> String {
    let good = simulate(dir, "good.csv", &["--freq-hz", "20", "--duration-s", "0.5", "--bias", "0.5"]);
    let text = std::fs::read_to_string(&good).unwrap();
    let mut out = String::new();
    for (k, line) in text.lines().enumerate() {
        let cell = if k == 0 { "temperature_C".to_string() } else { format!("{}", first + 1e-4 * k as f64) };
        out.push_str(&format!("{line},{cell}\n"));
    }
    let f = dir.join(name);
    std::fs::write(&f, out).unwrap();
    f.display().to_string()
}

/// A coil thermometer logged in °F under `temperature_C` (68 for a 20 °C room): the coil
/// heating's thermal resistance came out 1.8× too large, unsaid. A warning names `°F` and its
/// `--column`; read with it, the file is not doubted.
#[test]
fn a_thermometer_in_fahrenheit_is_said_with_its_unit() {
    let dir = tempfile::tempdir().unwrap();
    let f = with_thermometer(dir.path(), "fahrenheit.csv", 68.0);
    let w = warnings(&compare(&["--model", "ja+mech", &f]).unwrap()).join("\n");
    assert!(w.contains("fahrenheit.csv: `temperature_C` starts at 68") && w.contains(":°F`"), "{w}");
    let w = warnings(
        &compare(&["--model", "ja+mech", "--column", "temperature_C=temperature_C:°F", &f]).unwrap(),
    );
    assert!(!w.join("\n").contains("°F"), "{w:?}");
}

/// Issue 78 item 4: a coil thermometer logged in kelvin under `temperature_C` (295.15 for a 22 °C
/// room): the coil's ambient came out 295.15 °C, unsaid (°F was said). A warning names `K` and
/// its `--column`; read with it, the file is not doubted.
#[test]
fn a_thermometer_in_kelvin_is_said_with_its_unit() {
    let dir = tempfile::tempdir().unwrap();
    let f = with_thermometer(dir.path(), "kelvin.csv", 295.15);
    let w = warnings(&compare(&["--model", "ja+mech", &f]).unwrap()).join("\n");
    assert!(
        w.contains("kelvin.csv: `temperature_C` starts at 295.15") && w.contains("temperature_C:K`"),
        "{w}"
    );
    assert!(w.contains("a room at 22.0 °C logged in kelvin"), "{w}");
    let w =
        warnings(&compare(&["--model", "ja+mech", "--column", "temperature_C=temperature_C:K", &f]).unwrap());
    assert!(!w.join("\n").contains("kelvin"), "{w:?}");
}

/// A command logged in mV beside the logged current, run through an amplifier's model (the
/// command drives it): the current's scale was checked and the command's not, so the fit ran
/// to 25.6 % with its gain at a range end, and the only unit hint asked about the displacement.
/// Refused with the command's unit, as a file without the current column is; a model driven by
/// the current is not troubled by it.
#[test]
fn a_command_in_millivolts_beside_the_current_is_refused_with_its_unit() {
    let dir = tempfile::tempdir().unwrap();
    let good = simulate(dir.path(), "good.csv", &["--model", "amp+ja+mech", "--duration-s", "0.2"]);
    let u = column(&good, "command_V");
    let mv = edited(dir.path(), &good, "mv.csv", None, |_, c| c[u] = scaled(&c[u], 1e3));
    refused(
        &gma(&["compare", "--model", "amp+ja+mech", &mv]),
        &["mv.csv: ", "`command_V` reaches", "--column command_V=command_V:mV"],
        "a command in mV",
    );
    assert!(compare(&["--model", "ja+mech", &mv]).is_ok(), "driven by the current");
}
