//! Workbench speed (issue 4 targets), release build: `cargo bench -p host-sim --bench workbench`
//! (on 2 cores: `taskset -c 0,1 cargo bench …`). Wall-clock figures of whole jobs, each run once
//! or a few times — too long for criterion's repeated sampling.
//!
//! - plant simulation speed, × real time (target ≥ 500×), on 2 s and 30 s records, with distributed
//!   (the default) and lumped eddy currents
//!   (`cargo bench -p host-sim --bench workbench -- plant` runs this part alone);
//! - `fit --model ja+mech` on 4 files of 30 000 samples (target ≤ 20 s);
//! - a J–A fit to a 300-point magnetization loop (target ≤ 10 s);
//! - `diagnose` on every hidden-effect case (target ≤ 60 s each);
//! - `diagnose --model ja+mech` on 8 files of 30 000 samples, 4 fit and 4 validation, of a rig
//!   with eddy currents (issue 13 target ≤ 30 s; `-- diagnose8` runs this part alone, `-- fit4`
//!   the `ja+mech` fit alone; `BENCH_PROGRESS=1` in front shows its phases on stderr).

use std::time::Instant;

use host_sim::excitation::Excitation;
use host_sim::fit::{fit, FitOptions};
use host_sim::plant::{EddyModel, Plant};
use host_sim::{cases, diagnose};
use model_core::{ActuatorParams, ModelSpec};

fn main() {
    println!("rayon threads: {}", rayon::current_num_threads());
    // Plant: ja+eddy+mech+amp at 10 kHz, integrated at 20 kHz, a 100 Hz sine.
    let mut plant = Plant::new(ModelSpec::parse("amp+eddy+ja+mech").unwrap(), ActuatorParams::TERFENOL_DEMO);
    let exc = Excitation::Sine { freq_hz: 100.0, amplitude: 1.0, bias: 0.0 };
    for eddy in [EddyModel::Distributed, EddyModel::Lumped] {
        plant.eddy = eddy;
        for secs in [2.0, 30.0] {
            let mut best = f64::MAX;
            for seed in 0..5 {
                let t = Instant::now();
                let rec = plant.record("bench", &exc, secs, seed).unwrap();
                assert_eq!(rec.len(), (secs * 1e4) as usize);
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!(
                "| plant amp+eddy+ja+mech ({eddy:?} eddy), {secs} s at 10 kHz (×2 oversampling) | {:.1} ms | {:.0}× real time |",
                best * 1e3,
                secs / best
            );
        }
    }
    let only = |part: &str| std::env::args().any(|a| a == part);
    if only("plant") {
        return; // `cargo bench -p host-sim --bench workbench -- plant`: the plant alone
    }
    if !only("fit4") {
        diagnose_eight_files();
        if only("diagnose8") {
            return;
        }
    }

    // Fit ja+mech on 4 files × 30 000 samples.
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.ja.a_a_per_m = 7012.0;
    p.ja.k_a_per_m = 4283.0;
    p.mech.natural_frequency_hz = 1300.0;
    let rig = Plant::new(ModelSpec::parse("ja+mech").unwrap(), p);
    let files: Vec<_> = [(20.0, 2.0), (80.0, 1.5), (250.0, 1.0), (600.0, 0.8)]
        .iter()
        .enumerate()
        .map(|(i, &(f, a))| {
            rig.record(
                &format!("f{i}"),
                &Excitation::Sine { freq_hz: f, amplitude: a, bias: 0.2 },
                3.0,
                i as u64,
            )
            .unwrap()
        })
        .collect();
    let t = Instant::now();
    let r = fit(
        ModelSpec::parse("ja+mech").unwrap(),
        &ActuatorParams::TERFENOL_DEMO,
        &files,
        FitOptions::default(),
    )
    .unwrap();
    println!(
        "| fit ja+mech, 4 files × {} samples | {:.1} s | {} evaluations, fit NRMSE {:.3} % |",
        files[0].len(),
        t.elapsed().as_secs_f64(),
        r.evaluations,
        r.fit.mean_nrmse() * 100.0
    );
    if only("fit4") {
        return;
    }

    // A J–A major loop of 300 points (Terfenol-D, 0.2 % noise), all five parameters.
    {
        use host_sim::loop_fit::{self, LoopModel};
        use host_sim::loops::{LoopChannel, LoopFile};
        let truth = [6.0e5, 6512.0, -0.035, 4000.0, 0.2];
        let h: Vec<f64> =
            (0..=300).map(|k| 1.2e5 * (2.0 * std::f64::consts::PI * k as f64 / 300.0).cos()).collect();
        let model = LoopModel::JilesAtherton(model_core::magnetization::JaVariant::Bulk);
        let m = loop_fit::run(model, &truth, &h, 1.2e5).unwrap();
        let f = LoopFile { name: "bench".into(), h, value: m, channel: LoopChannel::Magnetization };
        let t = Instant::now();
        let r = loop_fit::fit(
            model,
            &[f],
            &ActuatorParams::TERFENOL_DEMO,
            host_sim::search::SearchOptions::default(),
        )
        .unwrap();
        println!(
            "| loop fit J–A, 300-point major loop | {:.1} s | {} evaluations, NRMSE {:.3} % |",
            t.elapsed().as_secs_f64(),
            r.evaluations,
            r.nrmse[0] * 100.0
        );
    }

    // Diagnose every hidden-effect case.
    for case in cases::all() {
        let (fit_files, val_files) = case.recordings(7).unwrap();
        let t = Instant::now();
        let d = diagnose::diagnose(case.model, &case.init, &fit_files, &val_files, FitOptions::default())
            .unwrap();
        println!(
            "| diagnose `{}` (hidden: {}) | {:.1} s | verdict {:?} |",
            case.model,
            case.name,
            t.elapsed().as_secs_f64(),
            d.verdict
        );
    }
}

/// `diagnose --model ja+mech` on 8 files × 30 000 samples (3 s at 10 kHz each): a SIMULATED rig
/// with distributed eddy currents, sines of 20–600 Hz for fitting and others for validation.
fn diagnose_eight_files() {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.mech.natural_frequency_hz = 1300.0;
    let rig = Plant::new(ModelSpec::parse("eddy+ja+mech").unwrap(), p);
    let record = |name: String, f: f64, a: f64, seed: u64| {
        rig.record(&name, &Excitation::Sine { freq_hz: f, amplitude: a, bias: 0.2 }, 3.0, seed).unwrap()
    };
    let fit_files: Vec<_> = [(20.0, 2.0), (80.0, 1.5), (250.0, 1.0), (600.0, 0.8)]
        .iter()
        .enumerate()
        .map(|(i, &(f, a))| record(format!("fit{i}"), f, a, i as u64))
        .collect();
    let val_files: Vec<_> = [(35.0, 1.8), (140.0, 1.2), (400.0, 0.9), (900.0, 0.6)]
        .iter()
        .enumerate()
        .map(|(i, &(f, a))| record(format!("val{i}"), f, a, 10 + i as u64))
        .collect();
    let t = Instant::now();
    let d = diagnose::diagnose(
        ModelSpec::parse("ja+mech").unwrap(),
        &ActuatorParams::TERFENOL_DEMO,
        &fit_files,
        &val_files,
        FitOptions { progress: std::env::var_os("BENCH_PROGRESS").is_some(), ..FitOptions::default() },
    )
    .unwrap();
    println!(
        "| diagnose `ja+mech`, 4 fit + 4 validation files × {} samples (hidden: eddy_current) | {:.1} s | verdict {:?} |",
        fit_files[0].len(),
        t.elapsed().as_secs_f64(),
        d.verdict
    );
}
