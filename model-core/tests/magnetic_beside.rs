//! `Actuator::step_magnetic_beside`: two actuators' magnetic stages stepped at once (the
//! workbench runs two files on one core this way) give the same bits, state and errors as each
//! stepped alone, whatever the structure, parameters (J–A variant included), sample period and inputs (one of them out
//! of range at times).

use model_core::magnetization::JaVariant;
use model_core::{Actuator, ActuatorParams, ActuatorState, MagneticOutput, ModelSpec, StepError};
use proptest::prelude::*;

const SPECS: [&str; 5] =
    ["ja", "amp+eddy+ja+aftereffect+mech+thermal+delay", "eddy+ja", "amp+preisach+mech", "linear+mech"];

fn bits(r: &Result<MagneticOutput, StepError>) -> Result<[u32; 3], StepError> {
    r.map(|o| [o.current_a.to_bits(), o.field_a_per_m.to_bits(), o.magnetization_a_per_m.to_bits()])
}

fn same_state(a: &ActuatorState, b: &ActuatorState) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn stepping_beside_another_actuator_changes_no_bit(
        spec in 0usize..SPECS.len(), spec_other in 0usize..SPECS.len(),
        k in 1000.0f32..8000.0, rate in 0.5f32..4.0, v in 0usize..JaVariant::ALL.len(),
        inputs in proptest::collection::vec((-4.0f32..4.0, -4.0f32..4.0, 0u8..20), 1..300),
    ) {
        let parse = |i: usize| ModelSpec::parse(SPECS[i]).unwrap();
        let p = ActuatorParams::TERFENOL_DEMO;
        let mut p_other = p;
        p_other.ja.k_a_per_m = k;
        p_other.ja.variant = JaVariant::ALL[v];
        p_other.dt_s = p.dt_s * rate;
        let (a, b) = (Actuator::new(parse(spec), &p).unwrap(), Actuator::new(parse(spec_other), &p_other).unwrap());
        let (mut alone, mut alone_other) = (a.rest_state(), b.rest_state());
        let (mut beside, mut beside_other) = (a.rest_state(), b.rest_state());
        for (u, u_other, bad) in inputs {
            // Now and then one input is not finite: that step is refused, the other still runs.
            let u = if bad == 0 { f32::NAN } else { u };
            let u_other = if bad == 1 { f32::INFINITY } else { u_other };
            let expected = [a.step_magnetic(&mut alone, u, |h| h), b.step_magnetic(&mut alone_other, u_other, |h| h)];
            let got = a.step_magnetic_beside(&mut beside, u, &b, &mut beside_other, u_other);
            prop_assert_eq!(bits(&got[0]), bits(&expected[0]));
            prop_assert_eq!(bits(&got[1]), bits(&expected[1]));
            prop_assert!(same_state(&beside, &alone) && same_state(&beside_other, &alone_other));
        }
    }
}
