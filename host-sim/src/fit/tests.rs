use super::*;
use crate::channels::{FLUX_SCALE_RANGE, MU0};
use crate::score::{flux_fit, temperature_fit};
use crate::simulated::Simulation;
use crate::simulation::{field_reach, preisach_plane_advice, run_model, simulate, InitialState};

/// The seen mode is written into the parameters by these names: a registry rename must not
/// switch it off unnoticed.
#[test]
fn the_mode_parameters_are_the_registrys() {
    let names: Vec<&str> =
        free_params(ModelSpec::LINEAR.with(model_core::Effect::MechanicalDynamics), Given::default())
            .iter()
            .map(|f| f.name())
            .collect();
    assert!(names.contains(&MODE_FREQUENCY) && names.contains(&MODE_DAMPING), "{names:?}");
}

#[test]
fn a_preisach_plane_far_wider_than_the_fields_reached_is_said() {
    let mut rec = Recording::with_time("r.csv", 4, 1e-4);
    rec.current_a = Some(vec![0.0, 1.0, -2.0, 0.5]);
    let mut p = ActuatorParams::TERFENOL_DEMO;
    (p.coil.turns_per_m, p.coil.bias_a_per_m) = (10_000.0, 5_000.0);
    // |5 000 + 10 000 i|: the largest field is at i = −2 A.
    assert_eq!(field_reach(&p, std::slice::from_ref(&rec)), Some(15_000.0));
    let preisach = ModelSpec::parse("preisach").expect("spec");
    p.preisach.h_max_a_per_m = 80_000.0;
    match preisach_plane_advice(preisach, &p, std::slice::from_ref(&rec)) {
        Some(Warning::PreisachPlaneWide { advised, .. }) => assert_eq!(advised, 1.25 * 15_000.0),
        other => panic!("{other:?}"),
    }
    assert_eq!(preisach_plane_advice(ModelSpec::parse("ja").expect("spec"), &p, &[rec.clone()]), None);
    p.preisach.h_max_a_per_m = 20_000.0;
    assert_eq!(preisach_plane_advice(preisach, &p, &[rec.clone()]), None);
    // Without a current, the command through the amplifier's gain.
    (rec.current_a, rec.command_v, p.amp.gain_a_per_v) = (None, Some(vec![0.0, 3.0]), 2.0);
    assert_eq!(field_reach(&p, &[rec]), Some(65_000.0));
}
use crate::excitation::Excitation;
use crate::plant::Plant;

/// Levenberg–Marquardt minimises the sum of squares of [`projected_residuals`], the simplex
/// and every report [`projected_cost`]: they must be the same number, with the current
/// channel scored, coil heating split off and λ_s solved or kept, away from the truth.
#[test]
fn the_residuals_square_to_the_cost() {
    let spec = ModelSpec::parse("amp+ja+mech+thermal").unwrap();
    let truth = ActuatorParams::TERFENOL_DEMO;
    let rig = Plant::new(spec, truth);
    let files: Vec<Recording> = [(30.0, 1.5, 0), (120.0, 1.0, 1)]
        .iter()
        .map(|&(f, a, seed)| {
            rig.record(
                &format!("f{seed}"),
                &Excitation::Sine { freq_hz: f, amplitude: a, bias: 0.2 },
                0.1,
                seed,
            )
            .unwrap()
        })
        .collect();
    assert!(files.iter().all(|r| r.current_a.is_some()), "the rig logs the current");
    // A search coil on the second file: its block enters the cost like the others.
    let mut files = files;
    let sim = simulate(spec, &truth, &files[1]).unwrap();
    files[1].flux_density_t = Some(
        sim.field_a_per_m
            .iter()
            .zip(&sim.magnetization_a_per_m)
            .map(|(h, m)| MU0 * (h + 1.1 * m) - 0.4)
            .collect(),
    );
    let prepared = prepare(spec, &files).unwrap();
    let mut off = truth;
    off.ja.a_a_per_m *= 1.3;
    off.mech.natural_frequency_hz *= 0.8;
    for lambda in [Some(LAMBDA_RANGE), None] {
        let cost = projected_cost(spec, &off, &prepared, lambda);
        let r = projected_residuals(spec, &off, &prepared, lambda).expect("the model runs");
        let squares: f64 = r.iter().map(|x| x * x).sum();
        assert!(cost > 1e-6, "the point is off the truth (cost {cost})");
        assert!((squares - cost).abs() <= 1e-9 * cost, "λ_s {lambda:?}: Σr² = {squares}, cost = {cost}");
    }
    let blocks = residual_blocks(spec, &off, &prepared).unwrap();
    assert_eq!(blocks.iter().map(|b| b.0).collect::<Vec<_>>(), [1, 0, 1, 0, 2], "blocks and their unknowns");
}

/// A run through the memo is the run without it, bit for bit: after a change of the
/// mechanical stages only (kept magnetic run reused) and after a change of each magnetic
/// stage (a new run; reusing the kept one would leave the displacement as it was).
#[test]
fn runs_through_the_magnetic_memo_are_the_runs_without_it() {
    let spec = ModelSpec::parse("amp+eddy+ja+mech+thermal+delay+aftereffect").unwrap();
    let truth = ActuatorParams::TERFENOL_DEMO;
    let rec = Plant::new(spec, truth)
        .record("f", &Excitation::Sine { freq_hz: 150.0, amplitude: 1.0, bias: 0.2 }, 0.05, 3)
        .unwrap();
    let memo = MagneticMemo::default();
    let bare = Prepared::new(spec, &rec).unwrap().starting(InitialState::Excursion(4000.0));
    let kept = Prepared { memo: Some(&memo), ..bare.clone() };
    let mut mechanical = truth;
    mechanical.mech.natural_frequency_hz *= 0.9;
    mechanical.mech.damping_ratio *= 1.2;
    mechanical.magnetostriction.lambda_s *= 1.1;
    mechanical.thermal.tau_s *= 0.5;
    mechanical.delay_samples = 1.5;
    let magnetic: [fn(&mut ActuatorParams); 5] = [
        |p| p.ja.k_a_per_m *= 1.05,
        |p| p.ja.alpha *= 0.9,
        |p| p.eddy_tau_s *= 2.0,
        |p| p.amp.tau_s *= 2.0,
        |p| p.aftereffect.fraction *= 2.0,
    ];
    let bits = |sim: &Simulation| -> Vec<u64> {
        [&sim.displacement_um, &sim.current_a, &sim.field_a_per_m, &sim.magnetization_a_per_m]
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect()
    };
    let mut sets = vec![truth, mechanical];
    for change in magnetic {
        let mut p = mechanical;
        change(&mut p);
        sets.push(p);
    }
    let first = bits(&run_model(spec, &truth, &kept, true).unwrap());
    for p in &sets {
        let through = bits(&run_model(spec, p, &kept, true).unwrap());
        let without = bits(&run_model(spec, p, &bare, true).unwrap());
        assert!(through == without, "{p:?}: the memo changed the run");
        assert!(p == &truth || through != first, "{p:?}: the change did not show in the run");
    }
    // The mechanical change reused the kept run; each magnetic one kept a run of its own.
    assert_eq!(memo.kept(), 1 + magnetic.len());
}

/// The sensor delay is a time: a parameter set counts it in periods of its own `dt_s`, and a
/// recording logged at another rate gets the same delay in seconds. Two recordings of one
/// rig (0.4 ms delay) at 10 kHz and 4 kHz are both explained by the 10 kHz set; read as
/// samples of each file (0.4 ms at 10 kHz, 1 ms at 4 kHz) the slower one is not.
#[test]
fn a_delay_counted_at_the_parameters_rate_holds_at_another_rate() {
    let spec = ModelSpec::parse("ja+delay").unwrap();
    let at = |dt_s: f32, delay_samples: f32| ActuatorParams {
        dt_s,
        delay_samples,
        ..ActuatorParams::TERFENOL_DEMO
    };
    let record = |p: ActuatorParams| {
        let mut rig = Plant::new(spec, p);
        rig.noise_um = 0.0;
        rig.record("d", &Excitation::Sine { freq_hz: 60.0, amplitude: 1.0, bias: 0.2 }, 0.1, 0).unwrap()
    };
    let fast = record(at(1e-4, 4.0));
    let slow = record(at(2.5e-4, 1.6));
    let nrmse = |p: ActuatorParams, rec: &Recording| {
        evaluate(spec, &p, std::slice::from_ref(rec)).unwrap().mean_nrmse()
    };
    let (on_fast, on_slow) = (nrmse(at(1e-4, 4.0), &fast), nrmse(at(1e-4, 4.0), &slow));
    let as_file_samples = nrmse(at(2.5e-4, 4.0), &slow);
    // The 4 kHz file against its own rig's parameters: the model's discretisation error there.
    let own = nrmse(at(2.5e-4, 1.6), &slow);
    assert!(
        on_fast < 2e-3 && (on_slow - own).abs() < 1e-5,
        "one set for both rates: {on_fast}, {on_slow} ({own})"
    );
    assert!(as_file_samples > 5.0 * on_slow.max(1e-3), "4 samples of the 4 kHz file: {as_file_samples}");
    // A delay the faster recording's line cannot hold is refused, naming the file and the times.
    let e = evaluate(spec, &at(2.5e-4, 40.0), std::slice::from_ref(&fast)).unwrap_err().to_string();
    assert!(e.contains("sensor delay") && e.contains("10.000 ms") && e.contains("100.0 samples"), "{e}");
}

/// The flux density's scale and zero come out in closed form: exact for a flux the model
/// explains up to them, the NRMSE of what it does not explain otherwise.
#[test]
fn the_flux_fit_solves_the_magnetization_scale_and_the_integrators_zero() {
    let h: Vec<f64> = (0..400).map(|k| 20e3 + 15e3 * (k as f64 * 0.05).sin()).collect();
    let m: Vec<f64> = h.iter().map(|h| 7e5 * (h / 9e3).tanh()).collect();
    let b: Vec<f64> = h.iter().zip(&m).map(|(h, m)| MU0 * (h + 0.85 * m) + 0.12).collect();
    let (f, model) = flux_fit(&b, &h, &m);
    assert!((f.scale - 0.85).abs() < 1e-9 && (f.offset_t - 0.12).abs() < 1e-9, "{f:?}");
    assert!(f.nrmse < 1e-9 && model.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-9));
    // What the model lacks stays in the residual: M three samples late.
    let late: Vec<f64> = (0..400usize).map(|k| m[k.saturating_sub(3)]).collect();
    let (g, _) = flux_fit(&b, &h, &late);
    assert!(g.nrmse > 1e-3, "{g:?}");
    // A flux that does not follow M at all: the scale stops at its range, never negative.
    let upside_down: Vec<f64> = b.iter().map(|v| -v).collect();
    assert_eq!(flux_fit(&upside_down, &h, &m).0.scale, FLUX_SCALE_RANGE.0);
}

/// The logged temperature's ambient comes out in closed form; without a rise (a model
/// without coil heating) the model is that constant and the whole variation is error.
#[test]
fn the_temperature_fit_solves_the_ambient() {
    let rise: Vec<f64> = (0..500).map(|k| 0.4 * (1.0 - (-(k as f64) / 300.0).exp())).collect();
    let logged: Vec<f64> = rise.iter().map(|r| 23.5 + r).collect();
    let (f, model) = temperature_fit(&logged, &rise);
    assert!((f.ambient_c - 23.5).abs() < 1e-9 && f.nrmse < 1e-9, "{f:?}");
    assert!(model.iter().zip(&logged).all(|(a, b)| (a - b).abs() < 1e-9));
    let (none, flat) = temperature_fit(&logged, &[]);
    let mean = logged.iter().sum::<f64>() / logged.len() as f64;
    assert!((none.ambient_c - mean).abs() < 1e-9 && flat.iter().all(|t| *t == none.ambient_c));
    assert!(none.nrmse > 0.2, "{none:?}");
}
