//! QEMU smoke test (netduinoplus2: a Cortex-M4F with the board's memory map): runs real
//! model-core code on the target — ZOH mechanics, and the J–A inverse compensator driving a
//! ja+eddy+amp+mech plant — and compares every checkpoint with the values the host computed at
//! build time from the same code, plus an absolute bound on the tracking error. Exit status 0
//! only when every check passes. `-append force-fail` perturbs the expectations, to prove that
//! a failure is reported.
#![no_std]
#![no_main]
// `!(error <= limit)` on purpose: a NaN error must fail the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use firmware::semihosting::{cmdline, exit};
use firmware::smoke_case::*;

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("qemu-smoke: PANIC {}", info);
    exit(101)
}

/// Compares `got` with `expected` within `rtol` of the expected signal's peak; returns failures.
fn compare(name: &str, got: &[f32], expected: &[f32], rtol: f32, perturb: bool) -> u32 {
    let scale = expected.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(f32::MIN_POSITIVE);
    let mut failures = 0;
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        let e = if perturb { e + 0.01 * scale } else { *e };
        if !((g - e).abs() <= rtol * scale) {
            if failures < 3 {
                hprintln!("qemu-smoke: FAIL {} checkpoint {}: target {}, host {}", name, i, g, e);
            }
            failures += 1;
        }
    }
    hprintln!("qemu-smoke: {} — {} checkpoints vs host, {} off", name, got.len(), failures);
    failures
}

/// The board's control code (gma-control) in closed loop with the simulated rig for 10 000
/// ticks (1 s at 10 kHz): tracking within 1 % RMS of amplitude, then a probe disconnect that
/// must trip within one tick, and a corrupt parameter set that must never enable the bridge.
fn closed_loop(force_fail: bool) -> u32 {
    use gma_control::faults::FaultCode;
    use gma_control::sim::{CoilActuator, Fault, Injection, Rig};
    use gma_control::{ControlConfig, Controller};
    use model_core::{ActuatorParams, ModelSpec};

    let mut failures = 0;
    let Ok(spec) = ModelSpec::parse("ja+eddy+mech") else { return 1 };
    let p = ActuatorParams::TERFENOL_DEMO;
    let Ok(plant) = CoilActuator::new(spec, &p, 1e-4) else { return 1 };
    let mut rig = Rig::new(plant, 1);
    let mut ctl = Controller::new(ControlConfig::REFERENCE, spec, &p);
    let (mut sum2, mut n) = (0.0f32, 0u32);
    for k in 0..10_000u32 {
        let y_now = rig.displacement_from_rest_um() as f32;
        let out = ctl.tick(&rig.sample());
        if !out.bridge_enabled {
            hprintln!("qemu-smoke: FAIL closed loop tripped at tick {}: faults {:#x}", k, out.frame.faults);
            return failures + 1;
        }
        if k >= 2000 {
            let e = y_now - out.frame.reference_um;
            sum2 += e * e;
            n += 1;
        }
        if rig.apply(&out).is_err() {
            hprintln!("qemu-smoke: FAIL closed loop: rig input out of range at tick {}", k);
            return failures + 1;
        }
    }
    let rms = model_core::math::sqrt(sum2 / n as f32) / 12.5 * 100.0;
    let limit = if force_fail { 0.0 } else { 1.0 };
    hprintln!(
        "qemu-smoke: closed loop 10000 ticks, 100 Hz 25 µm p-p tracking RMS {}% of amplitude (limit {}%)",
        rms,
        limit
    );
    if !(rms <= limit) {
        hprintln!("qemu-smoke: FAIL closed-loop tracking");
        failures += 1;
    }
    let unplugged = Injection { fault: Fault::DisplacementDropout, from: rig.tick(), ticks: u64::MAX };
    if rig.injections.push(unplugged).is_err() {
        return failures + 1;
    }
    let out = ctl.tick(&rig.sample());
    if out.bridge_enabled || !FaultCode(out.frame.faults).contains(FaultCode::DISPLACEMENT_SENSOR_RANGE) {
        hprintln!(
            "qemu-smoke: FAIL probe disconnect not tripped in its tick (faults {:#x})",
            out.frame.faults
        );
        failures += 1;
    } else {
        hprintln!("qemu-smoke: probe disconnect tripped in its tick (faults {:#x})", out.frame.faults);
    }
    let mut bad = p;
    bad.ja.k_a_per_m = f32::NAN;
    let mut ctl = Controller::new(ControlConfig::REFERENCE, spec, &bad);
    rig.injections.clear();
    let out = ctl.tick(&rig.sample());
    if out.bridge_enabled || !FaultCode(out.frame.faults).contains(FaultCode::PARAMETERS_INVALID) {
        hprintln!("qemu-smoke: FAIL corrupt parameter set enabled the bridge");
        failures += 1;
    }
    failures
}

/// The board's interrupt (`firmware::drive`) against the simulated rig, with stand-in registers:
/// telemetry through the queue and the thread-mode encoder decodes in order with its cycle
/// count; a break-input trip turns the outputs off in its own tick and keeps them off; one late
/// tick is counted, three in a row latch the bridge off in the third; the compare values keep
/// the duty inside the quiet window.
fn drive_loop() -> u32 {
    use core::sync::atomic::Ordering;
    use firmware::drive::{
        bus_code, encode_queued, quiet_window_max_duty, trip, BridgeTiming, DriveCounters, DriveLoop,
        MemoryStage, Slot, TelemetryQueue, DEADLINE_LATCH_AFTER,
    };
    use gma_control::sim::{CoilActuator, Rig};
    use gma_control::telemetry::{Decoder, MAX_ENCODED};
    use gma_control::{ControlConfig, Controller};
    use model_core::{ActuatorParams, ModelSpec};

    static QUEUE_BREAK: Slot<TelemetryQueue> = Slot::new();
    static QUEUE_DEADLINE: Slot<TelemetryQueue> = Slot::new();
    static COUNTERS_BREAK: DriveCounters = DriveCounters::new();
    static COUNTERS_DEADLINE: DriveCounters = DriveCounters::new();

    let mut failures = 0;
    let mut check = |ok: bool, what: &str| {
        if ok {
            hprintln!("qemu-smoke: drive loop: {}", what);
        } else {
            hprintln!("qemu-smoke: FAIL drive loop: {}", what);
            failures += 1;
        }
    };
    let Ok(spec) = ModelSpec::parse("ja+eddy+mech") else { return 1 };
    let p = ActuatorParams::TERFENOL_DEMO;
    let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
    let rig = || CoilActuator::new(spec, &p, 1e-4).map(|plant| Rig::new(plant, 1));
    let (Ok(mut rig_a), Ok(mut rig_b)) = (rig(), rig()) else { return 1 };
    // SAFETY: the only writes to these two slots.
    #[allow(unsafe_code)]
    let (queue_a, queue_b) =
        unsafe { (QUEUE_BREAK.write(TelemetryQueue::new()), QUEUE_DEADLINE.write(TelemetryQueue::new())) };
    let (producer, mut consumer) = queue_a.split();
    let ctl = Controller::new(ControlConfig::REFERENCE, spec, &p);
    let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS_BREAK);
    let mut decoder = Decoder::default();
    let mut bytes = [0u8; 8 * MAX_ENCODED];
    let (mut decoded, mut in_order, mut timed) = (0u32, true, true);
    let step = |drive: &mut DriveLoop<MemoryStage>, rig: &mut Rig<CoilActuator>| {
        let raw = rig.sample();
        drive.stage().conversions = [raw.current.0, raw.displacement.0, bus_code(raw.bus)];
        let out = drive.on_conversion();
        let _ = rig.apply(&out);
        out
    };
    let mut enabled_before = true;
    let mut widest = 0u16;
    for _ in 0..300 {
        let out = step(&mut drive, &mut rig_a);
        enabled_before &= out.bridge_enabled && drive.stage().outputs_enabled;
        let [a, b] = drive.stage().compare;
        widest = widest.max(a.abs_diff(b));
        let n = encode_queued(&mut consumer, &mut bytes);
        for &byte in &bytes[..n] {
            if let Some(d) = decoder.push(byte) {
                in_order &= d.frame.seq == decoded && d.gap == 0;
                timed &= d.tick_cycles.is_some();
                decoded += 1;
            }
        }
    }
    check(enabled_before, "bridge enabled for 300 fault-free ticks");
    check(
        decoded == 300 && in_order && timed && decoder.corrupt == 0,
        "300 telemetry records queued, encoded in thread mode, decoded in order (format 2)",
    );
    let window = (timing.max_duty * timing.period_ticks as f32) as u16 + 1;
    let full = [1.0f32, -1.0, f32::INFINITY, f32::NAN, 0.0].map(|d| timing.compare_values(d));
    let spans = full.map(|(a, b)| a.abs_diff(b));
    hprintln!(
        "qemu-smoke: drive loop: duty limit {} = {} of {} ticks; widest in closed loop {}",
        timing.max_duty,
        window,
        timing.period_ticks,
        widest
    );
    check(
        widest <= window
            && spans[..3].iter().all(|&s| s <= window && s + 2 >= window)
            && spans[3] == 0
            && spans[4] == 0,
        "compare values: full duty and beyond stop at the quiet-window limit, NaN and 0 give equal legs",
    );
    drive.stage().break_flag = true;
    let out = step(&mut drive, &mut rig_a);
    check(!out.bridge_enabled && !drive.stage().outputs_enabled, "break input: outputs off in its own tick");
    let mut stays_off = true;
    for _ in 0..10 {
        let out = step(&mut drive, &mut rig_a);
        stays_off &= !out.bridge_enabled && !drive.stage().outputs_enabled;
    }
    check(
        stays_off && COUNTERS_BREAK.trips.load(Ordering::Relaxed) & trip::BREAK_INPUT != 0,
        "break input: latched off for the following ticks",
    );

    // Dead time: the smallest whole number of timer ticks that covers DEAD_TIME_NS.
    let timer_hz = 170_000_000u64;
    let ticks = firmware::drive::dead_time_ticks(timer_hz as u32) as u64;
    let ns = |t: u64| t * 1_000_000_000 / timer_hz;
    let dead = firmware::drive::DEAD_TIME_NS as u64;
    check(
        ns(ticks) >= dead && ns(ticks - 1) < dead,
        "dead time: fewest 170 MHz ticks covering the datasheet value",
    );
    // Bus scaling: code → volts → code is exact over the range; 24 V within one code.
    let lsb = firmware::drive::bus_volts(1).0;
    let exact = (0..=4095u16).all(|c| bus_code(firmware::drive::bus_volts(c)) == c);
    let v24 = firmware::drive::bus_volts(bus_code(gma_control::units::Volts(24.0))).0;
    check(exact && (v24 - 24.0).abs() <= lsb, "bus voltage scaling round-trips every code");
    // Reset cause: a watchdog wins over the pin flag every internal reset also sets.
    use firmware::drive::ResetCause;
    let cause = |iwdg, sft, bor, pin| ResetCause::from_flags(iwdg, false, sft, bor, pin, false);
    check(
        cause(true, false, false, true).is_watchdog()
            && cause(false, false, false, true) == ResetCause::Pin
            && cause(false, false, true, true) == ResetCause::PowerOn
            && cause(false, true, false, true) == ResetCause::Software
            && !cause(false, false, true, true).is_watchdog(),
        "reset cause from RCC_CSR flags (watchdog over pin)",
    );

    let (producer, _consumer) = queue_b.split();
    let ctl = Controller::new(ControlConfig::REFERENCE, spec, &p);
    let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS_DEADLINE);
    for _ in 0..10 {
        step(&mut drive, &mut rig_b);
    }
    drive.stage().late = true;
    let mut on_while_counting = true;
    for _ in 1..DEADLINE_LATCH_AFTER {
        on_while_counting &= step(&mut drive, &mut rig_b).bridge_enabled;
    }
    let latched = !step(&mut drive, &mut rig_b).bridge_enabled && !drive.stage().outputs_enabled;
    drive.stage().late = false;
    let stays_off = !step(&mut drive, &mut rig_b).bridge_enabled;
    check(
        on_while_counting
            && latched
            && stays_off
            && COUNTERS_DEADLINE.deadline_overruns.load(Ordering::Relaxed) == DEADLINE_LATCH_AFTER as u32
            && COUNTERS_DEADLINE.trips.load(Ordering::Relaxed) & trip::DEADLINE != 0,
        "deadline: late ticks counted, the bridge latched off in the 3rd late tick in a row",
    );
    failures
}

#[entry]
fn main() -> ! {
    let mut buf = [0u8; 128];
    let force_fail = cmdline(&mut buf).split_whitespace().any(|a| a == "force-fail");

    let mut failures = 0u32;
    match smoke_workload() {
        Err(e) => {
            hprintln!("qemu-smoke: FAIL model parameters rejected: {}", e);
            failures += 1;
        }
        Ok(r) => {
            failures +=
                compare("mechanics ZOH [µm]", &r.mechanics_um, &EXPECTED_MECHANICS_UM, 1e-5, force_fail);
            failures += compare("compensated chain [µm]", &r.chain_um, &EXPECTED_CHAIN_UM, 1e-4, force_fail);
            failures +=
                compare("compensator command [V]", &r.command_v, &EXPECTED_COMMAND_V, 1e-4, force_fail);
            // Absolute: the open-loop compensated chain tracks a 50 Hz sine within 5 % RMS (the
            // residual is the uncompensated mechanics' phase lag).
            let limit = if force_fail { 0.0 } else { 5.0 };
            let rms = r.tracking_rms_percent;
            hprintln!(
                "qemu-smoke: tracking RMS error {}% of amplitude (host {}%)",
                rms,
                EXPECTED_TRACKING_RMS_PERCENT
            );
            if !(rms <= limit) {
                hprintln!("qemu-smoke: FAIL tracking error {}% > {}%", rms, limit);
                failures += 1;
            }
        }
    }
    failures += closed_loop(force_fail);
    failures += drive_loop();
    if failures == 0 {
        hprintln!("qemu-smoke: PASS");
        exit(0)
    } else {
        hprintln!("qemu-smoke: FAIL ({} checks failed)", failures);
        exit(1)
    }
}
