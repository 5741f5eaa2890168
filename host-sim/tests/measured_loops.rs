//! Loop fits on MEASURED B–H loops from public peer repositories (tests/data/measured-loops/:
//! soft and grain-oriented steel, three MnZn ferrites, an amorphous alloy, two AlNiCo magnets;
//! provenance and licences in its README). These are the evidence of physics: none of them was
//! made by our code. Every loop is fitted with `gma fit --model ja` in each J–A variant, with
//! `gma fit --model preisach`, and from each published coefficient set; the table prints what
//! was measured. Asserted: no fit ends worse than its start (in particular a published set), no
//! loop that a published set fits is refused, and issue 13's targets for the law that fits each
//! loop best (median ≤ 2 %, none > 5 % NRMSE). The square AlNiCo loops need the Preisach law:
//! J–A would need α·M_s/(3a) > 1 there, which every fit refuses.

mod common;

use std::path::{Path, PathBuf};

use common::{err, gma};
use host_sim::params::to_toml;
use model_core::magnetization::{JaParams, JaVariant};
use model_core::ActuatorParams;
use serde_json::Value;

fn folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/measured-loops")
}

/// A parameter file: the demo set with `ja` replaced (only the J–A table matters to a loop fit)
/// and its M_s in every table that holds one (a set whose strain's M_s is not its law's is
/// refused).
fn params_file(dir: &Path, name: &str, ja: JaParams) -> PathBuf {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.ja = ja;
    p.anhysteretic.ms_a_per_m = ja.ms_a_per_m;
    p.preisach.ms_a_per_m = ja.ms_a_per_m;
    p.magnetostriction.ms_a_per_m = ja.ms_a_per_m;
    let path = dir.join(name);
    std::fs::write(&path, to_toml(&p, "measured_loops test").unwrap()).unwrap();
    path
}

/// What `gma fit --model ja|preisach --json` said: (fit NRMSE, start NRMSE, start refused?) or the
/// refusal's message.
struct Fit {
    nrmse: f64,
    start_nrmse: Option<f64>,
    start_refused: Option<String>,
}

fn fit(loop_file: &Path, params: &Path) -> Result<Fit, String> {
    fit_law("ja", loop_file, params)
}

/// As [`fit`], with the magnetization law `law` (`ja`, `preisach`).
fn fit_law(law: &str, loop_file: &Path, params: &Path) -> Result<Fit, String> {
    let o = gma(&[
        "fit",
        "--model",
        law,
        "--params",
        params.to_str().unwrap(),
        "--json",
        loop_file.to_str().unwrap(),
    ]);
    let e = err(&o);
    assert!(!e.contains("panicked"), "{}: panic\n{e}", loop_file.display());
    if !o.status.success() {
        return Err(e.lines().find(|l| l.contains("gma: error")).unwrap_or(&e).to_string());
    }
    let j: Value = serde_json::from_slice(&o.stdout).unwrap();
    let nrmse = j["nrmse_fit"].as_f64().unwrap();
    assert!(nrmse.is_finite());
    Ok(Fit {
        nrmse,
        start_nrmse: j["start"]["nrmse"].as_f64(),
        start_refused: j["start"]["refused"].as_str().map(str::to_string),
    })
}

/// `gma compare` NRMSE of a parameter set on a loop (no refusal: it scores any valid set).
fn compare(loop_file: &Path, params: &Path) -> f64 {
    let o = gma(&[
        "compare",
        "--model",
        "ja",
        "--params",
        params.to_str().unwrap(),
        "--json",
        loop_file.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", err(&o));
    serde_json::from_slice::<Value>(&o.stdout).unwrap()["nrmse"].as_f64().unwrap()
}

/// Median and largest of NRMSEs, in %.
fn median_max_pct(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
    (median * 100.0, v[n - 1] * 100.0)
}

fn pct(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{:.2}", v * 100.0))
}

#[test]
fn measured_loops_in_every_variant_and_from_published_sets() {
    let index: toml::Table =
        toml::from_str(&std::fs::read_to_string(folder().join("index.toml")).unwrap()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut problems = Vec::new();
    let mut best_per_loop = Vec::new();
    let mut default_per_loop = Vec::new();
    let mut wins = vec![0usize; JaVariant::ALL.len()];
    println!(
        "\n{:44} {:>8} {:>8} {:>8} {:>8} {:>10} {:>9} {:>8} {:>14} {:>10}",
        "material (MEASURED loop)",
        "bulk %",
        "ja1986 %",
        "szewczyk %",
        "ungated %",
        "preisach %",
        "best J–A",
        "refused?",
        "published %",
        "from pub. %"
    );
    for entry in index["loop"].as_array().unwrap() {
        let file = folder().join(entry["file"].as_str().unwrap());
        let material = entry["material"].as_str().unwrap();
        // Every variant from the default start.
        let mut by_variant = Vec::new();
        let mut refused = Vec::new();
        for v in JaVariant::ALL {
            let p = params_file(
                dir.path(),
                &format!("{v}.toml"),
                JaParams { variant: v, ..JaParams::TSMA_ROD1_002 },
            );
            match fit(&file, &p) {
                Ok(f) => {
                    if let Some(s) = f.start_nrmse {
                        if f.nrmse > s {
                            problems.push(format!(
                                "{material} ({v}): fit {:.4} % worse than its start {:.4} %",
                                f.nrmse * 100.0,
                                s * 100.0
                            ));
                        }
                    }
                    by_variant.push(Some(f.nrmse));
                }
                Err(e) => {
                    refused.push(format!("{v}: {e}"));
                    by_variant.push(None);
                }
            }
        }
        let best = by_variant
            .iter()
            .enumerate()
            .filter_map(|(i, e)| e.map(|e| (i, e)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        // A variant "fits best" only when the others are more than 2 % (relative) worse: closer
        // than that the data do not tell them apart (c → 0 makes bulk and ja1986 one equation).
        let tied: Vec<&str> = match best {
            Some((_, e)) => JaVariant::ALL
                .iter()
                .zip(&by_variant)
                .filter(|(_, v)| v.is_some_and(|v| v <= 1.02 * e))
                .map(|(v, _)| v.name())
                .collect(),
            None => Vec::new(),
        };
        if let Some((i, _)) = best {
            if tied.len() == 1 {
                wins[i] += 1;
            }
        }
        // The Preisach law from the same start (its own table of the demo set).
        let preisach = match fit_law(
            "preisach",
            &file,
            &params_file(dir.path(), "preisach.toml", JaParams::TSMA_ROD1_002),
        ) {
            Ok(f) => {
                if let Some(s) = f.start_nrmse.filter(|s| f.nrmse > *s) {
                    problems.push(format!(
                        "{material} (preisach): fit {:.4} % worse than its start {:.4} %",
                        f.nrmse * 100.0,
                        s * 100.0
                    ));
                }
                Some(f.nrmse)
            }
            Err(e) => {
                problems.push(format!("{material}: the preisach fit failed: {e}"));
                None
            }
        };
        if let Some(e) = best.map(|b| b.1).into_iter().chain(preisach).min_by(f64::total_cmp) {
            best_per_loop.push(e);
        }
        if let Some(e) = by_variant[0] {
            default_per_loop.push(e);
        }
        // The published set: its own score, and a fit started from it.
        let (mut published, mut from_published) = (None, None);
        if let Some(pubset) = entry.get("published") {
            let num = |k: &str| pubset[k].as_float().unwrap() as f32;
            let variant = JaVariant::from_name(pubset["variant"].as_str().unwrap()).unwrap();
            let ja = JaParams {
                ms_a_per_m: num("ms_a_per_m"),
                a_a_per_m: num("a_a_per_m"),
                alpha: num("alpha"),
                k_a_per_m: num("k_a_per_m"),
                c: num("c"),
                variant,
            };
            let p = params_file(dir.path(), "published.toml", ja);
            published = Some(compare(&file, &p));
            match fit(&file, &p) {
                Ok(f) => {
                    match (&f.start_refused, f.start_nrmse) {
                        (None, Some(s)) => {
                            if f.nrmse > s {
                                problems.push(format!(
                                    "{material}: the fit from the published set ended at {:.4} %, worse than its {:.4} %",
                                    f.nrmse * 100.0,
                                    s * 100.0
                                ));
                            }
                            if !refused.is_empty() {
                                problems.push(format!(
                                    "{material}: refused although a published set fits: {refused:?}"
                                ));
                            }
                        }
                        (Some(why), _) => println!("  ({material}: published set refused as a start: {why})"),
                        (None, None) => {}
                    }
                    from_published = Some(f.nrmse);
                }
                Err(e) => {
                    problems.push(format!("{material}: the fit from the published set was refused: {e}"))
                }
            }
        }
        println!(
            "{:44} {:>8} {:>8} {:>8} {:>8} {:>10} {:>9} {:>8} {:>14} {:>10}",
            material,
            pct(by_variant[0]),
            pct(by_variant[1]),
            pct(by_variant[2]),
            pct(by_variant[3]),
            pct(preisach),
            if tied.len() > 1 { "tie".to_string() } else { tied.first().unwrap_or(&"—").to_string() },
            if refused.is_empty() {
                "no".to_string()
            } else {
                format!("{} of {}", refused.len(), JaVariant::ALL.len())
            },
            pct(published),
            pct(from_published),
        );
        for r in &refused {
            println!("    refused: {r}");
        }
    }
    let (med_default, max_default) = median_max_pct(&mut default_per_loop);
    let (med_best, max_best) = median_max_pct(&mut best_per_loop);
    println!(
        "default J–A variant (bulk): median {med_default:.2} %, max {max_default:.2} %; best law per loop (J–A \
         variants, Preisach): median {med_best:.2} %, max {max_best:.2} % — issue 13's targets: median ≤ 2 %, none > 5 %"
    );
    if med_best > 2.0 || max_best > 5.0 {
        problems.push(format!(
            "best law per loop: median {med_best:.2} %, max {max_best:.2} % (targets 2 %, 5 %)"
        ));
    }
    println!(
        "variant fitting best by > 2 %: {}; the other loops are ties",
        JaVariant::ALL.iter().zip(&wins).map(|(v, n)| format!("{v} {n}")).collect::<Vec<_>>().join(", ")
    );
    assert!(problems.is_empty(), "{problems:#?}");
}

/// Our `szewczyk` variant against the JAmodel code's OWN SIMULATION of two ferrite loops at its
/// published sets (tests/data/jamodel-simulated/: another author's implementation, not a
/// measurement). The same equation integrated two ways should agree to within integration
/// error (0.5 % NRMSE); the other variants, at the same coefficients, are different equations.
#[test]
fn the_szewczyk_variant_reproduces_the_jamodel_code_at_its_published_sets() {
    let index: toml::Table =
        toml::from_str(&std::fs::read_to_string(folder().join("index.toml")).unwrap()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let simulated = folder().join("../jamodel-simulated");
    for (entry, sim) in [
        ("jamodel-mit/ferrite-mnzn-a2018-jamodel.csv", "ferrite-mnzn-a2018-simulated-by-jamodel.csv"),
        ("jamodel-mit/ferrite-mnzn-hp-jamodel.csv", "ferrite-mnzn-hp-simulated-by-jamodel.csv"),
    ] {
        let loops = index["loop"].as_array().unwrap();
        let pubset = loops.iter().find(|l| l["file"].as_str() == Some(entry)).unwrap()["published"].clone();
        assert_eq!(pubset["variant"].as_str(), Some("szewczyk"));
        let num = |k: &str| pubset[k].as_float().unwrap() as f32;
        let mut by_variant = Vec::new();
        for variant in JaVariant::ALL {
            let ja = JaParams {
                ms_a_per_m: num("ms_a_per_m"),
                a_a_per_m: num("a_a_per_m"),
                alpha: num("alpha"),
                k_a_per_m: num("k_a_per_m"),
                c: num("c"),
                variant,
            };
            let p = params_file(dir.path(), &format!("{variant}.toml"), ja);
            by_variant.push(compare(&simulated.join(sim), &p));
        }
        println!(
            "{sim}: NRMSE against the JAmodel code's loop: {}",
            JaVariant::ALL
                .iter()
                .zip(&by_variant)
                .map(|(v, e)| format!("{v} {:.3} %", e * 100.0))
                .collect::<Vec<_>>()
                .join(", ")
        );
        assert!(by_variant[2] < 0.005, "{sim}: szewczyk {:.3} %", by_variant[2] * 100.0);
        assert!(
            by_variant[0] > 4.0 * by_variant[2] && by_variant[1] > 4.0 * by_variant[2],
            "{sim}: {by_variant:?}"
        );
    }
}
