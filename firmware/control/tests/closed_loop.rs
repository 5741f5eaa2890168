//! The control code in closed loop against the SIMULATED rig (issue 5): current step response,
//! displacement tracking with the compensator alone and with the PID, and faults reaching the
//! safe state within one tick with the right code.

use gma_control::current::{CurrentLoop, CurrentLoopParams};
use gma_control::faults::FaultCode;
use gma_control::pid::PidParams;
use gma_control::sim::{CoilActuator, Fault, Injection, Rig};
use gma_control::units::{Amps, Volts};
use gma_control::{ControlConfig, Controller, TickOutput};
use model_core::{ActuatorParams, ModelSpec};

const TICK: f32 = 1e-4;

fn spec(s: &str) -> ModelSpec {
    ModelSpec::parse(s).unwrap()
}

fn rig(model: ModelSpec, params: &ActuatorParams) -> Rig<CoilActuator> {
    Rig::new(CoilActuator::new(model, params, TICK).unwrap(), 1)
}

/// `fault` from the rig's present tick on.
fn inject(rig: &mut Rig<CoilActuator>, fault: Fault) {
    rig.injections.push(Injection { fault, from: rig.tick(), ticks: u64::MAX }).unwrap();
}

#[test]
fn current_step_settles_in_five_ticks_without_overshoot() {
    let mut rig = rig(spec("ja"), &ActuatorParams::TERFENOL_DEMO);
    let mut pi = CurrentLoop::new(CurrentLoopParams::REFERENCE).unwrap();
    let target = 0.5;
    let mut trace = Vec::new();
    for _ in 0..20 {
        let i = Amps(rig.current_a() as f32);
        let cmd = pi.step(Amps(target), i, Volts(rig.bus_v as f32));
        rig.apply(&TickOutput { duty: cmd.duty, bridge_enabled: true, frame: Default::default() }).unwrap();
        trace.push(rig.current_a() as f32);
    }
    let overshoot = (trace.iter().fold(f32::MIN, |m, &v| m.max(v)) - target) / target;
    println!("current step 0 → {target} A: {:?}", &trace[..8]);
    assert!(overshoot <= 0.10, "overshoot {:.1} %", overshoot * 100.0);
    assert!(
        trace[4..].iter().all(|v| (v - target).abs() <= 0.02 * target),
        "not settled within 2 % after 5 ticks: {trace:?}"
    );
}

/// Tracks the reference for 0.3 s; returns the RMS error over the last 0.2 s in % of amplitude.
fn tracking_rms_percent(pid: Option<PidParams>, plant_params: &ActuatorParams) -> f32 {
    let model = spec("ja+eddy+mech");
    let mut rig = rig(model, plant_params);
    let cfg = ControlConfig { pid, ..ControlConfig::REFERENCE };
    let mut ctl = Controller::new(cfg, model, &ActuatorParams::TERFENOL_DEMO);
    let (mut sum2, mut n) = (0.0f64, 0usize);
    for k in 0..3000 {
        let y_now = rig.displacement_from_rest_um();
        let out = ctl.tick(&rig.sample());
        assert!(
            out.bridge_enabled,
            "fault {:?} at tick {k}",
            FaultCode(out.frame.faults).names().collect::<Vec<_>>()
        );
        if k >= 1000 {
            // This tick's reference against the true displacement at the same instant.
            let e = y_now - out.frame.reference_um as f64;
            sum2 += e * e;
            n += 1;
        }
        rig.apply(&out).unwrap();
    }
    ((sum2 / n as f64).sqrt() / 12.5 * 100.0) as f32
}

#[test]
fn compensated_tracking_of_a_100_hz_sine() {
    let exact = ActuatorParams::TERFENOL_DEMO;
    let open = tracking_rms_percent(None, &exact);
    let closed = tracking_rms_percent(ControlConfig::REFERENCE.pid, &exact);
    // A rig that differs from the identified model: 8 % more strain, 10 % stiffer pinning.
    let mut off = exact;
    off.magnetostriction.lambda_s *= 1.08;
    off.ja.k_a_per_m *= 1.1;
    let open_off = tracking_rms_percent(None, &off);
    let closed_off = tracking_rms_percent(ControlConfig::REFERENCE.pid, &off);
    println!("25 µm p-p, 100 Hz: compensator alone {open:.2} %, + PID {closed:.2} %; model 8–10 % off: {open_off:.2} % / {closed_off:.2} %");
    assert!(open <= 5.0, "compensator alone: {open:.2} % RMS");
    assert!(closed <= 1.0, "compensator + PID: {closed:.2} % RMS");
    assert!(
        closed_off <= 1.0 && closed_off < open_off,
        "mismatched model: {open_off:.2} % → {closed_off:.2} %"
    );
}

fn run_until_fault(
    ctl: &mut Controller,
    rig: &mut Rig<CoilActuator>,
    ticks: usize,
) -> Option<(usize, TickOutput)> {
    for k in 0..ticks {
        let raw = rig.sample();
        let out = ctl.tick(&raw);
        if !out.bridge_enabled {
            return Some((k, out));
        }
        rig.apply(&out).unwrap();
    }
    None
}

#[test]
fn overcurrent_trips_in_the_tick_that_sees_it() {
    let model = spec("ja+eddy+mech");
    let mut rig = rig(model, &ActuatorParams::TERFENOL_DEMO);
    let mut ctl = Controller::new(ControlConfig::REFERENCE, model, &ActuatorParams::TERFENOL_DEMO);
    run_until_fault(&mut ctl, &mut rig, 200);
    // A gate-drive fault holds the bridge on with a partly shorted winding: the current shoots up.
    inject(&mut rig, Fault::BridgeStuckOn);
    rig.plant.coil_resistance_ohm = 1.0;
    let mut last_ok_current = 0.0;
    let mut tripped = None;
    for k in 0..200 {
        let raw = rig.sample();
        let i = rig.calibration.current(raw.current).0;
        let out = ctl.tick(&raw);
        if !out.bridge_enabled {
            tripped = Some((k, i, out));
            break;
        }
        last_ok_current = i;
        rig.apply(&out).unwrap();
    }
    let (k, i, out) = tripped.expect("no trip");
    assert!(
        i.abs() > 4.0 && last_ok_current.abs() <= 4.0,
        "tripped at {i} A (previous tick {last_ok_current} A)"
    );
    assert!(FaultCode(out.frame.faults).contains(FaultCode::OVERCURRENT), "code {:?}", out.frame.faults);
    assert_eq!(out.duty, 0.0);
    println!(
        "short circuit: tripped {k} ticks later at {i:.2} A, code {:?}",
        FaultCode(out.frame.faults).names().collect::<Vec<_>>()
    );
    // Latched: stays off even when the current has decayed, until the explicit command.
    rig.plant.coil_resistance_ohm = 6.0;
    rig.injections.clear();
    for _ in 0..50 {
        let out = ctl.tick(&rig.sample());
        assert!(!out.bridge_enabled);
        rig.apply(&out).unwrap();
    }
    assert!(ctl.clear_faults(&rig.sample()).is_clear());
    assert!(ctl.tick(&rig.sample()).bridge_enabled);
}

#[test]
fn probe_disconnect_and_frozen_probe_are_caught() {
    let model = spec("ja+eddy+mech");
    for (what, code) in
        [("disconnected", FaultCode::DISPLACEMENT_SENSOR_RANGE), ("frozen", FaultCode::DISPLACEMENT_STUCK)]
    {
        let mut rig = rig(model, &ActuatorParams::TERFENOL_DEMO);
        let mut ctl = Controller::new(ControlConfig::REFERENCE, model, &ActuatorParams::TERFENOL_DEMO);
        assert!(run_until_fault(&mut ctl, &mut rig, 300).is_none());
        inject(
            &mut rig,
            if what == "disconnected" { Fault::DisplacementDropout } else { Fault::DisplacementFrozen },
        );
        let (k, out) = run_until_fault(&mut ctl, &mut rig, 2000).expect("no fault");
        assert!(FaultCode(out.frame.faults).contains(code), "{what}: code {:?}", out.frame.faults);
        if what == "disconnected" {
            assert_eq!(k, 0, "a disconnected probe must trip in the tick that reads it");
        } else {
            assert!(
                k <= ControlConfig::REFERENCE.limits.stuck_ticks as usize + 1,
                "stuck detected after {k} ticks"
            );
        }
        // Still present: the recovery command refuses.
        assert!(ctl.clear_faults(&rig.sample()).contains(code) || what == "frozen");
    }
}

#[test]
fn a_corrupt_parameter_set_never_enables_the_bridge() {
    let model = spec("ja+eddy+mech");
    let mut bad = ActuatorParams::TERFENOL_DEMO;
    bad.ja.k_a_per_m = f32::NAN;
    let mut rig = rig(model, &ActuatorParams::TERFENOL_DEMO);
    let mut ctl = Controller::new(ControlConfig::REFERENCE, model, &bad);
    let out = ctl.tick(&rig.sample());
    assert!(!out.bridge_enabled);
    assert!(FaultCode(out.frame.faults).contains(FaultCode::PARAMETERS_INVALID));
    assert!(
        ctl.clear_faults(&rig.sample()).contains(FaultCode::PARAMETERS_INVALID),
        "a bad parameter set stays latched"
    );
    // A PID design that does not validate is refused the same way.
    let pid = ControlConfig::REFERENCE.pid.map(|p| PidParams { ki: f32::NAN, ..p });
    let mut ctl = Controller::new(
        ControlConfig { pid, ..ControlConfig::REFERENCE },
        model,
        &ActuatorParams::TERFENOL_DEMO,
    );
    let out = ctl.tick(&rig.sample());
    assert!(!out.bridge_enabled && FaultCode(out.frame.faults).contains(FaultCode::PARAMETERS_INVALID));
}
