//! Faults injected into the SIMULATED rig (workbench plant + bridge + front end) while the
//! board's control code (gma-control, unchanged) closes the loop, and into the telemetry path
//! between the board and `gma record`. Each case states the outcome the board must reach: the
//! safe state (bridge off, fault bits in every frame, coil current decaying) or riding through.

use gma_control::command::Command;
use gma_control::faults::FaultCode;
use gma_control::sim::{Fault, Injection, Rig};
use gma_control::telemetry::{Frame, MAX_ENCODED};
use gma_control::{ControlConfig, Controller, ResetCause};
use host_sim::plant::{Plant, PlantStepper};
use model_core::amplifier::FirstOrderAmpParams;
use model_core::{ActuatorParams, ModelSpec};

const FAULT_AT: u64 = 3000;
/// The operator arms the drive once its boot calibration is done.
const ARM_AT: u64 = 300;
const TICKS: u64 = 6000;

struct Outcome {
    /// First tick whose frame carries a fault bit.
    tripped_at: Option<u64>,
    /// Fault bits of the first faulted frame.
    first_faults: u16,
    /// Every frame after the trip had the bridge off and its fault bits set.
    safe_after_trip: bool,
    /// Ticks from the trip until the coil current stayed below 0.05 A.
    decay_ticks: Option<u64>,
    /// Largest |coil current| [A].
    max_current_a: f64,
    /// Tracking RMS over the last 1500 ticks [% of the 12.5 µm amplitude].
    rms_end_pct: f64,
    frames: Vec<Frame>,
}

fn rig(bus_v: f64, injections: Vec<Injection>) -> (Rig<PlantStepper>, Controller) {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.amp = FirstOrderAmpParams { gain_a_per_v: 1.0 / 6.0, tau_s: 6e-3 / 6.0 }; // 6 Ω, 6 mH coil
    let plant = Plant::new(ModelSpec::parse("amp+eddy+ja+mech").unwrap(), p);
    let mut rig = Rig::new(plant.stepper().unwrap(), 7);
    rig.bus_v = bus_v;
    rig.injections.extend(injections);
    let ctl = Controller::new(
        ControlConfig::REFERENCE,
        ModelSpec::parse("eddy+ja+mech").unwrap(),
        &p,
        ResetCause::PowerOn,
    );
    (rig, ctl)
}

/// Runs the loop, armed at `ARM_AT` with a keep-alive every 100 ms; `clear_at` sends the
/// explicit recovery and arm commands at that tick.
fn run(bus_v: f64, injections: Vec<Injection>, clear_at: Option<u64>) -> Outcome {
    let (mut rig, mut ctl) = rig(bus_v, injections);
    let mut o = Outcome {
        tripped_at: None,
        first_faults: 0,
        safe_after_trip: true,
        decay_ticks: None,
        max_current_a: 0.0,
        rms_end_pct: 0.0,
        frames: Vec::new(),
    };
    let (mut sum2, mut n) = (0.0, 0);
    for k in 0..TICKS {
        let raw = rig.sample();
        if k == ARM_AT {
            assert_eq!(ctl.command(0, &Command::Arm).outcome, Ok(()), "arm refused");
        }
        if k % 1000 == 0 {
            ctl.command(0, &Command::Ping);
        }
        if clear_at == Some(k) {
            ctl.clear_faults(&raw);
            ctl.command(0, &Command::Arm);
        }
        let out = ctl.tick(&raw);
        if out.frame.faults != 0 && o.tripped_at.is_none() {
            o.tripped_at = Some(k);
            o.first_faults = out.frame.faults;
        }
        let cleared = clear_at.is_some_and(|c| k >= c);
        // After a trip the bridge stays on only while the controller drives the coil's current
        // to zero (gma_control::DrainParams), and never again after that.
        let on_outside_the_drain = out.bridge_enabled && !ctl.draining();
        if o.tripped_at.is_some() && !cleared && (on_outside_the_drain || out.frame.faults == 0) {
            o.safe_after_trip = false;
        }
        if let Some(t) = o.tripped_at {
            if !cleared && rig.current_a().abs() >= 0.05 {
                o.decay_ticks = None;
            } else if o.decay_ticks.is_none() {
                o.decay_ticks = Some(k - t);
            }
        }
        o.max_current_a = o.max_current_a.max(rig.current_a().abs());
        if k >= TICKS - 1500 {
            let e = rig.displacement_from_rest_um() - out.frame.reference_um as f64;
            sum2 += e * e;
            n += 1;
        }
        o.frames.push(out.frame);
        rig.apply(&out).unwrap();
    }
    o.rms_end_pct = (sum2 / n as f64).sqrt() / 12.5 * 100.0;
    o
}

fn at(fault: Fault, ticks: u64) -> Vec<Injection> {
    vec![Injection { fault, from: FAULT_AT, ticks }]
}

fn report(name: &str, o: &Outcome) {
    println!(
        "| {name:<34} | {:>9} | {:<40} | {:>5} | {:>8} | {:>6.2} A | {:>6.2} % |",
        o.tripped_at.map_or("—".into(), |t| format!("{}", t as i64 - FAULT_AT as i64)),
        FaultCode(o.first_faults).names().collect::<Vec<_>>().join("+"),
        if o.tripped_at.is_some() {
            if o.safe_after_trip {
                "yes"
            } else {
                "NO"
            }
        } else {
            "—"
        },
        o.decay_ticks.map_or("—".into(), |d| format!("{:.1} ms", d as f64 * 0.1)),
        o.max_current_a,
        o.rms_end_pct
    );
}

/// A fault that must trip: latched in the tick it is first seen (within `latency` ticks), the
/// bridge off from then on with the bits in every frame, and the coil current below 50 mA
/// within 10 ms.
fn assert_trips(name: &str, o: &Outcome, expected: FaultCode, latency: u64) {
    let t = o.tripped_at.unwrap_or_else(|| panic!("{name}: never tripped"));
    assert!(t >= FAULT_AT && t <= FAULT_AT + latency, "{name}: tripped at tick {t}");
    assert!(FaultCode(o.first_faults).contains(expected), "{name}: faults {:#x}", o.first_faults);
    assert!(o.safe_after_trip, "{name}: the bridge came back on or a frame lost its fault bits");
    let d = o.decay_ticks.unwrap_or_else(|| panic!("{name}: coil current never decayed"));
    assert!(d <= 100, "{name}: coil current took {d} ticks to decay");
}

#[test]
fn every_injected_fault_ends_in_the_safe_state_or_is_ridden_through() {
    println!("| fault (from tick {FAULT_AT}) | trip after | faults latched | safe | current < 50 mA | max |i| | RMS end |");
    println!("|---|---|---|---|---|---|---|");
    let clean = run(24.0, vec![], None);
    report("none", &clean);
    assert!(clean.tripped_at.is_none() && clean.rms_end_pct < 1.0);

    let o = run(24.0, at(Fault::DisplacementDropout, u64::MAX), None);
    report("displacement probe unplugged", &o);
    assert_trips("probe dropout", &o, FaultCode::DISPLACEMENT_SENSOR_RANGE, 0);

    let o = run(24.0, at(Fault::CurrentSenseDropout, u64::MAX), None);
    report("current sense output lost", &o);
    assert_trips("current sense dropout", &o, FaultCode::CURRENT_SENSOR_RANGE, 0);

    let o = run(24.0, at(Fault::DisplacementSaturation { offset_um: 100.0 }, u64::MAX), None);
    report("displacement ADC saturated", &o);
    assert_trips("ADC saturation", &o, FaultCode::DISPLACEMENT_SENSOR_RANGE, 0);

    let o = run(30.0, at(Fault::BridgeStuckOn, u64::MAX), None);
    report("bridge stuck on (30 V bus)", &o);
    assert_trips("bridge stuck on", &o, FaultCode::OVERCURRENT, 30);
    assert!(o.max_current_a < 4.6, "stuck-on current peaked at {:.2} A", o.max_current_a);

    // A 10 ms supply sag: latched, and the bridge stays off after the bus recovers until the
    // explicit recovery command (tick 4000); then tracking resumes.
    let o = run(24.0, at(Fault::BusSag { bus_v: 9.0 }, 100), Some(4000));
    // Under-voltage trips once it has lasted the qualification ticks (one bad conversion does not).
    let qualified = FAULT_AT + ControlConfig::REFERENCE.limits.bus_qualify_ticks as u64 - 1;
    report("bus sags to 9 V for 10 ms, cleared", &o);
    assert!(
        FaultCode(o.first_faults).contains(FaultCode::BUS_UNDERVOLTAGE) && o.tripped_at == Some(qualified),
        "tripped at {:?}, qualified at {qualified}",
        o.tripped_at
    );
    assert!(o.safe_after_trip);
    assert!(o.frames[3999].faults != 0 && o.frames[4001].faults == 0, "latched until the clear command");
    assert!(o.rms_end_pct < 1.0, "tracking after recovery {:.2} %", o.rms_end_pct);

    // Ride-through: interference and a power stage that clips for 50 ms must not trip, and
    // tracking must recover (no integrator wind-up) once they end.
    let o = run(24.0, at(Fault::NoiseBurst { rms_um: 0.5 }, 500), None);
    report("0.5 µm rms noise burst for 50 ms", &o);
    assert!(o.tripped_at.is_none(), "noise tripped {:#x}", o.first_faults);
    assert!(o.rms_end_pct < 1.0 && o.max_current_a < 3.0, "{:.2} % {:.2} A", o.rms_end_pct, o.max_current_a);

    let o = run(24.0, at(Fault::AmplifierSaturation { max_v: 3.0 }, 500), None);
    report("power stage clips at ±3 V for 50 ms", &o);
    assert!(o.tripped_at.is_none(), "saturation tripped {:#x}", o.first_faults);
    assert!(o.rms_end_pct < 1.0, "tracking after saturation {:.2} %", o.rms_end_pct);
}

#[test]
fn a_lossy_telemetry_link_loses_frames_but_record_never_writes_a_wrong_row() {
    let sent = run(24.0, at(Fault::DisplacementDropout, u64::MAX), None).frames;
    // The link: every 97th frame dropped, every 131st with one byte flipped, line noise after
    // every 500th.
    let (mut stream, mut dropped, mut flipped) = (Vec::new(), 0u64, 0u64);
    for (k, f) in sent.iter().enumerate() {
        if k % 97 == 50 {
            dropped += 1;
            continue;
        }
        let mut buf = [0u8; MAX_ENCODED];
        let n = f.encode(&mut buf);
        if k % 131 == 70 {
            buf[1 + k % (n - 2)] ^= 0x24;
            flipped += 1;
        }
        stream.extend_from_slice(&buf[..n]);
        if k % 500 == 499 {
            stream.extend_from_slice(&[0x42, 0x17, 0x00]);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let no_stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let s = host_sim::record::record(
        Box::new(std::io::Cursor::new(stream)),
        &dir.path().join("rig.csv"),
        1e-4,
        no_stop,
    )
    .unwrap();
    println!(
        "telemetry: {} frames sent, {dropped} dropped, {flipped} corrupted → decoded {}, lost {}, corrupt {}, {} files",
        sent.len(),
        s.frames,
        s.lost,
        s.corrupt,
        s.files.len()
    );
    assert_eq!(s.lost, dropped + flipped, "every missing frame is counted");
    assert_eq!(s.frames, sent.len() as u64 - dropped - flipped);
    assert_eq!(s.corrupt, flipped + (sent.len() as u64 / 500));
    // Every row written is exactly a frame that was sent, in order, with its own fault bits.
    let key = |f: &Frame| {
        (
            f.command_v.to_bits(),
            f.current_a.to_bits(),
            f.displacement_um.to_bits(),
            f.reference_um.to_bits(),
            f.faults,
        )
    };
    let mut rows = 0u64;
    let mut next = 0usize;
    for path in &s.files {
        let text = std::fs::read_to_string(path).unwrap();
        for line in text.lines().skip(1) {
            let c: Vec<&str> = line.split(',').collect();
            let row = Frame {
                seq: 0,
                command_v: c[1].parse().unwrap(),
                current_a: c[2].parse().unwrap(),
                displacement_um: c[3].parse().unwrap(),
                reference_um: c[4].parse().unwrap(),
                faults: c[5].parse().unwrap(),
            };
            let found = sent[next..].iter().position(|f| key(f) == key(&row));
            let off = found.unwrap_or_else(|| panic!("{}: row `{line}` was never sent", path.display()));
            next += off + 1;
            rows += 1;
        }
    }
    assert_eq!(rows + s.short, s.frames, "every decoded frame is written or counted as too short");
}
