//! The drive's compiled-in parameter set: `firmware/build.rs` writes it with
//! `postcard::to_stdvec`, `gma-drive` reads it with `postcard::from_bytes` and boots refused
//! (`Controller::refused`) when that fails. postcard has no field names, so every field must be
//! written, an absent second-order amplifier included; parameter files (TOML) still leave it out.

use gma_control::command::{Command, Decoder, Received, MAX_ENCODED};
use model_core::amplifier::SecondOrderAmpParams;
use model_core::{ActuatorParams, ModelSpec};

fn with_second_order_amplifier() -> ActuatorParams {
    ActuatorParams {
        amp_second_order: Some(SecondOrderAmpParams { k_u: 1.0, a_s: 4.8e-4, b_s2: 2.5e-8, c_s: 6.4e-4 }),
        ..ActuatorParams::TERFENOL_DEMO
    }
}

#[test]
fn the_embedded_parameter_set_reads_back_as_written_with_and_without_the_second_order_amplifier() {
    for params in [ActuatorParams::TERFENOL_DEMO, with_second_order_amplifier()] {
        // As build.rs writes it and gma-drive reads it.
        let bytes = postcard::to_stdvec(&params).expect("serialise");
        let back: ActuatorParams =
            postcard::from_bytes(&bytes).expect("the board could not read its parameter set");
        assert_eq!(back, params);
    }
    let none = postcard::to_stdvec(&ActuatorParams::TERFENOL_DEMO).unwrap();
    let some = postcard::to_stdvec(&with_second_order_amplifier()).unwrap();
    // The presence tag is written either way (a skipped `None` would make `none` a byte shorter).
    assert_eq!(some.len(), none.len() + 4 * 4, "the amplifier adds its four f32 after the tag");
    let demo = ActuatorParams::TERFENOL_DEMO;
    let prefix = postcard::to_stdvec(&(demo.dt_s, demo.amp, None::<SecondOrderAmpParams>)).unwrap();
    assert!(none.starts_with(&prefix), "no presence tag after the first-order amplifier");
}

#[test]
fn a_parameter_file_still_leaves_an_absent_second_order_amplifier_out() {
    let text = toml::to_string(&ActuatorParams::TERFENOL_DEMO).unwrap();
    assert!(!text.contains("amp_second_order"), "{text}");
    let back: ActuatorParams = toml::from_str(&text).unwrap();
    assert_eq!(back, ActuatorParams::TERFENOL_DEMO);
    let with = with_second_order_amplifier();
    let text = toml::to_string(&with).unwrap();
    assert!(text.contains("[amp_second_order]"), "{text}");
    assert_eq!(toml::from_str::<ActuatorParams>(&text).unwrap(), with);
}

#[test]
fn a_load_command_carries_the_second_order_amplifier_through_the_decoder() {
    let spec = ModelSpec::parse("amp+ja+eddy+mech").unwrap();
    for params in [ActuatorParams::TERFENOL_DEMO, with_second_order_amplifier()] {
        let cmd = Command::LoadParameters { spec, params };
        let mut buf = [0u8; MAX_ENCODED];
        let n = cmd.encode(7, &mut buf).unwrap();
        let mut d = Decoder::default();
        let got: Vec<Received> = buf[..n].iter().filter_map(|&b| d.push_command(b)).collect();
        assert_eq!(got, vec![Received::Command(7, cmd)]);
    }
}
