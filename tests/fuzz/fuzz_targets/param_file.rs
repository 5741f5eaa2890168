//! Parameter files: any text is a parameter set the model accepts, or an error naming the file;
//! never a panic. A set that loads must build and step to finite outputs.
#![no_main]

use host_sim::params;
use libfuzzer_sys::fuzz_target;
use model_core::{Actuator, ModelSpec};

fuzz_target!(|input: (u8, &str)| {
    let (pick, text) = input;
    let specs = ["ja+mech", "saturation+eddy+amp", "preisach+thermal+aftereffect", "linear+delay"];
    let spec = ModelSpec::parse(specs[pick as usize % specs.len()]).expect("a valid spec");
    match params::parse("fuzz.toml", text, spec) {
        Ok(p) => {
            let model = Actuator::new(spec, &p).expect("a loaded set is valid for its spec");
            let mut s = model.rest_state();
            for k in 0..64 {
                let out = model.step(&mut s, (k as f32 * 0.3).sin()).expect("input in range");
                assert!(out.displacement_m.is_finite() && out.magnetization_a_per_m.is_finite());
            }
        }
        Err(e) => assert!(format!("{e:#}").starts_with("fuzz.toml")),
    }
});
