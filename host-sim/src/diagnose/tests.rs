use super::candidate::error_cut;
use super::scoring::effect_shows;
use super::signatures::lowpass;
use super::*;
use rand::{Rng, SeedableRng};

/// No verdict after a time limit that left a candidate untested or stopped its refit is
/// "undecided", never "nothing is missing" (a refit stopped at once ends near the baseline
/// and cannot pass: that answer would be the time limit's, not the data's).
#[test]
fn no_verdict_is_undecided_when_the_time_limit_cut_a_candidate() {
    let d = |not_refitted: Vec<Effect>, cut_short: Vec<Effect>| Diagnosis {
        model: "ja".into(),
        nrmse_fit: 0.05,
        nrmse_val: None,
        candidates: Vec::new(),
        verdict: None,
        undistinguished: Vec::new(),
        not_refitted,
        cut_short,
        findings: Vec::new(),
        baseline: None,
        time_limited: true,
        ja_variants: None,
        laws: None,
    };
    assert_eq!(d(vec![], vec![]).no_verdict(), "nothing significant is missing");
    let cut = d(vec![], vec![Effect::EddyCurrent]).to_string();
    assert!(
            cut.starts_with("verdict: undecided — the time limit stopped the refit of `eddy_current` before it converged; raise the time limit (`--time-limit`, Python's `time_limit_s`)"),
            "{cut}"
        );
    let both = d(vec![Effect::MechanicalDynamics], vec![Effect::EddyCurrent]).no_verdict();
    assert!(
        both.contains("left `mechanical_dynamics` untested and stopped the refit of `eddy_current`"),
        "{both}"
    );
}

/// Plumbing, on the model's own data (it proves the wiring, not the physics: the
/// independent rig's suite does that): with `temperature_C` logged, coil heating is judged
/// on the temperature, and named where the model lacks it.
#[test]
fn coil_heating_is_judged_on_a_logged_temperature() {
    let dt = 2e-3;
    let heating = ModelSpec::parse("linear+thermal").unwrap();
    let mut p = model_core::ActuatorParams::TERFENOL_DEMO;
    p.dt_s = dt as f32;
    p.thermal.tau_s = 60.0;
    p.thermal.thermal_resistance_c_per_w = 4.0;
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut file = |name: &str, f_hz: f64, amp_a: f64, secs: f64| {
        let n = (secs / dt) as usize;
        let mut rec = Recording::with_time(name, n, dt);
        let w = 2.0 * std::f64::consts::PI * f_hz * dt;
        rec.current_a = Some((0..n).map(|k| 0.3 + amp_a * (w * k as f64).sin()).collect());
        let (sim, _) = crate::simulation::simulate_drive(
            heating,
            &p,
            &rec,
            crate::simulation::InitialState::Demagnetized,
        )
        .unwrap();
        // Uniform noise: 0.01 µm and 0.02 °C rms.
        let mut noisy = |v: f64, rms: f64| v + rng.random_range(-1.0..1.0) * rms * 3f64.sqrt();
        rec.displacement_um = Some(sim.displacement_um.iter().map(|y| noisy(y + 5.0, 0.01)).collect());
        rec.temperature_c = Some(sim.temperature_rise_c.iter().map(|t| noisy(22.0 + t, 0.02)).collect());
        rec
    };
    let fit_files = vec![file("fit", 2.0, 1.0, 12.0)];
    let val_files = vec![file("val", 3.0, 0.8, 10.0)];
    let d = diagnose(ModelSpec::LINEAR, &p, &fit_files, &val_files, FitOptions::default()).unwrap();
    let c = d.candidates.iter().find(|c| c.effect == Effect::ThermalDrift).unwrap();
    assert_eq!(c.channel, "temperature", "{d}");
    assert_eq!(d.verdict, Some(Effect::ThermalDrift), "{d}");
    assert!(c.nrmse_before > 3.0 * c.nrmse_after, "{d}");
    // Without the log it is judged on the displacement, as before.
    let unlogged = |files: &[Recording]| -> Vec<Recording> {
        files.iter().cloned().map(|r| Recording { temperature_c: None, ..r }).collect()
    };
    let d =
        diagnose(ModelSpec::LINEAR, &p, &unlogged(&fit_files), &unlogged(&val_files), FitOptions::default())
            .unwrap();
    let c = d.candidates.iter().find(|c| c.effect == Effect::ThermalDrift).unwrap();
    assert_eq!(c.channel, "displacement", "{d}");
}

/// A channel some files log and others not is said, naming the files without it (the
/// diagnosis then judged on the displacement without a word); none when all or none log it.
#[test]
fn a_channel_some_files_lack_is_said_with_those_files() {
    let file = |name: &str, flux: bool| {
        let mut r = Recording::with_time(name, 10, 1e-4);
        r.current_a = Some(vec![0.0; 10]);
        r.flux_density_t = flux.then(|| vec![0.0; 10]);
        r
    };
    let said = Measured::partly(&[file("a", true), file("b", true)], &[file("v", false)]);
    assert_eq!(said.len(), 1, "{said:?}");
    assert!(said[0].starts_with("flux_density_T: logged in some files but not in v:"), "{said:?}");
    assert!(Measured::partly(&[file("a", true)], &[file("v", true)]).is_empty());
    assert!(Measured::partly(&[file("a", false)], &[file("v", false)]).is_empty());
}

#[test]
fn required_wins_is_the_one_sided_sign_test_at_five_percent() {
    // Below five files no count is significant: all must improve.
    for n in 1..=5 {
        assert_eq!(required_wins(n), n, "n = {n}");
    }
    // P(≥ 5 of 6) = 7/64 > 5 %, P(6 of 6) = 1/64; P(≥ 7 of 8) = 9/256 ≤ 5 % < P(≥ 6 of 8).
    assert_eq!(required_wins(6), 6);
    assert_eq!(required_wins(8), 7);
    assert_eq!(required_wins(10), 9);
    // What the "no candidate passes" finding says: all of up to seven files.
    assert_eq!(all_must_improve_up_to(), 7);
}

fn candidate(effect: Effect, cut: f64, r2: f64, delta_bic: f64, n_eff: f64) -> Candidate {
    Candidate {
        effect,
        channel: "displacement",
        score: 0.5,
        evidence: String::new(),
        nrmse_before: 0.03,
        nrmse_after: 0.03 / cut,
        evidence_r2: r2,
        files_improved: 4,
        files_scored: 4,
        files_showing: 4,
        files_improved_showing: 4,
        files_deciding: 4,
        files_improved_deciding: 4,
        held_out: true,
        delta_bic,
        n_eff,
        per_file_after: vec![0.03 / cut; 4],
        refit: None,
    }
}

/// The verdict among candidates the data cannot tell apart is a property of the set, not of
/// the order they arrive in: R² within their significance (3.84/N_eff = 0.4 %) leave it to
/// ΔBIC, whatever order the cuts put them in. (A pairwise "R² if they differ, else ΔBIC"
/// picked `sensor_delay` in one order and `eddy_current` in another.)
#[test]
fn the_choice_among_undistinguished_candidates_does_not_depend_on_their_order() {
    let set = [
        candidate(Effect::EddyCurrent, 2.02, 0.300, 10.0, 1000.0),
        candidate(Effect::MechanicalDynamics, 2.01, 0.297, 30.0, 1000.0),
        candidate(Effect::SensorDelay, 2.00, 0.294, 50.0, 1000.0),
    ];
    for order in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
        let tied: Vec<&Candidate> = order.iter().map(|&i| &set[i]).collect();
        let (k, by_signature) = choose_among_tied(&tied);
        assert_eq!(tied[k].effect, Effect::SensorDelay, "order {order:?}");
        assert!(!by_signature);
    }
    // A signature that explains clearly more than every other's decides, ΔBIC or not.
    let set = [
        candidate(Effect::EddyCurrent, 2.0, 0.60, 10.0, 1000.0),
        candidate(Effect::MechanicalDynamics, 2.0, 0.30, 30.0, 1000.0),
        candidate(Effect::SensorDelay, 2.0, 0.297, 50.0, 1000.0),
    ];
    for order in [[0, 1, 2], [2, 1, 0], [1, 2, 0]] {
        let tied: Vec<&Candidate> = order.iter().map(|&i| &set[i]).collect();
        let (k, by_signature) = choose_among_tied(&tied);
        assert_eq!((tied[k].effect, by_signature), (Effect::EddyCurrent, true), "order {order:?}");
    }
}

/// Issue 61: an aftereffect refit lower on 4 of 5 validation files was refused, its fifth
/// file worse by less than its own noise. Such a file is a tie and does not vote; a fifth
/// file worse beyond the noise still refuses it.
#[test]
fn a_file_that_moves_by_less_than_its_noise_does_not_vote() {
    let mut c = candidate(Effect::MagneticAftereffect, 2.0, 0.3, 120.0, 1000.0);
    (c.files_scored, c.files_showing, c.files_improved_showing) = (5, 5, 4);
    (c.files_deciding, c.files_improved_deciding) = (4, 4);
    assert!(c.passes());
    (c.files_deciding, c.files_improved_deciding) = (5, 4);
    assert!(!c.passes());
    (c.files_deciding, c.files_improved_deciding) = (0, 0);
    assert!(!c.passes(), "a refit that moves no file beyond its noise shows nothing");
}

/// An exact refit of a noise-free recording is the strongest evidence there is: it passes
/// (its cut was read as 1× before, and it could never pass).
#[test]
fn an_exact_refit_cuts_the_error_infinitely_and_passes() {
    let mut c = candidate(Effect::Hysteresis, 2.0, 0.5, 100.0, 1000.0);
    c.nrmse_after = 0.0;
    c.per_file_after = vec![0.0; 4];
    assert!(c.cut().is_infinite());
    assert!(c.passes());
    assert_eq!(cut_words(c.cut()), "to zero");
    assert_eq!(error_cut(f64::NAN, 0.01), 1.0);
    assert_eq!(error_cut(0.0, 0.0), 1.0);
    assert_eq!(cut_words(0.5), "2.0× higher");
    assert_eq!(cut_words(1.003), "unchanged");
    assert_eq!(cut_words(1.0 / 1.003), "unchanged");
    assert_eq!(cut_words(1.02), "1.02× lower");
    assert_eq!(cut_words(1.0 / 1.06), "1.06× higher");
    assert_eq!(cut_words(1.12), "1.1× lower");
}

/// A law with a memory starts each scored file from a fitted pre-history: one parameter per
/// file that the information criterion counts when a refit adds the memory.
#[test]
fn a_fitted_initial_state_per_file_counts_as_a_parameter() {
    let spec = |s: &str| ModelSpec::parse(s).unwrap();
    assert_eq!(estimated_states(spec("anhysteretic+mech"), 4), 0);
    assert_eq!(estimated_states(spec("ja+mech"), 4), 4);
    assert_eq!(estimated_states(spec("preisach"), 3), 3);
    assert_eq!(estimated_states(spec("linear"), 3), 0);
}

/// A file counts for an effect when switching it off moves the prediction by more than the
/// noise, whatever slow model error the refit leaves there: the successive-difference noise
/// estimate sees the white part of the residual, not a slow error ten times its size.
#[test]
fn an_effect_shows_where_it_moves_the_prediction_above_the_noise() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let n = 4000;
    let slow = |k: usize| (2.0 * std::f64::consts::PI * k as f64 / n as f64).sin();
    let noise: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0) * 0.01 * 3f64.sqrt()).collect();
    // The refit misses a slow error of 10 noise rms and the sensor's noise (rms 0.01).
    let on: Vec<f64> = (0..n).map(|k| 0.1 * slow(k) + noise[k]).collect();
    // Switched off, the effect moves the prediction by 2 or by 0.5 noise rms (plus an offset,
    // which does not count).
    let moved = |size: f64| -> Vec<f64> {
        on.iter().enumerate().map(|(k, r)| r + 0.3 + size * 0.01 * 2f64.sqrt() * slow(3 * k)).collect()
    };
    assert!(effect_shows(&moved(2.0), &on));
    assert!(!effect_shows(&moved(0.5), &on));
}

#[test]
fn a_refit_is_unpinned_only_when_it_gains_on_the_fit_files_and_loses_on_every_validation_file() {
    let worse_everywhere = [(0.014, 0.020), (0.010, 0.067)];
    assert!(not_pinned_by_the_fit_files((0.012, 0.009), &worse_everywhere));
    // No gain on the fit files: a failed or idle refit, not an unpinned one.
    assert!(!not_pinned_by_the_fit_files((0.012, 0.012), &worse_everywhere));
    // One validation file better: no pattern.
    assert!(!not_pinned_by_the_fit_files((0.012, 0.009), &[(0.014, 0.020), (0.010, 0.009)]));
    // One validation file alone is no pattern either.
    assert!(!not_pinned_by_the_fit_files((0.012, 0.009), &[(0.014, 0.020)]));
}

fn rec_with(u: Vec<f64>, i: Vec<f64>, dt: f64) -> Recording {
    let mut r = Recording::with_time("t.csv", u.len(), dt);
    r.displacement_um = Some(u.iter().map(|v| v * 10.0).collect());
    r.command_v = Some(u);
    r.current_a = Some(i);
    r
}

#[test]
fn burn_in_is_the_first_drive_cycle() {
    let dt = 1e-4;
    let u: Vec<f64> = (0..4000).map(|k| (2.0 * std::f64::consts::PI * 10.0 * k as f64 * dt).sin()).collect();
    let rec = rec_with(u.clone(), u, dt);
    // A 10 Hz sine reverses at 25 and 75 ms; the second reversal is confirmed shortly after.
    let k = burn_in(&rec);
    assert!((750..900).contains(&k), "burn-in {k} samples");
}

#[test]
fn static_gain_sees_an_amplifier_lag_only_when_there_is_one() {
    let dt = 1e-4;
    let u: Vec<f64> = (0..3000)
        .map(|k| {
            let t = k as f64 * dt;
            (2.0 * std::f64::consts::PI * 40.0 * t).sin()
                + 0.5 * (2.0 * std::f64::consts::PI * 170.0 * t).sin()
        })
        .collect();
    let ideal: Vec<f64> = u.iter().map(|v| 2.0 * v + 0.01).collect();
    let lagged: Vec<f64> = lowpass(&u, dt, 5e-4).iter().map(|v| 2.0 * v).collect();
    let files = [rec_with(u.clone(), ideal, dt)];
    let skip = [burn_in(&files[0])];
    let g = StaticGain::fit(&files, &skip);
    assert!((g.gain - 2.0).abs() < 1e-9 && (g.offset - 0.01).abs() < 1e-9);
    assert!(g.scores(&files, &skip)[0].nrmse < 1e-9);
    let files = [rec_with(u, lagged, dt)];
    let g = StaticGain::fit(&files, &skip);
    assert!(g.scores(&files, &skip)[0].nrmse > 0.01);
    // −d(g·u)/dt is the first-order sketch of the lag: most, not all, of its residual.
    assert!(g.lag_evidence(&files, &skip) > 0.8, "lag evidence {}", g.lag_evidence(&files, &skip));
}
