//! Identification quality (issue 4, as in 001 §4): Jiles–Atherton parameters recovered from
//! noisy SIMULATED recordings, starting from a different parameter set. Prints the parameter
//! errors and the number of model evaluations (001 used 600 generations × 100 individuals).

use host_sim::excitation::Excitation;
use host_sim::fit::{fit, FitOptions};
use host_sim::plant::Plant;
use model_core::magnetization::JaParams;
use model_core::{ActuatorParams, ModelSpec};

#[test]
fn jiles_atherton_parameters_are_recovered_from_noisy_loops() {
    let mut truth = ActuatorParams::TERFENOL_DEMO;
    truth.ja = JaParams {
        ms_a_per_m: 6.0e5,
        a_a_per_m: 7012.0,
        alpha: -0.01,
        k_a_per_m: 4283.0,
        c: 0.18,
        ..JaParams::TSMA_ROD1_002
    };
    truth.magnetostriction.lambda_s = 1.2e-3;
    let mut plant = Plant::new(ModelSpec::parse("ja").unwrap(), truth);
    plant.noise_um = 0.1; // ~0.1–0.2 % of the stroke
    let sine = |f, a, b| Excitation::Sine { freq_hz: f, amplitude: a, bias: b };
    // Major loop, a biased minor loop and a small loop: different field ranges pin a, k, α, c.
    let files: Vec<_> =
        [(sine(5.0, 2.5, 0.0), 0.4), (sine(10.0, 0.8, 1.0), 0.2), (sine(8.0, 0.4, -0.6), 0.25)]
            .iter()
            .enumerate()
            .map(|(i, (e, d))| plant.record(&format!("loop{i}.csv"), e, *d, 11 + i as u64).unwrap())
            .collect();
    let start = ActuatorParams::TERFENOL_DEMO; // a 6512, α −0.035, k 4000, c 0.2, λ_s 1e-3
    let res =
        fit(ModelSpec::parse("ja").unwrap(), &start, &files, FitOptions { seed: 3, ..Default::default() })
            .unwrap();
    let p = &res.params;
    let rel = |got: f32, want: f32| ((got - want) / want).abs();
    let errors = [
        ("ja.a_a_per_m", rel(p.ja.a_a_per_m, truth.ja.a_a_per_m)),
        ("ja.k_a_per_m", rel(p.ja.k_a_per_m, truth.ja.k_a_per_m)),
        ("ja.c", rel(p.ja.c, truth.ja.c)),
        ("magnetostriction.lambda_s", rel(p.magnetostriction.lambda_s, truth.magnetostriction.lambda_s)),
    ];
    println!("fit NRMSE {:.3} %, {} model evaluations", res.fit.mean_nrmse() * 100.0, res.evaluations);
    for (n, e) in &errors {
        println!("  {n:28} relative error {:.2} %", e * 100.0);
    }
    println!(
        "  ja.alpha                     {} (true {}), absolute error {:.4}",
        p.ja.alpha,
        truth.ja.alpha,
        (p.ja.alpha - truth.ja.alpha).abs()
    );
    for (n, e) in errors {
        assert!(e < 0.02, "{n}: relative error {:.1} %", e * 100.0);
    }
    assert!((p.ja.alpha - truth.ja.alpha).abs() < 0.002, "alpha {}", p.ja.alpha);
    assert!(res.fit.mean_nrmse() < 0.005);
}
