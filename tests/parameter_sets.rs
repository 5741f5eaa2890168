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
