//! The inverse divides by the rod length, the strain scale k_λ, the susceptibility and the coil's
//! turns: each has a physical floor, a value below it is refused by name (subnormal values were
//! accepted and gave an infinite or NaN compensator state, its output frozen), and at the floor
//! the compensator's command stays finite and follows the reference.

use model_core::magnetostriction::Preload;
use model_core::{Actuator, ActuatorParams, Compensator, ModelSpec};

const DEMO: ActuatorParams = ActuatorParams::TERFENOL_DEMO;

fn spec(s: &str) -> ModelSpec {
    ModelSpec::parse(s).unwrap()
}

#[test]
fn divisors_below_their_floor_are_refused_by_name() {
    let mut thermal = DEMO;
    thermal.thermal.rod_length_m = 1e-45;
    let mut preload = DEMO;
    preload.magnetostriction.preload =
        Some(Preload { force_n: 11_000.0, optimal_force_n: 1000.0, max_force_n: 10_000.0 });
    let cases = [
        ("ja", ActuatorParams { rod_length_m: 1e-45, ..DEMO }, "rod_length_m"),
        ("ja+thermal", thermal, "thermal.rod_length_m"),
        ("ja+aftereffect", preload, "magnetostriction.preload.force_n"),
    ];
    for (s, p, name) in cases {
        assert_eq!(Actuator::new(spec(s), &p).err().map(|e| e.name()), Some(name), "{s}");
    }
}

#[test]
fn at_the_floors_the_compensator_command_stays_finite_and_moves() {
    let mut floors = [DEMO; 5];
    floors[0].rod_length_m = 1e-4;
    floors[1].linear.susceptibility = 1e-3;
    floors[2].coil.turns_per_m = 1.0;
    floors[3].magnetostriction.lambda_s = 1e-9;
    floors[4].magnetostriction.preload =
        Some(Preload { force_n: 10_900.0, optimal_force_n: 1000.0, max_force_n: 10_000.0 });
    let specs = ["ja+aftereffect", "linear+eddy", "ja", "ja+aftereffect", "ja+aftereffect"];
    for (s, p) in specs.into_iter().zip(floors) {
        let model = Actuator::new(spec(s), &p).unwrap();
        let comp = Compensator::new(model);
        let mut cs = comp.rest_state();
        let y0 = model.rest_state().mech.displacement_m;
        // A stroke the model can reach: half what one ampere makes.
        let mut at_1a = model.rest_state();
        let y1 = (0..20).map(|_| model.step(&mut at_1a, 1.0).unwrap().displacement_m).last().unwrap();
        let stroke = 0.5 * (y1 - y0).abs();
        let outs: Vec<f32> =
            (0..100).map(|n| comp.step(&mut cs, y0 + stroke * libm::sinf(0.1 * n as f32))).collect();
        assert!(outs.iter().all(|u| u.is_finite()), "{s}: {outs:?}");
        let moved = outs.windows(2).filter(|w| w[0] != w[1]).count();
        assert!(moved > 90, "{s} with {p:?}: the command moved {moved} times in 100 samples");
    }
}
