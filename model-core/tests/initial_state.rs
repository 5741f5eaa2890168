//! The state at rest after a pre-history (`Actuator::rest_state_after`): what a fit estimates per
//! file when the rod on a rig has a history the recording does not show.

use model_core::{Actuator, ActuatorParams, ModelSpec};

fn model(spec: &str) -> Actuator {
    Actuator::new(ModelSpec::parse(spec).unwrap(), &ActuatorParams::TERFENOL_DEMO).unwrap()
}

#[test]
fn no_excursion_is_the_boot_state() {
    for spec in ["ja", "preisach", "anhysteretic", "linear", "amp+eddy+ja+aftereffect+mech+thermal+delay"] {
        let m = model(spec);
        assert_eq!(m.rest_state_after(0.0), m.rest_state(), "{spec}");
        // A non-finite excursion is no excursion (never a NaN state).
        assert_eq!(m.rest_state_after(f32::NAN), m.rest_state(), "{spec}");
    }
}

#[test]
fn a_hysteretic_rod_remembers_the_side_it_came_from() {
    for spec in ["ja", "preisach"] {
        let m = model(spec);
        assert!(m.has_magnetic_memory());
        let above = m.rest_state_after(60_000.0);
        let below = m.rest_state_after(-60_000.0);
        let (m_above, m_below) = (above.m_slow_a_per_m.value(), below.m_slow_a_per_m.value());
        // Same field (the bias), different magnetization: above on the descending branch.
        assert_eq!(above.rod_field_a_per_m, below.rod_field_a_per_m);
        assert!(m_above > m_below + 1e3, "{spec}: {m_above} vs {m_below}");
        assert!(above.mech.displacement_m.is_finite() && below.mech.displacement_m.is_finite());
        // Continuous in the excursion (a fit differentiates through it): no jump between
        // neighbouring excursions larger than the slope between distant ones allows.
        let m_at = |x: f32| m.rest_state_after(x).m_slow_a_per_m.value();
        let slope = (m_at(40_000.0) - m_at(20_000.0)).abs() / 20_000.0;
        let step = (m_at(30_010.0) - m_at(30_000.0)).abs() / 10.0;
        assert!(step <= 20.0 * slope + 1e-3, "{spec}: local slope {step} against {slope}");
    }
}

#[test]
fn laws_without_memory_ignore_the_history() {
    for spec in ["anhysteretic", "linear"] {
        let m = model(spec);
        assert!(!m.has_magnetic_memory());
        assert_eq!(m.rest_state_after(50_000.0).m_slow_a_per_m, m.rest_state().m_slow_a_per_m, "{spec}");
    }
}
