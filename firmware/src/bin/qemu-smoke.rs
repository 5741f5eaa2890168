//! QEMU smoke test (netduinoplus2: a Cortex-M4F with the board's memory map): runs real
//! model-core code on the target — ZOH mechanics, and the J–A inverse compensator driving a
//! ja+eddy+amp+mech plant — and compares every checkpoint with the values the host computed at
//! build time from the same code, plus an absolute bound on the tracking error. Exit status 0
//! only when every check passes. `-append force-fail` perturbs the expectations, to prove that
//! a failure is reported; `-append stack-overflow` runs only the stack-overflow check (a
//! recursion without end must end in the HardFault handler, on an address just below the
//! stack, with the statics untouched).
#![no_std]
#![no_main]
// `!(error <= limit)` on purpose: a NaN error must fail the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use firmware::semihosting::{cmdline, exit};
use firmware::smoke_case::*;

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("qemu-smoke: PANIC {}", info);
    exit(101)
}

/// Set while the stack-overflow check digs: the one run where a HardFault is the expected end.
static DIGGING: AtomicBool = AtomicBool::new(false);
/// A block of statics with a known pattern, checked after the overflow: a stack that grew into
/// `.bss` (the layout before flip-link) would have overwritten it on its way down.
static CANARY: [AtomicU32; 64] = [const { AtomicU32::new(0) }; 64];
const CANARY_WORD: u32 = 0xC0DE_5AFE;

/// Called by `firmware::fault`'s HardFault entry with the stack pointer reset.
#[allow(unsafe_code)] // no_mangle: the symbol the HardFault entry branches to.
#[no_mangle]
extern "C" fn gma_hard_fault() -> ! {
    let status = firmware::fault::FaultStatus::read();
    hprintln!(
        "qemu-smoke: HardFault (CFSR {:#010x}, HFSR {:#010x}, bus fault address {:x?}, stack floor {:#010x})",
        status.cfsr,
        status.hfsr,
        status.bus_fault_address,
        firmware::stack::lowest()
    );
    if !DIGGING.load(Ordering::Relaxed) {
        hprintln!("qemu-smoke: FAIL unexpected HardFault");
        exit(102)
    }
    // One frame of `dig` (a little over 256 B) is the farthest a single push can land below.
    let at_the_floor = status.is_stack_overflow(1024);
    let intact = CANARY.iter().all(|w| w.load(Ordering::Relaxed) == CANARY_WORD);
    if at_the_floor && intact {
        hprintln!("qemu-smoke: PASS stack overflow faulted below the stack's floor, statics intact");
        exit(0)
    }
    hprintln!(
        "qemu-smoke: FAIL stack overflow: fault below the floor {}, statics intact {}",
        at_the_floor,
        intact
    );
    exit(1)
}

/// Recurses `depth` levels with a 256 B frame each: far past the stack when depth is large.
#[inline(never)]
fn dig(depth: u32) -> u32 {
    let mut frame = [depth; 64];
    core::hint::black_box(&mut frame);
    if depth == 0 {
        return frame[0];
    }
    dig(depth - 1).wrapping_add(frame[1])
}

/// The stack-overflow check: ends in `gma_hard_fault`, or fails here if the recursion returns.
fn stack_overflow_check() -> ! {
    for w in &CANARY {
        w.store(CANARY_WORD, Ordering::Relaxed);
    }
    DIGGING.store(true, Ordering::Relaxed);
    // 100 000 frames of 256 B: 25 MB, several hundred times the stack.
    let sum = dig(core::hint::black_box(100_000));
    hprintln!("qemu-smoke: FAIL a recursion of 25 MB returned ({}) without a fault", sum);
    exit(1)
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
#[inline(never)] // its frame (two actuators, a controller) is freed before the next check runs
fn closed_loop(force_fail: bool) -> u32 {
    use gma_control::command::Command;
    use gma_control::faults::FaultCode;
    use gma_control::sim::{CoilActuator, Fault, Injection};
    use gma_control::{Controller, ResetCause};
    use model_core::{ActuatorParams, ModelSpec};

    let mut failures = 0;
    let Ok(spec) = ModelSpec::parse("ja+eddy+mech") else { return 1 };
    let p = ActuatorParams::TERFENOL_DEMO;
    let Ok(plant) = CoilActuator::new(spec, &p, 1e-4) else { return 1 };
    let mut rig = Rig::new(plant, 1);
    let cfg = firmware::drive::control_config();
    let mut ctl = Controller::new(cfg, spec, &p, ResetCause::PowerOn);
    for _ in 0..cfg.offset_calibration_ticks {
        let out = ctl.tick(&rig.sample());
        let _ = rig.apply(&out);
    }
    if let Err(r) = ctl.command(1, &Command::Arm).outcome {
        hprintln!("qemu-smoke: FAIL closed loop: arm refused ({})", r.name());
        return 1;
    }
    let (mut sum2, mut n) = (0.0f32, 0u32);
    for k in 0..10_000u32 {
        if k % 1000 == 0 {
            ctl.command(2, &Command::Ping);
        }
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
    // A software trip drives the coil's current to zero before the bridge opens
    // (`ControlConfig::drain`): the fault latched and the controller disarmed in the trip tick's
    // record, the bridge on after it only while `draining()`, off within the drain's bound
    // (`max_ticks` after the trip tick), the coil's current near zero when it opens.
    let sensor = FaultCode::DISPLACEMENT_SENSOR_RANGE;
    let out = ctl.tick(&rig.sample());
    let in_its_tick = FaultCode(out.frame.faults).contains(sensor) && !ctl.armed();
    let mut only_while_draining = !out.bridge_enabled || ctl.draining();
    let mut latched = in_its_tick;
    let (mut opened_after, mut open_at_a) = (None, f64::NAN);
    if !out.bridge_enabled {
        (opened_after, open_at_a) = (Some(0u32), rig.current_a());
    }
    let _ = rig.apply(&out);
    let bound = u32::from(cfg.drain.max_ticks);
    let mut k = 0;
    while opened_after.is_none() && k < bound + 5 {
        k += 1;
        let i_a = rig.current_a();
        let out = ctl.tick(&rig.sample());
        only_while_draining &= !out.bridge_enabled || ctl.draining();
        latched &= FaultCode(out.frame.faults).contains(sensor);
        if !out.bridge_enabled {
            (opened_after, open_at_a) = (Some(k), i_a);
        }
        let _ = rig.apply(&out);
    }
    let ok = in_its_tick
        && latched
        && only_while_draining
        && opened_after.is_some_and(|k| k <= bound)
        && open_at_a.abs() < 0.1;
    if ok == force_fail {
        hprintln!(
            "qemu-smoke: FAIL probe disconnect not latched in its tick or the bridge not off within the drain's {} ticks \
             (faults {:#x}, latched {}, on only while draining {}, off after {:?} ticks at {} A)",
            bound,
            out.frame.faults,
            latched,
            only_while_draining,
            opened_after,
            open_at_a
        );
        failures += 1;
    } else {
        hprintln!(
            "qemu-smoke: probe disconnect latched in its tick (faults {:#x}), bridge off after {:?} ticks of drain at {} A (bound {})",
            out.frame.faults,
            opened_after,
            open_at_a,
            bound
        );
    }
    let mut bad = p;
    bad.ja.k_a_per_m = f32::NAN;
    let mut ctl = Controller::new(cfg, spec, &bad, ResetCause::PowerOn);
    rig.injections.clear();
    let out = ctl.tick(&rig.sample());
    if out.bridge_enabled || !FaultCode(out.frame.faults).contains(FaultCode::PARAMETERS_INVALID) {
        hprintln!("qemu-smoke: FAIL corrupt parameter set enabled the bridge");
        failures += 1;
    }
    failures
}

/// The board's side of one simulated trigger: the rig's conversions (and its gate driver's fault
/// pin on the break flag) into the stand-in registers, the interrupt, the bridge back to the rig.
fn trigger(
    drive: &mut firmware::drive::DriveLoop<firmware::drive::MemoryStage>,
    rig: &mut Rig,
) -> TickOutput {
    let raw = rig.sample();
    let stage = drive.stage();
    stage.conversions = [raw.current.0, raw.displacement.0, firmware::drive::bus_code(raw.bus)];
    // The gate driver's fault pin: the timer sets its flag and clears MOE, in hardware.
    if raw.break_tripped {
        stage.break_flag = true;
        stage.outputs_enabled = false;
    }
    stage.cycles = stage.cycles.wrapping_add(firmware::drive::TICK_CYCLES);
    let out = drive.on_conversion();
    let _ = rig.apply(&out);
    out
}

type Rig = gma_control::sim::Rig<gma_control::sim::CoilActuator>;
use gma_control::TickOutput;

/// The operator's side of the command channel: commands encoded as `gma drive` does, through the
/// board's command port (decoder → controller) and back as replies.
struct Operator {
    port: firmware::drive::CommandPort,
    replies: heapless::spsc::Consumer<'static, gma_control::command::Reply>,
    tag: u8,
}

impl Operator {
    /// Sends `cmd`; the reply with its tag, or `None` when none came back.
    fn send(
        &mut self,
        drive: &mut firmware::drive::DriveLoop<firmware::drive::MemoryStage>,
        cmd: &gma_control::command::Command,
    ) -> Option<gma_control::command::Reply> {
        let mut frame = [0u8; gma_control::command::MAX_ENCODED];
        self.tag = self.tag.wrapping_add(1);
        let n = cmd.encode(self.tag, &mut frame).ok()?;
        self.port.on_bytes(&frame[..n], |r, staged| Some(firmware::drive::execute(drive, r, staged)));
        let reply = self.replies.dequeue()?;
        (reply.tag == self.tag).then_some(reply)
    }
}

/// The board's interrupt (`firmware::drive`) and its command channel against the simulated rig,
/// with stand-in registers, through the whole operating sequence: boot idle (no switching)
/// while the current zero is calibrated → arm by a command frame → tracking, telemetry through
/// the queue and the thread-mode encoder in order with cycle counts → a corrupt frame counted
/// and ignored → a gate-driver fault on the break input: outputs off in its own tick, latched,
/// visible in telemetry → disarm and clear by command → idle → parameter sets loaded by command
/// (Preisach, then J–A) → re-armed, a bus over-voltage trip; then the
/// deadline latch, and a watchdog reset booting latched (an arm command refused).
#[inline(never)]
fn drive_loop() -> u32 {
    use core::sync::atomic::Ordering;
    use firmware::drive::{
        boot_config, encode_queued, quiet_window_max_duty, trip, BridgeTiming, CommandPort, DriveCounters,
        DriveLoop, MemoryStage, ReplyQueue, Slot, TelemetryQueue,
    };
    use gma_control::command::{Command, ReferenceCommand, Refusal, Shape};
    use gma_control::faults::FaultCode;
    use gma_control::sim::{CoilActuator, Fault, Injection};
    use gma_control::telemetry::{Decoder, MAX_ENCODED};
    use gma_control::{Controller, ResetCause};
    use model_core::{ActuatorParams, ModelSpec};

    static QUEUE_RUN: Slot<TelemetryQueue> = Slot::new();
    static QUEUE_WATCHDOG: Slot<TelemetryQueue> = Slot::new();
    static REPLIES: Slot<ReplyQueue> = Slot::new();
    static COUNTERS_RUN: DriveCounters = DriveCounters::new();
    static COUNTERS_WATCHDOG: DriveCounters = DriveCounters::new();

    let mut failures = 0;
    let mut check = |ok: bool, what: &str| {
        if ok {
            hprintln!("qemu-smoke: drive loop: {}", what);
        } else {
            hprintln!("qemu-smoke: FAIL drive loop: {}", what);
            failures += 1;
        }
    };
    let acked = |r: Option<gma_control::command::Reply>| r.is_some_and(|r| r.outcome.is_ok());
    let Ok(spec) = ModelSpec::parse("ja+eddy+mech") else { return 1 };
    let p = ActuatorParams::TERFENOL_DEMO;
    // The board's own boot configuration: it holds rest until a reference is commanded.
    let cfg = boot_config();
    let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
    let rig = || CoilActuator::new(spec, &p, 1e-4).map(|plant| Rig::new(plant, 1));
    // Each phase below builds its own rig and drive in a block of its own: alive together, the
    // three took a 57 KB frame and overflowed the stack (`qemu-smoke: stack peak`).
    // SAFETY: the only writes to these slots.
    #[allow(unsafe_code)]
    let (queue_a, queue_c, replies) = unsafe {
        (
            QUEUE_RUN.write(TelemetryQueue::new()),
            QUEUE_WATCHDOG.write(TelemetryQueue::new()),
            REPLIES.write(ReplyQueue::new()),
        )
    };
    let (reply_producer, reply_consumer) = replies.split();
    let mut op = Operator { port: CommandPort::new(reply_producer), replies: reply_consumer, tag: 0 };
    {
        let Ok(mut rig_a) = rig() else { return 1 };
        let (producer, mut consumer) = queue_a.split();
        let ctl = Controller::new(cfg, spec, &p, ResetCause::PowerOn);
        let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS_RUN);

        // Boot idle: no switching while the current zero is calibrated; an early arm is refused.
        let mut idle = true;
        for _ in 0..cfg.offset_calibration_ticks / 2 {
            let out = trigger(&mut drive, &mut rig_a);
            idle &= !out.bridge_enabled && !drive.stage().outputs_enabled;
        }
        let early = op.send(&mut drive, &Command::Arm);
        for _ in cfg.offset_calibration_ticks / 2..cfg.offset_calibration_ticks {
            let out = trigger(&mut drive, &mut rig_a);
            idle &= !out.bridge_enabled && !drive.stage().outputs_enabled;
        }
        let zero = drive.controller().current_zero_v();
        hprintln!("qemu-smoke: drive loop: current zero calibrated at boot {:?} V", zero);
        check(
            idle && early.is_some_and(|r| r.outcome == Err(Refusal::NotCalibrated) && !r.armed)
                && zero.is_some_and(|v| (v - 1.65).abs() < 0.01),
            "boot idle: outputs off through the offset calibration, an early arm command refused",
        );
        while consumer.dequeue().is_some() {}

        // Arm by a command frame; run.
        let arm = op.send(&mut drive, &Command::Arm);
        check(
            acked(arm) && arm.is_some_and(|r| r.armed),
            "arm command frame decoded, executed, acknowledged",
        );
        // Armed before any reference: the rod is held at rest, no waveform runs.
        let mut held = true;
        for _ in 0..200 {
            let out = trigger(&mut drive, &mut rig_a);
            held &= out.bridge_enabled && out.frame.reference_um == 0.0;
        }
        let rest = rig_a.displacement_from_rest_um();
        hprintln!("qemu-smoke: drive loop: armed without a reference, 200 ticks: {} µm from rest", rest);
        check(held && rest.abs() < 1.0, "armed before any reference: held at rest (reference 0 µm)");
        let sine = ReferenceCommand { shape: Shape::Sine, amplitude_um: 12.5, bias_um: 15.0, freq_hz: 100.0 };
        check(acked(op.send(&mut drive, &Command::SetReference(sine))), "reference command: 100 Hz sine");
        while consumer.dequeue().is_some() {}
        let mut decoder = Decoder::default();
        let mut bytes = [0u8; 8 * MAX_ENCODED];
        let (mut decoded, mut in_order, mut timed, mut first_seq) = (0u32, true, true, None);
        let mut enabled = true;
        let mut widest = 0u16;
        let mut keep_alive = true;
        for k in 0..3000 {
            if k % 500 == 0 {
                keep_alive &= acked(op.send(&mut drive, &Command::Ping));
            }
            let out = trigger(&mut drive, &mut rig_a);
            enabled &= out.bridge_enabled && drive.stage().outputs_enabled;
            let [a, b] = drive.stage().compare;
            widest = widest.max(a.abs_diff(b));
            let n = encode_queued(&mut consumer, &mut bytes);
            for &byte in &bytes[..n] {
                if let Some(d) = decoder.push(byte) {
                    let first = *first_seq.get_or_insert(d.frame.seq);
                    in_order &= d.frame.seq == first.wrapping_add(decoded) && d.gap == 0;
                    timed &= d.tick_cycles.is_some();
                    decoded += 1;
                }
            }
        }
        let y = rig_a.displacement_from_rest_um();
        check(enabled && keep_alive, "armed: bridge switching for 3000 ticks with a keep-alive every 500");
        let writes = drive.stage().enable_writes;
        hprintln!("qemu-smoke: drive loop: MOE written 1 {} time(s) in 3000 armed ticks", writes);
        check(writes == 1, "MOE written 1 only on the arming tick, read back on the others");
        check(
            decoded == 3000 && in_order && timed && decoder.corrupt == 0,
            "3000 telemetry records queued, encoded in thread mode, decoded in order (format 2)",
        );
        hprintln!("qemu-smoke: drive loop: displacement at the last tick {} µm (reference 15 ± 12.5 µm)", y);
        check((1.0..=29.0).contains(&y), "tracking: the displacement is inside the reference's range");
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

        // A corrupt frame: counted, no reply, nothing changes.
        let mut frame = [0u8; gma_control::command::MAX_ENCODED];
        let n = Command::Disarm.encode(99, &mut frame).unwrap_or(0);
        frame[n / 2] ^= 0x10;
        let corrupt_before = op.port.decoder.corrupt;
        op.port.on_bytes(&frame[..n], |r, staged| Some(firmware::drive::execute(&mut drive, r, staged)));
        let out = trigger(&mut drive, &mut rig_a);
        check(
            op.port.decoder.corrupt == corrupt_before + 1
                && op.replies.dequeue().is_none()
                && out.bridge_enabled,
            "corrupt command frame counted, not answered, not executed",
        );

        // A gate-driver fault on the break input (the records before it are dropped here).
        while consumer.dequeue().is_some() {}
        let from = rig_a.tick();
        let gate_fault = Injection { fault: Fault::GateDriverFault, from, ticks: 5 };
        if rig_a.injections.push(gate_fault).is_err() {
            return failures + 1;
        }
        let out = trigger(&mut drive, &mut rig_a);
        check(
            !out.bridge_enabled
                && !drive.stage().outputs_enabled
                && FaultCode(out.frame.faults).contains(FaultCode::BRIDGE_BREAK),
            "break input: outputs off in its own tick, bridge_break in its record",
        );
        let (mut stays_off, mut visible, mut seen) = (true, true, 0);
        for _ in 0..20 {
            let out = trigger(&mut drive, &mut rig_a);
            stays_off &= !out.bridge_enabled && !drive.stage().outputs_enabled;
            let n = encode_queued(&mut consumer, &mut bytes);
            for &byte in &bytes[..n] {
                if let Some(d) = decoder.push(byte) {
                    visible &= FaultCode(d.frame.faults).contains(FaultCode::BRIDGE_BREAK);
                    seen += 1;
                }
            }
        }
        check(
            stays_off
                && visible
                && seen == 21
                && COUNTERS_RUN.trips.load(Ordering::Relaxed) & trip::BREAK_INPUT != 0,
            "break input: latched off after the pin released, bridge_break in every decoded frame",
        );
        rig_a.injections.clear();

        // Disarm and clear through commands: back to idle, the fault gone, still not switching.
        let disarm = op.send(&mut drive, &Command::Disarm);
        let clear = op.send(&mut drive, &Command::ClearFaults);
        let mut idle_again = true;
        for _ in 0..50 {
            let out = trigger(&mut drive, &mut rig_a);
            idle_again &= !out.bridge_enabled && !drive.stage().outputs_enabled && out.frame.faults == 0;
        }
        check(
            acked(disarm) && acked(clear) && clear.is_some_and(|r| r.faults == 0 && !r.armed) && idle_again,
            "disarm and clear by command: faults cleared, idle (no switching without a new arm)",
        );

        // Parameter sets by command frame while disarmed, the stack's deepest path (the
        // compensator's model built where the controller keeps it): a Preisach set, then the
        // J–A set back for the checks below. Idle after both.
        let Ok(preisach) = ModelSpec::parse("preisach+eddy+mech") else { return failures + 1 };
        let load_preisach = op.send(&mut drive, &Command::LoadParameters { spec: preisach, params: p });
        let load_ja = op.send(&mut drive, &Command::LoadParameters { spec, params: p });
        // The move held the interrupt off for about half a tick (`qemu-bench load-swap`): the
        // next entry comes that much late, the one after it early; not a tick-period fault.
        let lock = firmware::drive::TICK_CYCLES * 3 / 5;
        drive.stage().cycles = drive.stage().cycles.wrapping_add(lock);
        let mut idle_after_load = trigger(&mut drive, &mut rig_a).frame.faults == 0;
        drive.stage().cycles = drive.stage().cycles.wrapping_sub(lock);
        for _ in 0..50 {
            let out = trigger(&mut drive, &mut rig_a);
            idle_after_load &= !out.bridge_enabled && !drive.stage().outputs_enabled && out.frame.faults == 0;
        }
        check(
            acked(load_preisach) && acked(load_ja) && idle_after_load,
            "load parameters by command (built before the lock, moved in under it): a Preisach set and a J–A set \
             acknowledged while disarmed, idle, the late entry after the move not a tick-period fault",
        );

        // Re-armed (once the zero and rest are measured again with the bridge off), the bus
        // pumped over its limit: bus_overvoltage trips and the bridge goes off.
        for _ in 0..cfg.calibration_settle_ticks + cfg.offset_calibration_ticks {
            trigger(&mut drive, &mut rig_a);
        }
        let rearm = op.send(&mut drive, &Command::Arm);
        rig_a.bus_v = 40.0;
        // Latched within 3 ticks (the qualifying ticks), the bridge then on only while the
        // current is driven to zero and off within the drain's bound: over 30 V the regeneration
        // limit lets no energy back, so the current decays through the winding.
        let (mut tripped_after, mut off_after) = (None, None);
        let mut only_while_draining = true;
        let bound = u32::from(cfg.drain.max_ticks) + 3;
        for k in 1..=bound + 5 {
            let out = trigger(&mut drive, &mut rig_a);
            let latched = FaultCode(out.frame.faults).contains(FaultCode::BUS_OVERVOLTAGE);
            if latched && tripped_after.is_none() {
                tripped_after = Some(k);
            }
            if tripped_after.is_some() {
                only_while_draining &= !out.bridge_enabled || drive.controller().draining();
            }
            if latched && !out.bridge_enabled && !drive.stage().outputs_enabled {
                off_after = Some(k);
                break;
            }
        }
        let refused_while_over = op.send(&mut drive, &Command::ClearFaults);
        rig_a.bus_v = 24.0;
        trigger(&mut drive, &mut rig_a);
        let cleared = op.send(&mut drive, &Command::ClearFaults);
        hprintln!(
            "qemu-smoke: drive loop: bus at 40 V tripped after {:?} ticks, bridge off after {:?} (bound {})",
            tripped_after,
            off_after,
            bound
        );
        check(
            acked(rearm)
                && tripped_after.is_some_and(|k| k <= 3)
                && only_while_draining
                && off_after.is_some_and(|k| k <= bound)
                && !drive.stage().outputs_enabled
                && refused_while_over.is_some_and(|r| r.outcome == Err(Refusal::FaultStillPresent))
                && acked(cleared),
            "bus over-voltage: tripped within 3 ticks, bridge off within the drain's bound (on only while draining), \
             kept while present, cleared by command after",
        );
    }

    // Watchdog reset: the RCC_CSR flags (IWDG with the pin flag every internal reset sets) boot
    {
        let Ok(mut rig_c) = rig() else { return 1 };
        // the controller with watchdog_reset latched; an arm command is refused, nothing switches.
        let cause = ResetCause::from_rcc_flags(true, false, false, false, true, false);
        let (producer, _consumer) = queue_c.split();
        let ctl = Controller::new(cfg, spec, &p, cause);
        let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS_WATCHDOG);
        let mut off = true;
        let mut shown = true;
        for _ in 0..cfg.offset_calibration_ticks + 10 {
            let out = trigger(&mut drive, &mut rig_c);
            off &= !out.bridge_enabled && !drive.stage().outputs_enabled;
            shown &= FaultCode(out.frame.faults).contains(FaultCode::WATCHDOG_RESET);
        }
        let arm = op.send(&mut drive, &Command::Arm);
        let out = trigger(&mut drive, &mut rig_c);
        check(
            cause == ResetCause::Watchdog
                && ResetCause::from_rcc_flags(false, false, false, false, true, false) == ResetCause::Pin
                && off
                && shown
                && arm.is_some_and(|r| r.outcome == Err(Refusal::FaultLatched) && !r.armed)
                && !out.bridge_enabled,
            "watchdog reset: boots with watchdog_reset latched, arm refused, never switching",
        );
    }

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
    let exact = (0..=4095u16).all(|c| firmware::drive::bus_code(firmware::drive::bus_volts(c)) == c);
    let v24 = firmware::drive::bus_volts(firmware::drive::bus_code(gma_control::units::Volts(24.0))).0;
    check(exact && (v24 - 24.0).abs() <= lsb, "bus voltage scaling round-trips every code");
    failures
}

/// The bridge gate (MOE written 1 only on the arming tick, read back on the others, never over a
/// pending break flag), the tick period check, the deadline latch, and the re-arm ration they
/// add up to (the third unverifiable trip within a minute), on a drive of their own.
/// A function of its own, called from `main` after [`drive_loop`]: its drive and rig take
/// their own frame, not one stacked on that one's.
#[inline(never)]
fn gate_timing_deadline() -> u32 {
    use core::sync::atomic::Ordering;
    use firmware::drive::{
        control_config, quiet_window_max_duty, trip, BridgeTiming, CommandPort, DriveCounters, DriveLoop,
        MemoryStage, ReplyQueue, Slot, TelemetryQueue, DEADLINE_LATCH_AFTER,
    };
    use gma_control::command::{Command, Refusal};
    use gma_control::faults::FaultCode;
    use gma_control::sim::CoilActuator;
    use gma_control::{Controller, ResetCause};
    use model_core::{ActuatorParams, ModelSpec};

    static QUEUE_DEADLINE: Slot<TelemetryQueue> = Slot::new();
    static REPLIES: Slot<ReplyQueue> = Slot::new();
    static COUNTERS_DEADLINE: DriveCounters = DriveCounters::new();
    // SAFETY: the only writes to these slots.
    #[allow(unsafe_code)]
    let (queue_b, replies) =
        unsafe { (QUEUE_DEADLINE.write(TelemetryQueue::new()), REPLIES.write(ReplyQueue::new())) };
    let (reply_producer, reply_consumer) = replies.split();
    let op = &mut Operator { port: CommandPort::new(reply_producer), replies: reply_consumer, tag: 0 };
    let mut failures = 0;
    let mut check = |ok: bool, what: &str| {
        if ok {
            hprintln!("qemu-smoke: drive loop: {}", what);
        } else {
            hprintln!("qemu-smoke: FAIL drive loop: {}", what);
            failures += 1;
        }
    };
    let acked = |r: Option<gma_control::command::Reply>| r.is_some_and(|r| r.outcome.is_ok());
    let Ok(spec) = ModelSpec::parse("ja+eddy+mech") else { return 1 };
    let p = ActuatorParams::TERFENOL_DEMO;
    let cfg = control_config();
    let timing = BridgeTiming { period_ticks: 4250, max_duty: quiet_window_max_duty() };
    let Ok(mut rig_b) = CoilActuator::new(spec, &p, 1e-4).map(|plant| Rig::new(plant, 1)) else { return 1 };
    let (producer, _consumer) = queue_b.split();
    let ctl = Controller::new(cfg, spec, &p, ResetCause::PowerOn);
    let mut drive = DriveLoop::new(ctl, MemoryStage::default(), timing, producer, &COUNTERS_DEADLINE);
    // The bridge gate and the tick period first, then the deadline.
    let boot = |drive: &mut DriveLoop<MemoryStage>, rig: &mut Rig, idle: u16| {
        for _ in 0..idle {
            trigger(drive, rig);
        }
    };
    boot(&mut drive, &mut rig_b, cfg.offset_calibration_ticks);
    let armed = acked(op.send(&mut drive, &Command::Arm));
    for _ in 0..10 {
        trigger(&mut drive, &mut rig_b);
    }
    // MOE cleared behind the firmware's back (no flag): seen in the next tick, latched as
    // bridge_break, never written 1 again.
    let writes = drive.stage().enable_writes;
    drive.stage().outputs_enabled = false;
    let out = trigger(&mut drive, &mut rig_b);
    let lost_seen = !out.bridge_enabled
        && FaultCode(out.frame.faults).contains(FaultCode::BRIDGE_BREAK)
        && COUNTERS_DEADLINE.trips.load(Ordering::Relaxed) & trip::OUTPUTS_LOST != 0;
    for _ in 0..20 {
        trigger(&mut drive, &mut rig_b);
    }
    check(
        armed && lost_seen && drive.stage().enable_writes == writes && !drive.stage().outputs_enabled,
        "MOE read back 0 while armed: bridge_break latched in that tick, MOE not written 1 again",
    );
    // A break flag raised between the tick's flag read and the arming write: MOE stays 0.
    let clear = op.send(&mut drive, &Command::ClearFaults);
    boot(&mut drive, &mut rig_b, cfg.calibration_settle_ticks + cfg.offset_calibration_ticks);
    let rearm = acked(op.send(&mut drive, &Command::Arm));
    drive.stage().break_during_tick = true;
    let out = trigger(&mut drive, &mut rig_b);
    check(
        acked(clear)
            && rearm
            && !out.bridge_enabled
            && !drive.stage().outputs_enabled
            && drive.stage().enable_writes == writes
            && FaultCode(out.frame.faults).contains(FaultCode::BRIDGE_BREAK)
            && COUNTERS_DEADLINE.trips.load(Ordering::Relaxed) & trip::ARMING_BLOCKED != 0,
        "arming tick with a break flag pending: MOE left at 0, bridge_break latched",
    );
    // Tick period: a single late entry (a 20 µs critical section) rides through; a
    // period 3 % long latches tick_timing at the end of a 32-interval window (the first
    // window it fills enough, at most two).
    drive.stage().break_flag = false;
    let clear = op.send(&mut drive, &Command::ClearFaults);
    boot(&mut drive, &mut rig_b, cfg.calibration_settle_ticks + cfg.offset_calibration_ticks);
    let rearm = acked(op.send(&mut drive, &Command::Arm));
    let late_entry = firmware::drive::TICK_CYCLES / 5;
    drive.stage().cycles = drive.stage().cycles.wrapping_add(late_entry);
    let mut rode_through = trigger(&mut drive, &mut rig_b).bridge_enabled;
    drive.stage().cycles = drive.stage().cycles.wrapping_sub(late_entry);
    for _ in 0..10 {
        rode_through &= trigger(&mut drive, &mut rig_b).bridge_enabled;
    }
    let slow = firmware::drive::TICK_CYCLES * 3 / 100;
    let mut tripped_after = None;
    for k in 1..=80 {
        drive.stage().cycles = drive.stage().cycles.wrapping_add(slow);
        let out = trigger(&mut drive, &mut rig_b);
        if !out.bridge_enabled && FaultCode(out.frame.faults).contains(FaultCode::TICK_TIMING) {
            tripped_after = Some(k);
            break;
        }
    }
    hprintln!("qemu-smoke: drive loop: tick period 3 % long tripped after {:?} ticks", tripped_after);
    check(
        acked(clear)
            && rearm
            && rode_through
            && tripped_after.is_some_and(|k| (22..=64).contains(&k))
            && !drive.stage().outputs_enabled
            && COUNTERS_DEADLINE.trips.load(Ordering::Relaxed) & trip::TICK_PERIOD != 0,
        "tick period: one late entry rides through, a period 3 % long latches tick_timing within two windows",
    );
    // Cleared at once, the fault is back in the next tick: no window has been judged right
    // since, so nothing shows the period good again.
    let early = op.send(&mut drive, &Command::ClearFaults);
    let back = FaultCode(trigger(&mut drive, &mut rig_b).frame.faults).contains(FaultCode::TICK_TIMING);
    check(
        acked(early) && back,
        "tick period: tick_timing cleared before a whole window was judged right latches again",
    );
    // Re-armed for the deadline check, after clean windows.
    boot(&mut drive, &mut rig_b, cfg.calibration_settle_ticks + cfg.offset_calibration_ticks);
    let clear = op.send(&mut drive, &Command::ClearFaults);
    let armed = acked(clear) && acked(op.send(&mut drive, &Command::Arm));
    for _ in 0..10 {
        trigger(&mut drive, &mut rig_b);
    }
    drive.stage().late = true;
    let mut on_while_counting = true;
    for _ in 1..DEADLINE_LATCH_AFTER {
        on_while_counting &= trigger(&mut drive, &mut rig_b).bridge_enabled;
    }
    let out = trigger(&mut drive, &mut rig_b);
    let latched = !out.bridge_enabled
        && !drive.stage().outputs_enabled
        && FaultCode(out.frame.faults).contains(FaultCode::MISSED_DEADLINE);
    drive.stage().late = false;
    let out = trigger(&mut drive, &mut rig_b);
    let stays_off = !out.bridge_enabled && FaultCode(out.frame.faults).contains(FaultCode::MISSED_DEADLINE);
    check(
        armed
            && on_while_counting
            && latched
            && stays_off
            && COUNTERS_DEADLINE.deadline_overruns.load(Ordering::Relaxed) == DEADLINE_LATCH_AFTER as u32
            && COUNTERS_DEADLINE.trips.load(Ordering::Relaxed) & trip::DEADLINE != 0,
        "deadline: late ticks counted, missed_deadline latched, bridge off in the 3rd late tick in a row",
    );
    // That was the third trip the board cannot verify with the bridge off (MOE lost, the
    // blocked arming, the deadline) within a minute: only a reset clears it.
    let refused = op.send(&mut drive, &Command::ClearFaults);
    check(
        refused.is_some_and(|r| {
            r.outcome == Err(Refusal::FaultStillPresent)
                && FaultCode(r.faults).contains(FaultCode::REPEATED_TRIPS)
                && FaultCode(r.faults).contains(FaultCode::MISSED_DEADLINE)
        }),
        "third unverifiable trip within a minute: repeated_trips latched, the clear command refused",
    );
    failures
}

/// Stack the smoke run may reach, of its region (the start of SRAM up to `.data`/`.bss`): a
/// quarter is kept free for what the board adds (the executor's task polls, interrupt frames).
const STACK_BUDGET_FRACTION: f32 = 0.75;

#[entry]
fn main() -> ! {
    firmware::stack::paint();
    let mut buf = [0u8; 128];
    let args = cmdline(&mut buf);
    if args.split_whitespace().any(|a| a == "stack-overflow") {
        stack_overflow_check();
    }
    let force_fail = args.split_whitespace().any(|a| a == "force-fail");

    let mut failures = open_loop(force_fail);
    failures += closed_loop(force_fail);
    failures += drive_loop();
    failures += gate_timing_deadline();
    let (peak, size) = (firmware::stack::peak(), firmware::stack::size());
    let budget = if force_fail { 0 } else { (STACK_BUDGET_FRACTION * size as f32) as usize };
    hprintln!("qemu-smoke: stack peak {} B of {} B (budget {} B)", peak, size, budget);
    if peak > budget {
        hprintln!("qemu-smoke: FAIL stack peak {} B over its budget {} B", peak, budget);
        failures += 1;
    }
    if failures == 0 {
        hprintln!("qemu-smoke: PASS");
        exit(0)
    } else {
        hprintln!("qemu-smoke: FAIL ({} checks failed)", failures);
        exit(1)
    }
}

/// The model-core workload against the host's checkpoints, and the open-loop tracking bound.
#[inline(never)]
fn open_loop(force_fail: bool) -> u32 {
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
            failures += compare(
                "Preisach compensated chain [µm]",
                &r.preisach_um,
                &EXPECTED_PREISACH_UM,
                1e-4,
                force_fail,
            );
            // Absolute: each open-loop compensated chain tracks a 50 Hz sine within 5 % RMS (the
            // J–A chain's residual is the uncompensated mechanics' phase lag).
            let limit = if force_fail { 0.0 } else { 5.0 };
            for (chain, rms, host) in [
                ("J–A", r.tracking_rms_percent, EXPECTED_TRACKING_RMS_PERCENT),
                ("Preisach", r.preisach_tracking_rms_percent, EXPECTED_PREISACH_TRACKING_RMS_PERCENT),
            ] {
                hprintln!("qemu-smoke: {} tracking RMS error {}% of amplitude (host {}%)", chain, rms, host);
                if !(rms <= limit) {
                    hprintln!("qemu-smoke: FAIL {} tracking error {}% > {}%", chain, rms, limit);
                    failures += 1;
                }
            }
        }
    }
    failures
}
