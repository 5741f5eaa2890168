//! Magnetization-loop fits (issue 7): loops generated from known J–A parameters of three kinds
//! of material, full loops and single descending branches, with noise, fitted back.

use host_sim::loop_fit::{self, LoopModel};
use host_sim::loops::{self, LoopChannel, LoopFile};
use host_sim::search::SearchOptions;
use model_core::magnetization::JaVariant;
use model_core::ActuatorParams;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

struct Material {
    name: &'static str,
    /// M_s, a, α, k, c.
    truth: [f64; 5],
    h_max: f64,
}

const MATERIALS: [Material; 3] = [
    Material { name: "soft iron-like", truth: [1.3e6, 150.0, 2e-4, 120.0, 0.2], h_max: 3000.0 },
    Material { name: "Terfenol-D (002 rod 1)", truth: [6.0e5, 6512.0, -0.035, 4000.0, 0.2], h_max: 1.2e5 },
    Material { name: "permanent-magnet-like", truth: [9.0e5, 4.0e4, 0.05, 3.0e5, 0.05], h_max: 1.2e6 },
];

fn loop_file(m: &Material, branch_only: bool, seed: u64) -> LoopFile {
    // A full major loop (cosine: starts and ends at +H_max, denser near the tips) or one
    // descending branch, 300 points.
    let n = 300;
    let h: Vec<f64> = (0..=n)
        .map(|k| {
            let u = k as f64 / n as f64;
            m.h_max
                * if branch_only {
                    (std::f64::consts::PI * u).cos()
                } else {
                    (2.0 * std::f64::consts::PI * u).cos()
                }
        })
        .collect();
    let clean = loop_fit::run(LoopModel::JilesAtherton(JaVariant::Bulk), &m.truth, &h, m.h_max).unwrap();
    let range = clean.iter().fold(f64::MIN, |a, &v| a.max(v)) - clean.iter().fold(f64::MAX, |a, &v| a.min(v));
    let noise = Normal::new(0.0, 0.002 * range).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let value = clean.iter().map(|v| v + noise.sample(&mut rng)).collect();
    LoopFile {
        name: format!("{}{}", m.name, if branch_only { " (branch)" } else { "" }),
        h,
        value,
        channel: LoopChannel::Magnetization,
    }
}

#[test]
fn jiles_atherton_is_recovered_from_loops_of_three_materials() {
    // 0.2 % noise; the fits reach that floor (NRMSE ≈ 0.19 %) on every case.
    let names = ["M_s", "a", "alpha", "k", "c"];
    let mut failures = Vec::new();
    for m in &MATERIALS {
        for branch in [false, true] {
            let f = loop_file(m, branch, 5);
            let t = std::time::Instant::now();
            let fit = loop_fit::fit(
                LoopModel::JilesAtherton(JaVariant::Bulk),
                std::slice::from_ref(&f),
                &ActuatorParams::TERFENOL_DEMO,
                SearchOptions::default(),
            )
            .unwrap();
            let v = fit.values();
            let errs: Vec<f64> = v.iter().zip(&m.truth).map(|(g, w)| ((g - w) / w).abs()).collect();
            println!(
                "{:40} NRMSE {:.3} %, {} evaluations, {:.1} s; errors: {}{}",
                f.name,
                fit.nrmse[0] * 100.0,
                fit.evaluations,
                t.elapsed().as_secs_f64(),
                names
                    .iter()
                    .zip(&errs)
                    .map(|(n, e)| format!("{n} {:.1} %", e * 100.0))
                    .collect::<Vec<_>>()
                    .join(", "),
                if fit.warnings.is_empty() {
                    String::new()
                } else {
                    format!(
                        " — {}",
                        fit.warnings.iter().map(|w| w.to_string()).collect::<Vec<_>>().join("; ")
                    )
                }
            );
            if fit.nrmse[0] > 0.01 {
                failures.push(format!("{}: NRMSE {:.2} %", f.name, fit.nrmse[0] * 100.0));
            }
            // Identifiable: M_s and a from any branch, k from a full loop (both branches pin the
            // coercivity). c and α trade off against k and a within the noise of one loop, and k
            // from a single branch is weakly determined: reported above, not asserted.
            let identifiable: &[usize] = if branch { &[0, 1] } else { &[0, 1, 3] };
            {
                for &i in identifiable {
                    if errs[i] > 0.05 {
                        failures.push(format!("{}: {} off by {:.1} %", f.name, names[i], errs[i] * 100.0));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The laws without hysteresis fit loop files too (`gma fit --model linear|anhysteretic` on a
/// loop panicked on J–A's mean-field check until 2026-11-24). A Langevin curve made by our own
/// loop model (plumbing, not physics): the anhysteretic law recovers its M_s and a, and the
/// linear law fits it, worse, without failing.
#[test]
fn the_laws_without_hysteresis_fit_a_loop() {
    let truth = [7.6e5, 7000.0];
    let h: Vec<f64> =
        (0..=300).map(|k| 6.0e4 * (2.0 * std::f64::consts::PI * k as f64 / 300.0).cos()).collect();
    let value = loop_fit::run(LoopModel::Anhysteretic, &truth, &h, 6.0e4).unwrap();
    let f = LoopFile { name: "langevin".into(), h, value, channel: LoopChannel::Magnetization };
    let fit = |model| {
        loop_fit::fit(
            model,
            std::slice::from_ref(&f),
            &ActuatorParams::TERFENOL_DEMO,
            SearchOptions::default(),
        )
        .unwrap()
    };
    let an = fit(LoopModel::Anhysteretic);
    for (got, want) in an.values().iter().zip(truth) {
        assert!(((got - want) / want).abs() < 0.01, "anhysteretic: {:?} for {truth:?}", an.values());
    }
    let lin = fit(LoopModel::Linear);
    assert!(
        lin.nrmse[0].is_finite() && lin.nrmse[0] > 10.0 * an.nrmse[0],
        "{} vs {}",
        lin.nrmse[0],
        an.nrmse[0]
    );
}

/// What a loop fit reports (`params` in the JSON, the values its NRMSE was scored at) is what
/// `--params-out` writes: the parameter set holds f32, and the model runs on f32 values, so the
/// reported values are those, not the search's f64 between them.
#[test]
fn a_loop_fit_reports_the_values_it_writes() {
    let m = &MATERIALS[0];
    let f = loop_file(m, false, 3);
    let model = LoopModel::JilesAtherton(JaVariant::Bulk);
    let opts = SearchOptions { effort: 0.2, ..SearchOptions::default() };
    let fit = loop_fit::fit(model, std::slice::from_ref(&f), &ActuatorParams::TERFENOL_DEMO, opts).unwrap();
    assert!(!fit.start.kept, "{:?}", fit.start);
    let written = model.values_of(&fit.apply_to(&ActuatorParams::TERFENOL_DEMO));
    assert_eq!(fit.values(), written, "reported vs written");
    let again = loop_fit::run(model, &written, &f.h, m.h_max).unwrap();
    assert_eq!(fit.nrmse[0], host_sim::score::nrmse(&f.value, &again), "the NRMSE of the written set");
}

/// A unit written after a `/`, `_` or space is read as in brackets: the same loop in Oe and T
/// under each header form gives the same SI points (a header `H/Oe` read as A/m would shrink
/// every field 79.6×).
#[test]
fn a_unit_outside_brackets_is_converted_as_in_brackets() {
    let dir = tempfile::tempdir().unwrap();
    let rows: String =
        (0..20).map(|k| format!("{},{}\n", 10.0 * k as f64 - 100.0, 0.05 * k as f64 - 0.4)).collect();
    let read = |header: &str| {
        let path = dir.path().join("loop.csv");
        std::fs::write(&path, format!("{header}\n{rows}")).unwrap();
        loops::read(&path).unwrap_or_else(|e| panic!("{header}: {e:#}"))
    };
    let brackets = read("H(Oe),B(T)");
    assert!((brackets.h[0] + 100.0 * 1e3 / (4.0 * std::f64::consts::PI)).abs() < 1e-9, "{}", brackets.h[0]);
    for header in ["H/Oe,B/T", "H_Oe,B_T", "H Oe,B T", "H / Oe,B / T", "h/Oe,b/T"] {
        let other = read(header);
        assert_eq!((&other.h, &other.value), (&brackets.h, &brackets.value), "{header}");
    }
}

/// Rows `H,M` of a counterclockwise loop of a ferromagnet-like shape, ±2 kA/m, M up to `m_max`,
/// branches `coercive` [A/m] either side of H = 0: the falling branch, then the rising one.
fn tanh_loop_rows(m_max: f64, coercive: f64) -> Vec<String> {
    let branch = |sign: f64| {
        (0..=100).map(move |k| {
            let h = sign * (2000.0 - 40.0 * k as f64);
            format!("{h},{}", m_max * ((h + sign * coercive) / 500.0).tanh())
        })
    };
    branch(1.0).chain(branch(-1.0)).collect()
}

/// `gma fit --model ja --json` of the loop file `path`, which must succeed: its JSON.
fn fit_loop_json(path: &std::path::Path) -> serde_json::Value {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_gma"))
        .args(["fit", "--model", "ja", "--json", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The warnings of `gma fit --model ja` on `rows` (`H,M` in A/m) written to `path`.
fn fit_warnings(path: &std::path::Path, rows: &[String]) -> Vec<String> {
    std::fs::write(path, format!("H(A/m),M(A/m)\n{}\n", rows.join("\n"))).unwrap();
    warnings(&fit_loop_json(path))
}

fn warnings(j: &serde_json::Value) -> Vec<String> {
    j["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap().to_string()).collect()
}

/// A loop whose magnetization is far below the smallest M_s the models hold (a weak sample, or
/// M in kA/m under an A/m header) is fitted within the models' range and said to be, not
/// answered with the start values at an NRMSE of thousands of per cent; the fit names its J–A
/// form.
#[test]
fn a_weak_loop_is_fitted_within_the_models_range_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("weak.csv");
    std::fs::write(&path, format!("H,M\n{}\n", tanh_loop_rows(1.5, 300.0).join("\n"))).unwrap();
    let j = fit_loop_json(&path);
    assert_eq!(j["ja_variant"], "bulk", "{j:#}");
    assert_eq!(j["start"]["kept"], false, "{j:#}");
    assert!(j["nrmse_fit"].as_f64().unwrap() < 1.0, "{j:#}");
    let w = warnings(&j);
    assert!(
        w.iter()
            .any(|w| w.starts_with("the loop's largest |M| is 1.500e0 A/m, below the smallest saturation")),
        "{w:?}"
    );
    assert!(w.iter().any(|w| w.starts_with("`ms_a_per_m` = 1.0000e3 ended at the edge")), "{w:?}");
}

/// A loop file whose rows run backwards in time traverses its loop clockwise, which no
/// ferromagnet does: said, with the file; in time order nothing is said.
#[test]
fn a_loop_traversed_clockwise_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("loop.csv");
    let said = |rows: &[String]| fit_warnings(&path, rows);
    let rows = tanh_loop_rows(8e5, 300.0);
    let reversed: Vec<String> = rows.iter().rev().cloned().collect();
    let clockwise = |w: &[String]| w.iter().any(|w| w.contains("the loop runs clockwise in the H–M plane"));
    assert!(!clockwise(&said(&rows)), "{:?}", said(&rows));
    // The initial magnetization curve first (0 → +H_max from the demagnetized state), then a
    // narrow loop: counterclockwise still (closed back to the curve's start it read +6 %).
    let virgin: Vec<String> = (0..50)
        .map(|k| 40.0 * k as f64)
        .map(|h| format!("{h},{}", 8e5 * (h / 500.0).tanh()))
        .chain(tanh_loop_rows(8e5, 50.0))
        .collect();
    assert!(!clockwise(&said(&virgin)), "{:?}", said(&virgin));
    let backwards = said(&reversed);
    let named = format!("{}: the loop runs clockwise", path.display());
    assert!(clockwise(&backwards) && backwards.iter().any(|w| w.starts_with(&named)), "{backwards:?}");
    // A whole cycle from mid-branch, closed on its first point (H = 0 on the falling branch):
    // from its first end the path runs 1.5 ranges only, and the reversed file was not said.
    let mid = 50;
    let cycle: Vec<String> = rows[mid..].iter().chain(&rows[..=mid]).cloned().collect();
    assert!(!clockwise(&said(&cycle)), "{:?}", said(&cycle));
    let cycle_reversed: Vec<String> = cycle.iter().rev().cloned().collect();
    assert!(clockwise(&said(&cycle_reversed)), "{:?}", said(&cycle_reversed));
}

/// H written in kA/m under an A/m header: the loop reaches M_s at fields of a few A/m, a J–A fit
/// follows it with a and k of a few A/m at a low NRMSE, and nothing was said. Now said, with
/// the file; the same loop in A/m is not.
#[test]
fn a_loop_with_its_field_in_kilo_amperes_per_metre_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("loop.csv");
    let said = |rows: &[String]| fit_warnings(&path, rows);
    let rows = tanh_loop_rows(8e5, 300.0);
    let in_kilo: Vec<String> = rows
        .iter()
        .map(|r| {
            let (h, m) = r.split_once(',').unwrap();
            format!("{},{m}", h.parse::<f64>().unwrap() / 1000.0)
        })
        .collect();
    let kilo = |w: &[String]| w.iter().any(|w| w.contains("is H in kA/m under an A/m header?"));
    assert!(!kilo(&said(&rows)), "{:?}", said(&rows));
    let w = said(&in_kilo);
    assert!(kilo(&w) && w.iter().any(|w| w.starts_with(&format!("{}: M reaches", path.display()))), "{w:?}");
    // Measured soft magnets (ferrites, steels, an amorphous alloy: M/H up to 5 500) are not asked.
    let measured = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/measured-loops");
    let mut seen = 0;
    for dir in std::fs::read_dir(measured).unwrap().map(|d| d.unwrap().path()).filter(|d| d.is_dir()) {
        for file in std::fs::read_dir(dir).unwrap() {
            let file = file.unwrap().path();
            if file.extension().is_some_and(|e| e == "csv") {
                let o = std::process::Command::new(env!("CARGO_BIN_EXE_gma"))
                    .args(["compare", "--model", "ja", "--json", "--out-dir"])
                    .arg(dir_path(&path))
                    .arg(&file)
                    .output()
                    .unwrap();
                assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
                let w = warnings(&serde_json::from_slice(&o.stdout).unwrap());
                assert!(!kilo(&w), "{}: {w:?}", file.display());
                seen += 1;
            }
        }
    }
    assert!(seen >= 8, "{seen} measured loops");
}

/// A folder beside `path` for plots.
fn dir_path(path: &std::path::Path) -> std::path::PathBuf {
    path.with_file_name("plots")
}
