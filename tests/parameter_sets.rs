//! A parameter set moves from the workbench to the board as text (TOML for `--params-out`,
//! JSON for scripts): after the round trip the model must step identically.

use model_core::{Actuator, ActuatorParams, ModelSpec};

fn run(params: &ActuatorParams, spec: &str) -> Vec<f32> {
    let model = Actuator::new(ModelSpec::parse(spec).unwrap(), params).unwrap();
    let mut s = model.rest_state();
    (0..2000)
        .map(|n| {
            let u = 1.5 * (n as f32 * 2e-3 * std::f32::consts::PI).sin();
            model.step(&mut s, u).unwrap().displacement_m
        })
        .collect()
}

#[test]
fn toml_and_json_round_trips_step_identically() {
    let p = ActuatorParams::TERFENOL_DEMO;
    let spec = "ja+eddy+amp+mech+aftereffect+thermal+delay";
    let reference = run(&p, spec);

    let toml_text = toml::to_string(&p).unwrap();
    let from_toml: ActuatorParams = toml::from_str(&toml_text).unwrap();
    assert_eq!(from_toml, p, "TOML:\n{toml_text}");
    assert_eq!(run(&from_toml, spec), reference);

    let json_text = serde_json::to_string(&p).unwrap();
    let from_json: ActuatorParams = serde_json::from_str(&json_text).unwrap();
    assert_eq!(run(&from_json, spec), reference);
    // The file names every stage's parameters by the names the errors use.
    for key in ["[ja]", "ms_a_per_m", "eddy_tau_s", "[mech]", "natural_frequency_hz", "delay_samples"] {
        assert!(toml_text.contains(key), "missing {key} in\n{toml_text}");
    }
}

#[test]
fn a_corrupt_parameter_set_is_refused_by_name() {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.ja.c = 1.5;
    let err = Actuator::new(ModelSpec::parse("ja+mech").unwrap(), &p).unwrap_err();
    assert_eq!(err.to_string(), "parameter `ja.c` is out of range: must be in [0, 1)");
    // Stages the spec does not use are not validated: the same set builds a linear model.
    assert!(Actuator::new(ModelSpec::LINEAR, &p).is_ok());
}

/// Found by the model_step fuzz target (tests/fuzz): λ_s = 3.4e38, M_s = 3.6e10, a 3.9e28 A/V
/// amplifier, a 2.4e-38 A/m field scale and a 3.6e5 Ω coil all passed validation and stepped to
/// inf/NaN. Each is now refused by name, so a valid set steps to finite outputs.
#[test]
fn sets_that_overflowed_are_refused_by_name() {
    use model_core::ParamError;
    let spec = ModelSpec::parse("amp+ja+thermal").unwrap();
    let demo = ActuatorParams::TERFENOL_DEMO;
    let mut cases = [
        (demo, "magnetostriction.lambda_s"),
        (demo, "ja.ms_a_per_m"),
        (demo, "amp.gain_a_per_v"),
        (demo, "ja.a_a_per_m"),
        (demo, "thermal.coil_resistance_ohm"),
    ];
    cases[0].0.magnetostriction.lambda_s = 3.4e38;
    cases[1].0.ja.ms_a_per_m = 3.6e10;
    cases[2].0.amp.gain_a_per_v = 3.9e28;
    cases[3].0.ja.a_a_per_m = 2.4e-38;
    cases[4].0.thermal.coil_resistance_ohm = 3.6e5;
    for (p, name) in cases {
        match Actuator::new(spec, &p) {
            Err(ParamError::OutOfRange(n, _)) => assert_eq!(n, name),
            other => panic!("{name}: {other:?}"),
        }
    }
}
