//! The coil's energy and the bus: the SIMULATED rig with a bus capacitance (100 µF, the
//! reference board's) behind a supply that cannot sink current, so whatever the bridge returns
//! raises the bus. A trip, a disarm and regenerative running, each with the drive-to-zero and
//! the regeneration limit (`ControlConfig::REFERENCE`) and without them (the bridge opened at
//! once, the loop free to return any power): the figures firmware/README.md's safety table
//! states. All plants are our own simulation.

use gma_control::command::{Command, ReferenceCommand, Shape};
use gma_control::current::{CurrentLoop, CurrentLoopParams, RegenLimit};
use gma_control::faults::FaultCode;
use gma_control::pid::PidParams;
use gma_control::sim::{diode_discharge_peak_v, BusCapacitance, CoilActuator, Fault, Injection, Rig};
use gma_control::units::Amps;
use gma_control::{ControlConfig, Controller, DrainParams, ResetCause, TickOutput};
use model_core::{ActuatorParams, ModelSpec};

fn model() -> ModelSpec {
    ModelSpec::parse("ja+eddy+mech").unwrap()
}

/// The rig with the reference board's bus; its rod has `strain` × the identified
/// magnetostriction (0.3: the displacement PID, its limit raised in [`config`], winds the
/// current up to the controller's limit on a 50 µm reference).
fn capacitive_rig_of(strain: f32) -> Rig<CoilActuator> {
    let mut weak = ActuatorParams::TERFENOL_DEMO;
    weak.magnetostriction.lambda_s *= strain;
    let mut rig = Rig::new(CoilActuator::new(model(), &weak, 1e-4).unwrap(), 1)
        .with_bus_capacitance(BusCapacitance::REFERENCE_BOARD);
    rig.adc_noise_codes = 1;
    rig
}

fn capacitive_rig() -> Rig<CoilActuator> {
    capacitive_rig_of(0.3)
}

/// The reference design (drive-to-zero, regeneration limit) or the one without both.
fn config(protected: bool, max_current_a: f32) -> ControlConfig {
    let r = ControlConfig::REFERENCE;
    let pid = Some(PidParams { limit_a: max_current_a, ..r.pid.unwrap() });
    if protected {
        ControlConfig { max_current_a, pid, ..r }
    } else {
        ControlConfig {
            max_current_a,
            pid,
            drain: DrainParams::NONE,
            current_loop: CurrentLoopParams { regen: RegenLimit::NONE, ..r.current_loop },
            ..r
        }
    }
}

fn step(ctl: &mut Controller, rig: &mut Rig<CoilActuator>) -> TickOutput {
    let out = ctl.tick(&rig.sample());
    rig.apply(&out).unwrap();
    out
}

/// Boots, arms and holds a constant 50 µm reference (the current at the controller's limit)
/// for 100 ms; returns the controller and rig.
fn at_high_current(cfg: ControlConfig) -> (Controller, Rig<CoilActuator>) {
    let mut rig = capacitive_rig();
    let mut ctl = Controller::new(cfg, model(), &ActuatorParams::TERFENOL_DEMO, ResetCause::PowerOn);
    for _ in 0..cfg.offset_calibration_ticks {
        step(&mut ctl, &mut rig);
    }
    let hold = ReferenceCommand { shape: Shape::Constant, amplitude_um: 0.0, bias_um: 50.0, freq_hz: 0.0 };
    assert_eq!(ctl.command(1, &Command::SetReference(hold)).outcome, Ok(()));
    assert_eq!(ctl.command(2, &Command::Arm).outcome, Ok(()));
    for k in 0..1000 {
        if k % 500 == 0 {
            ctl.command(3, &Command::Ping);
        }
        let out = step(&mut ctl, &mut rig);
        assert!(
            out.frame.faults == 0,
            "tripped while holding: {:?}",
            FaultCode(out.frame.faults).names().collect::<Vec<_>>()
        );
    }
    (ctl, rig)
}

/// After the event: runs 30 ms; returns (the bus peak since the event [V], the tick the bridge
/// opened, the coil current then [A]).
fn after_event(ctl: &mut Controller, rig: &mut Rig<CoilActuator>) -> (f64, usize, f64) {
    rig.bus_peak_v = rig.bus_now();
    let mut opened = None;
    for k in 0..300 {
        let i = rig.current_a();
        let out = step(ctl, rig);
        if !out.bridge_enabled && opened.is_none() {
            opened = Some((k, i));
        }
    }
    let (k, i) = opened.expect("the bridge never opened");
    (rig.bus_peak_v, k, i)
}

/// A software trip (the probe unplugged) at the controller's 3.5 A limit, and a disarm there.
#[test]
fn a_trip_and_a_disarm_drive_the_current_to_zero_before_the_bridge_opens() {
    let mut figures = Vec::new();
    for (what, event) in [("trip (probe unplugged)", 0), ("disarm", 1)] {
        let mut peaks = [0.0; 2];
        for (n, protected) in [true, false].into_iter().enumerate() {
            let (mut ctl, mut rig) = at_high_current(config(protected, 3.5));
            let i0 = rig.current_a();
            assert!(i0 > 3.3, "holding {i0} A");
            if event == 0 {
                let from = rig.tick();
                rig.injections
                    .push(Injection { fault: Fault::DisplacementDropout, from, ticks: u64::MAX })
                    .unwrap();
            } else {
                assert_eq!(ctl.command(3, &Command::Disarm).outcome, Ok(()));
            }
            let (peak, opened_at, i_open) = after_event(&mut ctl, &mut rig);
            figures.push(format!(
                "{what} at {i0:.2} A, {}: bus peak {peak:.1} V, bridge open after {opened_at} ticks at {i_open:.3} A",
                if protected { "drive-to-zero" } else { "opened at once" }
            ));
            if protected {
                assert!(i_open.abs() < 0.06, "{what}: opened at {i_open} A");
                assert!(opened_at <= 100, "{what}: drained for {opened_at} ticks");
            } else {
                assert_eq!(opened_at, 0, "{what}: not opened at once");
            }
            peaks[n] = peak;
        }
        // The reference design stays under the regeneration limit's 30 V; opened at once, the
        // coil's 37 mJ lift the bus past 32 V.
        assert!(peaks[0] <= 30.1, "{what}: {:.2} V with the drive-to-zero", peaks[0]);
        assert!(peaks[1] > 32.0, "{what}: {:.2} V opened at once", peaks[1]);
    }
    for f in &figures {
        println!("{f}");
    }
}

/// The 4 A overcurrent trip (the controller's limit raised to 4.5 A so that the loop itself
/// drives the coil there, a cold 5 Ω winding so that the 24 V bus can): the drive-to-zero keeps the bus under the 34 V over-voltage trip,
/// opening at once does not.
#[test]
fn an_overcurrent_trip_drains_under_the_bus_limit() {
    let mut peaks = [0.0; 2];
    for (n, protected) in [true, false].into_iter().enumerate() {
        let cfg = config(protected, 4.5);
        let mut rig = capacitive_rig_of(0.1);
        // 4 A takes 24 V across the 6 Ω winding, more than the bridge's 22.8 V: a cold one.
        rig.plant.coil_resistance_ohm = 5.0;
        let mut ctl = Controller::new(cfg, model(), &ActuatorParams::TERFENOL_DEMO, ResetCause::PowerOn);
        for _ in 0..cfg.offset_calibration_ticks {
            step(&mut ctl, &mut rig);
        }
        let hold =
            ReferenceCommand { shape: Shape::Constant, amplitude_um: 0.0, bias_um: 50.0, freq_hz: 0.0 };
        assert_eq!(ctl.command(1, &Command::SetReference(hold)).outcome, Ok(()));
        assert_eq!(ctl.command(2, &Command::Arm).outcome, Ok(()));
        let mut trip = None;
        for k in 0..3000 {
            if k % 500 == 0 {
                ctl.command(3, &Command::Ping);
            }
            let i = rig.current_a();
            let out = step(&mut ctl, &mut rig);
            if out.frame.faults != 0 {
                trip = Some((k, i, out.frame.faults));
                break;
            }
        }
        let (k, i, faults) = trip.expect("no trip");
        assert!(
            FaultCode(faults).contains(FaultCode::OVERCURRENT),
            "{:?}",
            FaultCode(faults).names().collect::<Vec<_>>()
        );
        let (peak, opened_at, i_open) = after_event(&mut ctl, &mut rig);
        println!(
            "overcurrent trip at {i:.2} A (tick {k}), {}: bus peak {peak:.1} V, bridge open after {opened_at} more ticks at {i_open:.3} A; latched {:?}",
            if protected { "drive-to-zero" } else { "opened at once" },
            ctl.faults().names().collect::<Vec<_>>()
        );
        peaks[n] = peak;
    }
    assert!(peaks[0] <= 30.1, "{:.2} V with the drive-to-zero", peaks[0]);
    assert!(peaks[1] > 34.0, "{:.2} V opened at once", peaks[1]);
}

/// The current loop alone on the capacitive rig: returns the bus peak [V] and the RMS current
/// error [A] over 100 ms of `reference(tick)`.
fn run_current(regen: RegenLimit, reference: impl Fn(u32) -> f32) -> (f64, f32) {
    let mut rig = capacitive_rig();
    let mut pi =
        CurrentLoop::new(CurrentLoopParams { regen, ..ControlConfig::REFERENCE.current_loop }).unwrap();
    let (mut sum2, mut n) = (0.0f32, 0);
    for k in 0..1000 {
        let raw = rig.sample();
        let i = rig.calibration.current(raw.current);
        let r = reference(k);
        let cmd = pi.step(Amps(r), i, raw.bus);
        rig.apply(&TickOutput { duty: cmd.duty, bridge_enabled: true, frame: Default::default() }).unwrap();
        if k >= 200 {
            sum2 += (i.0 - reference(k)) * (i.0 - reference(k));
            n += 1;
        }
    }
    (rig.bus_peak_v, (sum2 / n as f32).sqrt())
}

/// Regenerative running: a current reversing between ±3.5 A (a 50 Hz square) returns up to the
/// coil's ½ L I² = 37 mJ (less what the winding takes) each half period; a large fast sine
/// (2 A at 200 Hz, near the bridge's voltage) returns its reactive share. The regeneration
/// limit holds the bus near its 30 V end; without it the reversals lift the bus further.
#[test]
fn regenerative_running_is_held_by_the_regeneration_limit() {
    let square = |k: u32| if (k / 100) % 2 == 0 { 3.5 } else { -3.5 };
    let sine = |k: u32| 2.0 * (2.0 * core::f32::consts::PI * 200.0 * k as f32 * 1e-4).sin();
    let (sq_limited, sq_err_limited) = run_current(RegenLimit::REFERENCE, square);
    let (sq_free, sq_err_free) = run_current(RegenLimit::NONE, square);
    let (sine_limited, sine_err_limited) = run_current(RegenLimit::REFERENCE, sine);
    let (sine_free, sine_err_free) = run_current(RegenLimit::NONE, sine);
    println!(
        "±3.5 A square at 50 Hz: bus peak {sq_limited:.1} V with the regeneration limit (RMS current error \
         {sq_err_limited:.3} A), {sq_free:.1} V without ({sq_err_free:.3} A)"
    );
    println!(
        "2 A sine at 200 Hz: bus peak {sine_limited:.1} V with the limit (RMS error {sine_err_limited:.3} A), \
         {sine_free:.1} V without ({sine_err_free:.3} A)"
    );
    assert!(sq_limited <= 30.1, "square, limited: {sq_limited:.2} V");
    assert!(sq_free > 31.0, "square, free: {sq_free:.2} V");
    // The sine returns little (its reactive power is small against the winding's loss here):
    // the limit never binds, and costs it nothing.
    assert!(sine_limited <= 30.0, "sine, limited: {sine_limited:.2} V");
    assert!((sine_err_limited - sine_err_free).abs() < 0.005, "{sine_err_limited} A vs {sine_err_free} A");
}

/// A hardware break (all four switches off at once, nothing the firmware can do): the coil
/// discharges through the body diodes into the bus capacitance, its resistance taking part of
/// the energy. The rig's bus follows the fine L–R–C integration, and the figures the safety
/// table states: 34.7 V from 4 A and 36.3 V from 4.4 A with ideal diodes (39.2 / 41.7 V
/// without the coil's 6 Ω).
#[test]
fn a_hardware_break_lifts_the_bus_as_the_lrc_discharge_says() {
    let (r, l, c) = (6.0, 6e-3, 100e-6);
    let at_4 = diode_discharge_peak_v(4.0, r, l, c, 24.0);
    let at_44 = diode_discharge_peak_v(4.4, r, l, c, 24.0);
    let lossless_4 = (24.0f64 * 24.0 + l * 16.0 / c).sqrt();
    println!("hardware break, ideal diodes, with R: {at_4:.2} V from 4 A, {at_44:.2} V from 4.4 A (without R: {lossless_4:.1} V)");
    assert!((at_4 - 34.67).abs() < 0.02, "{at_4}");
    assert!((at_44 - 36.27).abs() < 0.02, "{at_44}");
    assert!(at_4 > 34.0, "a 4 A break no longer passes the 34 V trip: update the docs");
    // The rig from its 3.5 A hold, the break input tripped: its bus against the integration.
    let (mut ctl, mut rig) = at_high_current(config(true, 3.5));
    let i0 = rig.current_a();
    let from = rig.tick();
    rig.injections.push(Injection { fault: Fault::GateDriverFault, from, ticks: u64::MAX }).unwrap();
    let (peak, opened_at, _) = after_event(&mut ctl, &mut rig);
    let want = diode_discharge_peak_v(i0, r, l, c, 24.0);
    println!("the rig's break from {i0:.2} A: bus peak {peak:.2} V (integration {want:.2} V)");
    assert_eq!(opened_at, 0, "a break opens in its tick");
    assert!((peak - want).abs() < 0.3, "rig {peak:.2} V, integration {want:.2} V");
}
