//! The board's control code (gma-control), unchanged, in closed loop with the workbench's plant
//! simulator (issue 5: "the same control code runs on the host against the host-sim plant") in
//! the board's simulated rig, with the board's timing (the duty of tick n across the coil from
//! the next PWM update, 12-bit conversions with ±1 code of noise, the bus measured). The coil's
//! R–L electrics are the plant's first-order `amp` stage (gain 1/R, τ = L/R: a held bridge
//! voltage in, coil current out), integrated at 2× the tick rate. SIMULATED data throughout.

use gma_control::command::Command;
use gma_control::sim::Rig;
use gma_control::{ControlConfig, Controller, ResetCause};
use host_sim::plant::Plant;
use model_core::amplifier::FirstOrderAmpParams;
use model_core::{ActuatorParams, ModelSpec};

#[test]
fn control_code_tracks_on_the_workbench_plant() {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.amp = FirstOrderAmpParams { gain_a_per_v: 1.0 / 6.0, tau_s: 6e-3 / 6.0 }; // 6 Ω, 6 mH coil
    let plant = Plant::new(ModelSpec::parse("amp+eddy+ja+mech").unwrap(), p);
    let mut rig = Rig::new(plant.stepper().unwrap(), 1);
    rig.adc_noise_codes = 1;
    // The controller's model is the identified actuator (no amp: its current loop is the amp).
    let model = ModelSpec::parse("eddy+ja+mech").unwrap();
    let mut ctl = Controller::new(ControlConfig::REFERENCE, model, &p, ResetCause::PowerOn);
    // Boot idle through the offset calibration, then the arm command.
    for _ in 0..ControlConfig::REFERENCE.offset_calibration_ticks {
        let out = ctl.tick(&rig.sample());
        assert!(!out.bridge_enabled, "switching before the arm command");
        rig.apply(&out).unwrap();
    }
    assert_eq!(ctl.command(0, &Command::Arm).outcome, Ok(()));
    let (mut sum2, mut n) = (0.0f64, 0usize);
    for k in 0..4000 {
        if k % 1000 == 0 {
            ctl.command(0, &Command::Ping);
        }
        let y = rig.displacement_from_rest_um();
        let out = ctl.tick(&rig.sample());
        assert!(out.bridge_enabled, "tripped at tick {k}: {:#x}", out.frame.faults);
        if k >= 1000 {
            let e = y - out.frame.reference_um as f64;
            sum2 += e * e;
            n += 1;
        }
        rig.apply(&out).unwrap();
    }
    let rms = (sum2 / n as f64).sqrt() / 12.5 * 100.0;
    println!("gma-control on the host-sim plant: 25 µm p-p 100 Hz, RMS {rms:.2} % of amplitude");
    assert!(rms <= 1.0, "tracking RMS {rms:.2} %");
}
