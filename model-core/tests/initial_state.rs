//! The state of a rod at rest when a record starts (`Actuator::rest_state_at`): demagnetised at
//! the first drive's field, then a field excursion from there and back. What a fit estimates per
//! file when the rod on a rig has a history the recording does not show.

use model_core::amplifier::SecondOrderAmpParams;
use model_core::magnetization::JaVariant;
use model_core::{Actuator, ActuatorParams, ModelSpec};

fn model(spec: &str) -> Actuator {
    Actuator::new(ModelSpec::parse(spec).unwrap(), &ActuatorParams::TERFENOL_DEMO).unwrap()
}

/// No excursion: the rod demagnetised at the first drive's field. J–A's integrated
/// magnetization is 0 there (M = c M_an(H + αM) for the bulk and 1986 forms, M = 0 for the
/// total forms); the lags and the mechanics are settled at the drive.
#[test]
fn no_excursion_is_the_rod_demagnetised_at_the_first_field() {
    let p = ActuatorParams::TERFENOL_DEMO;
    for variant in JaVariant::ALL {
        let mut q = p;
        q.ja.variant = variant;
        let m = Actuator::new(ModelSpec::parse("ja+eddy+mech").unwrap(), &q).unwrap();
        let s = m.rest_state_at(1.5, 0.0);
        let h0 = p.coil.bias_a_per_m + 1.5 * p.coil.turns_per_m;
        assert!(
            (s.rod_field_a_per_m.value() - h0).abs() < 1e-2,
            "{variant}: the eddy lag settled at the field"
        );
        assert_eq!(s.ja.h_a_per_m, s.rod_field_a_per_m.value());
        if variant.is_total_magnetization() {
            assert_eq!(s.ja.m_a_per_m, 0.0, "{variant}");
        } else {
            assert_eq!(s.ja.m_irr_a_per_m, 0.0, "{variant}");
            // M = c M_s L((h + αM)/a), solved.
            let j = q.ja;
            let x = (h0 + j.alpha * s.ja.m_a_per_m) / j.a_a_per_m;
            let langevin = 1.0 / x.tanh() - 1.0 / x;
            let m_rev = j.c * j.ms_a_per_m * langevin;
            assert!(
                (s.ja.m_a_per_m - m_rev).abs() < 1e-4 * j.ms_a_per_m,
                "{variant}: {} vs {m_rev}",
                s.ja.m_a_per_m
            );
        }
        assert_eq!(s.m_slow_a_per_m.value(), s.ja.m_a_per_m);
        // The displacement at rest is the strain of that magnetization.
        assert!(s.mech.displacement_m.is_finite() && s.mech.velocity_m_per_rad == 0.0);
        // A non-finite excursion is no excursion (never a NaN state).
        assert_eq!(m.rest_state_at(1.5, f32::NAN), s, "{variant}");
    }
}

/// A command drive's amplifier is settled at the command: the current is the static gain's.
#[test]
fn the_amplifier_is_settled_at_the_first_command() {
    for second_order in [None, Some(SecondOrderAmpParams::TSMA_002)] {
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.amp_second_order = second_order;
        let spec = ModelSpec::parse("amp+ja").unwrap();
        let m = Actuator::new(spec, &p).unwrap();
        let mut s = m.rest_state_at(0.5, 0.0);
        let i0 = s.amp.current_a;
        assert!(i0 > 0.0, "{spec}: {i0}");
        // Held there, nothing moves.
        let o = m.step(&mut s, 0.5).unwrap();
        assert!((o.current_a - i0).abs() < 1e-5 * i0, "{spec}: {} vs {i0}", o.current_a);
    }
}

#[test]
fn a_hysteretic_rod_remembers_the_side_it_came_from() {
    for spec in ["ja", "preisach"] {
        let m = model(spec);
        assert!(m.has_magnetic_memory());
        let above = m.rest_state_at(0.0, 60_000.0);
        let below = m.rest_state_at(0.0, -60_000.0);
        let (m_above, m_below) = (above.m_slow_a_per_m.value(), below.m_slow_a_per_m.value());
        // Same field (the bias), different magnetization: above on the descending branch.
        assert_eq!(above.rod_field_a_per_m, below.rod_field_a_per_m);
        assert!(m_above > m_below + 1e3, "{spec}: {m_above} vs {m_below}");
        assert!(above.mech.displacement_m.is_finite() && below.mech.displacement_m.is_finite());
        // Continuous in the excursion (a fit differentiates through it): no jump between
        // neighbouring excursions larger than the slope between distant ones allows.
        let m_at = |x: f32| m.rest_state_at(0.0, x).m_slow_a_per_m.value();
        let slope = (m_at(40_000.0) - m_at(20_000.0)).abs() / 20_000.0;
        let step = (m_at(30_010.0) - m_at(30_000.0)).abs() / 10.0;
        assert!(step <= 20.0 * slope + 1e-3, "{spec}: local slope {step} against {slope}");
    }
}

/// The family holds the anhysteretic state at the field (M_irr = M_an) and the board's boot
/// state (the virgin curve from zero field): some excursion reaches each within 1 % of M_s.
#[test]
fn the_excursions_reach_the_anhysteretic_and_the_virgin_state() {
    let p = ActuatorParams::TERFENOL_DEMO;
    let m = model("ja");
    let h0 = p.coil.bias_a_per_m;
    let j = p.ja;
    // M_an at h0 with M = M_an (the anhysteretic state), solved by iteration.
    let mut man = 0.0f32;
    for _ in 0..200 {
        let x = (h0 + j.alpha * man) / j.a_a_per_m;
        man = j.ms_a_per_m * (1.0 / x.tanh() - 1.0 / x);
    }
    let virgin = m.rest_state().ja.m_irr_a_per_m;
    let reached: Vec<f32> =
        (-400..=400).map(|k| m.rest_state_at(0.0, k as f32 * 250.0).ja.m_irr_a_per_m).collect();
    for (name, target) in [("anhysteretic", man), ("virgin", virgin)] {
        let nearest = reached.iter().map(|r| (r - target).abs()).fold(f32::MAX, f32::min);
        assert!(nearest < 0.01 * j.ms_a_per_m, "{name} M_irr {target}: nearest reached {nearest} off");
    }
}

#[test]
fn laws_without_memory_ignore_the_history() {
    for spec in ["anhysteretic", "linear"] {
        let m = model(spec);
        assert!(!m.has_magnetic_memory());
        assert_eq!(m.rest_state_at(0.0, 50_000.0), m.rest_state_at(0.0, 0.0), "{spec}");
        assert_eq!(m.rest_state_at(0.0, 0.0).m_slow_a_per_m, m.rest_state().m_slow_a_per_m, "{spec}");
    }
}
