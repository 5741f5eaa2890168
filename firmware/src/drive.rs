//! The drive's interrupt, free of the HAL: one call of [`DriveLoop::on_conversion`] is the whole
//! work of the 10 kHz end-of-conversion interrupt (read the conversions, run the control tick,
//! write the bridge, feed the watchdog, check the deadline, queue the telemetry record). The
//! board (`gma-drive`) implements [`PowerStage`] with register writes; the QEMU bench and smoke
//! binaries implement it with memory stand-ins, so the instruction counts and checks they report
//! are those of the board's handler apart from the few register accesses.
//!
//! Telemetry leaves the interrupt as the raw [`TimedFrame`] through a single-producer
//! single-consumer queue; thread mode encodes (CRC + COBS) and sends it.
//!
//! The bridge's master output enable is written 1 only on the tick that arms, with no break
//! flag pending, and read back on every other armed tick ([`gma_control::gate`]); each
//! interrupt entry is timed with the cycle counter against the tick period
//! ([`gma_control::timing`]).

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use gma_control::command::{Command, Decoder, Received, Reply, MAX_REPLY_ENCODED};
use gma_control::current::CurrentLoopParams;
use gma_control::faults::FaultCode;
use gma_control::gate::{GateAction, OutputGate};
use gma_control::reference::Waveform;
use gma_control::telemetry::TimedFrame;
use gma_control::timing::TickPeriod;
use gma_control::units::{AdcCode, Volts, ADC_FULL_SCALE};
use gma_control::{ControlConfig, Controller, RawSample, StagedParameters, TickOutput};
use heapless::spsc::{Consumer, Producer, Queue};

/// PWM carrier [Hz]: 20 kHz, above hearing; center-aligned, so the counter's update events come
/// at 40 kHz and a repetition count of 3 gives one ADC trigger per 4 half-periods = 10 kHz.
pub const PWM_HZ: u32 = 20_000;

/// Bridge dead time [ns] from the reference board's parts (values as read from their datasheets;
/// check them against the revision of the parts fitted):
/// gate driver Infineon IR2110 — delay matching high/low side 10 ns max, turn-off fall time
/// 25 ns max; MOSFET Infineon IRF540N — turn-off delay 39 ns and fall time 35 ns (typical, so
/// taken twice). The driver's turn-on delay of the other side is not subtracted (margin).
pub const DEAD_TIME_NS: u32 = 10 + 25 + 2 * (39 + 35);

/// Settling of the coil-current amplifier's output after a bridge edge [ns]: an allowance for
/// the reference board's shunt amplifier (measure it with a scope and change it for another).
pub const CURRENT_SETTLE_NS: u32 = 1_000;

/// ADC clock [Hz]: SYSCLK 170 MHz / 4 (the HAL's prescaler for the G4's 60 MHz limit).
pub const ADC_CLOCK_HZ: u32 = 42_500_000;

/// Sampling time of every injected channel [ADC clock cycles × 2]: 24.5 cycles (SMPR = 24.5;
/// 576 ns at 42.5 MHz, enough for the amplifier's output impedance).
pub const SAMPLE_HALF_CYCLES: u32 = 49;

/// Largest bridge duty magnitude that keeps the current sample quiet: in center-aligned PWM the
/// bridge edges nearest the sample instant (counter peak or trough) are (1 − |d|) · T/4 away from
/// it on both sides (T = 50 µs). Before the sample the edge, the dead time and the amplifier's
/// settling must be over; after it, the edge must wait for the current channel's sampling phase:
/// |d| ≤ 1 − 4 · max(dead + settle, sampling) / T = 0.905 with the values above.
pub const fn quiet_window_max_duty() -> f32 {
    let before_ns = DEAD_TIME_NS + CURRENT_SETTLE_NS;
    let sample_ns = (SAMPLE_HALF_CYCLES as u64 * 1_000_000_000 / (2 * ADC_CLOCK_HZ as u64)) as u32;
    let need_ns = if before_ns > sample_ns { before_ns } else { sample_ns };
    let quarter_period_ns = 1_000_000_000 / (4 * PWM_HZ);
    1.0 - need_ns as f32 / quarter_period_ns as f32
}

/// Dead time in timer clock ticks for a timer clock of `timer_hz` [Hz], rounded up.
pub const fn dead_time_ticks(timer_hz: u32) -> u32 {
    ((DEAD_TIME_NS as u64 * timer_hz as u64).div_ceil(1_000_000_000)) as u32
}

/// Bus voltage divider of the reference board [V at the bus per V at the ADC pin]: 56 kΩ over
/// 3.3 kΩ, so the 3.3 V ADC range spans 0–59.3 V (the coil's energy pumps the 100 µF, 24 V bus
/// to 39.2 V on a 4 A trip, 41.7 V on a 4.4 A one; the divider must not saturate there).
pub const BUS_DIVIDER: f32 = (56.0 + 3.3) / 3.3;

/// ADC reference [V].
const ADC_VREF_V: f32 = 3.3;

/// The bus voltage a conversion code stands for.
pub fn bus_volts(code: u16) -> Volts {
    Volts(code as f32 * (ADC_VREF_V * BUS_DIVIDER / ADC_FULL_SCALE as f32))
}

/// The conversion code the bus voltage `v` gives (the simulated boards' ADC).
pub fn bus_code(v: Volts) -> u16 {
    let code = v.0 / (ADC_VREF_V * BUS_DIVIDER) * ADC_FULL_SCALE as f32 + 0.5;
    if code.is_nan() || code <= 0.0 {
        0
    } else if code >= ADC_FULL_SCALE as f32 {
        ADC_FULL_SCALE
    } else {
        code as u16
    }
}

/// The reference design on this board's bridge: its duty limit at the quiet-window clamp, so that
/// the current loop's anti-windup knows the clamp; the 100 Hz sine reference of the tests and
/// benchmarks. The board itself boots with [`boot_config`].
pub const fn control_config() -> ControlConfig {
    let r = ControlConfig::REFERENCE;
    ControlConfig {
        current_loop: CurrentLoopParams { max_duty: quiet_window_max_duty(), ..r.current_loop },
        ..r
    }
}

/// The configuration the board boots with: [`control_config`] holding the rest position (a
/// constant 0 µm reference) until a `reference` command sets a waveform, so that an `arm` sent
/// before any reference energises the coil without moving the rod. The reference design's 100 Hz
/// sine stays the workload of the tests and benchmarks.
pub const fn boot_config() -> ControlConfig {
    ControlConfig { reference: Waveform::Constant { bias: 0.0 }, ..control_config() }
}

// The board's boot reference holds rest: no waveform runs before one is commanded.
const _: () = assert!(matches!(boot_config().reference, Waveform::Constant { bias } if bias == 0.0));

/// Telemetry records buffered between the interrupt and thread mode (25 ms at 10 kHz; one slot
/// of the ring stays empty).
pub const TELEMETRY_QUEUE: usize = 256;
/// The queue's type.
pub type TelemetryQueue = Queue<TimedFrame, TELEMETRY_QUEUE>;

/// Consecutive missed deadlines that latch the bridge off: one late tick is counted (a flash
/// wait or a long telemetry burst), three in a row mean the loop no longer runs at its rate.
pub const DEADLINE_LATCH_AFTER: u8 = 3;

/// CPU clock [Hz] (gma-drive's clock tree: HSI 16 MHz / 4 × 85 / 2).
pub const SYSCLK_HZ: u32 = 170_000_000;
/// CPU cycles per control tick, as the cycle counter should count them between two interrupt
/// entries: 17 000 at 10 kHz.
pub const TICK_CYCLES: u32 =
    (SYSCLK_HZ as f64 * ControlConfig::REFERENCE.current_loop.tick_s as f64 + 0.5) as u32;
/// The tick period check: ±2 % of [`TICK_CYCLES`] over each window of 32 intervals, any single
/// interval off by half a period at once, the first 2 intervals after start-up not judged (see
/// [`gma_control::timing`] for why one interval out of ±2 % is only counted).
pub const fn tick_period_check() -> TickPeriod {
    TickPeriod::new(TICK_CYCLES, TICK_CYCLES / 50, 2)
}

/// What the interrupt needs from the hardware. Each method is a few register accesses on the
/// board.
pub trait PowerStage {
    /// The injected conversions of this trigger: coil current, displacement, bus voltage
    /// (raw codes); acknowledges them.
    fn read_conversions(&mut self) -> [u16; 3];
    /// Whether any break flag (break input 1, break input 2, system break) has been set since
    /// the last call; clears them (a flag whose source is still active stays set). The
    /// hardware has already forced the outputs off when it reads true.
    fn take_break_flags(&mut self) -> bool;
    /// Whether any break flag is set now (not cleared): asked right before MOE is written 1.
    fn break_pending(&self) -> bool;
    /// Timer compare values of leg A and leg B (preloaded: they take effect at the next update).
    fn set_compare(&mut self, leg_a: u16, leg_b: u16);
    /// Master output enable (false: the outputs go to their idle state, all gates low).
    fn set_outputs_enabled(&mut self, enabled: bool);
    /// The master output enable as read back (the hardware clears it on a break).
    fn outputs_enabled(&self) -> bool;
    /// Feeds the independent watchdog.
    fn feed_watchdog(&mut self);
    /// Whether the next conversion has already completed: the tick overran its period.
    fn next_conversion_done(&self) -> bool;
    /// A free-running CPU cycle counter [cycles].
    fn cycle_count(&self) -> u32;
    /// Whether the conversion came at the sampling edge the design expects (on the board: TIM1
    /// CR1.DIR read in the interrupt, `firmware::board_check`); stand-ins have none to check.
    fn sample_edge_ok(&self) -> bool {
        true
    }
}

/// What the interrupt has seen since boot (bits, for the status log). Each one also latches a
/// fault in the controller, which holds the bridge off and reports it in telemetry until a clear
/// command finds the cause gone.
pub mod trip {
    /// The break input tripped (gate-driver fault pin): `BRIDGE_BREAK`.
    pub const BREAK_INPUT: u32 = 1 << 0;
    /// [`super::DEADLINE_LATCH_AFTER`] consecutive ticks overran their period: `MISSED_DEADLINE`.
    pub const DEADLINE: u32 = 1 << 1;
    /// The controller asked for a duty that is not a finite number: `PARAMETERS_INVALID` (the
    /// model produced it; only a new parameter set clears it).
    pub const NON_FINITE_DUTY: u32 = 1 << 2;
    /// MOE read back 0 on an armed tick with no break flag seen: `BRIDGE_BREAK`.
    pub const OUTPUTS_LOST: u32 = 1 << 3;
    /// An arming tick found a break flag pending, before or right after its MOE write, and left
    /// MOE at 0: `BRIDGE_BREAK`.
    pub const ARMING_BLOCKED: u32 = 1 << 4;
    /// The interval between interrupt entries was not the tick period: `TICK_TIMING`.
    pub const TICK_PERIOD: u32 = 1 << 5;
    /// The board's configuration read back differently from its table, or a conversion came at
    /// the wrong counter edge (`firmware::board_check`): `PARAMETERS_INVALID`, latched again on
    /// every tick, so that nothing but a reset clears it.
    pub const BOARD_CHECK: u32 = 1 << 6;
}

/// Counters the interrupt publishes for thread mode (it is their only writer).
#[derive(Default)]
pub struct DriveCounters {
    /// Telemetry records the queue had no room for (the host sees them as sequence gaps).
    pub telemetry_dropped: AtomicU32,
    /// Ticks that overran their period.
    pub deadline_overruns: AtomicU32,
    /// [`trip`] bits seen since boot.
    pub trips: AtomicU32,
    /// Largest interrupt duration so far [cycles].
    pub max_tick_cycles: AtomicU32,
    /// Intervals between interrupt entries outside ±2 % of the tick period, one by one
    /// (interrupt latency included).
    pub period_off: AtomicU32,
    /// The last 32-interval window's length [cycles] (nominal 32 × [`TICK_CYCLES`]).
    pub last_window_cycles: AtomicU32,
}

impl DriveCounters {
    /// All zero.
    pub const fn new() -> Self {
        Self {
            telemetry_dropped: AtomicU32::new(0),
            deadline_overruns: AtomicU32::new(0),
            trips: AtomicU32::new(0),
            max_tick_cycles: AtomicU32::new(0),
            period_off: AtomicU32::new(0),
            last_window_cycles: AtomicU32::new(0),
        }
    }

    fn add(counter: &AtomicU32, n: u32) {
        counter.store(counter.load(Ordering::Relaxed).wrapping_add(n), Ordering::Relaxed);
    }
}

/// The board-check bit the interrupt sets when [`DEADLINE_LATCH_AFTER`] conversions in a row came
/// at the wrong counter edge (`firmware::board_check::route::SAMPLE_EDGE`).
pub const SAMPLE_EDGE_FAULT: u32 = 1 << 29;

/// Bridge timing: compare values from the signed duty.
#[derive(Debug, Clone, Copy)]
pub struct BridgeTiming {
    /// Timer auto-reload value (counter peak) [timer ticks].
    pub period_ticks: u16,
    /// Largest duty magnitude ([`quiet_window_max_duty`]).
    pub max_duty: f32,
}

impl BridgeTiming {
    /// Compare values of leg A and leg B for the signed duty `d` (bipolar full bridge: leg A at
    /// (1 + d)/2 of the period, leg B at (1 − d)/2), `d` limited to ±`max_duty`; a duty that is
    /// not a number gives 0 (both legs at half period).
    pub fn compare_values(&self, d: f32) -> (u16, u16) {
        let d = if d.is_nan() { 0.0 } else { d.clamp(-self.max_duty, self.max_duty) };
        let arr = self.period_ticks;
        let a = (0.5 * (1.0 + d) * arr as f32 + 0.5) as u16;
        let a = a.min(arr);
        (a, arr - a)
    }
}

/// The interrupt's state: the controller, the hardware, the telemetry producer and what the
/// firmware's own checks have seen.
pub struct DriveLoop<S: PowerStage> {
    controller: Controller,
    stage: S,
    timing: BridgeTiming,
    telemetry: Producer<'static, TimedFrame>,
    counters: &'static DriveCounters,
    late_in_a_row: u8,
    trips: u32,
    gate: OutputGate,
    period: TickPeriod,
    /// Since the period was last judged wrong: the clean-window count then (`tick_timing`
    /// stays latched until the count moves on).
    timing_suspect: Option<u32>,
    /// Mismatches of the board's configuration check (`firmware::board_check` bits; 0: none).
    board_faults: u32,
    /// Consecutive ticks whose conversion came at the wrong counter edge.
    wrong_edge_in_a_row: u8,
}

impl<S: PowerStage> DriveLoop<S> {
    /// The loop, with the bridge off (`stage` must start with the outputs disabled).
    pub fn new(
        controller: Controller,
        stage: S,
        timing: BridgeTiming,
        telemetry: Producer<'static, TimedFrame>,
        counters: &'static DriveCounters,
    ) -> Self {
        Self {
            controller,
            stage,
            timing,
            telemetry,
            counters,
            late_in_a_row: 0,
            trips: 0,
            gate: OutputGate::new(),
            period: tick_period_check(),
            timing_suspect: None,
            board_faults: 0,
            wrong_edge_in_a_row: 0,
        }
    }

    /// The board's configuration check at boot (`firmware::board_check`): any bit set refuses
    /// every arming until reset.
    pub fn set_board_faults(&mut self, mismatches: u32) {
        self.board_faults |= mismatches;
    }

    /// The configuration check's mismatches so far (the interrupt adds the sampling edge's).
    pub fn board_faults(&self) -> u32 {
        self.board_faults
    }

    /// The controller (faults, commands from thread mode).
    pub fn controller(&mut self) -> &mut Controller {
        &mut self.controller
    }

    /// The whole end-of-conversion interrupt; returns the tick's output. The bridge is enabled
    /// only when the controller allows it; the firmware's own trips latch controller faults,
    /// shown in this tick's telemetry record.
    pub fn on_conversion(&mut self) -> TickOutput {
        let start = self.stage.cycle_count();
        let period_wrong = self.period.entry(start);
        let [current, displacement, bus] = self.stage.read_conversions();
        let flags = self.stage.take_break_flags();
        // MOE read back before anything writes it: 0 while held on means the hardware took the
        // outputs off, whether or not a flag says why.
        let lost = self.gate.lost(self.stage.outputs_enabled());
        if flags {
            self.trips |= trip::BREAK_INPUT;
        }
        if lost {
            self.trips |= trip::OUTPUTS_LOST;
        }
        if period_wrong {
            self.trips |= trip::TICK_PERIOD;
            self.timing_suspect = Some(self.period.clean_windows);
        } else if self.timing_suspect.is_some_and(|at| self.period.clean_windows != at) {
            self.timing_suspect = None;
        }
        if self.stage.sample_edge_ok() {
            self.wrong_edge_in_a_row = 0;
        } else {
            // A late entry (a critical section in thread mode over 22 µs) reads the direction
            // after the next extreme: one such tick is latency; a wrong phase is every tick.
            self.wrong_edge_in_a_row = self.wrong_edge_in_a_row.saturating_add(1);
            if self.wrong_edge_in_a_row >= DEADLINE_LATCH_AFTER {
                self.board_faults |= SAMPLE_EDGE_FAULT;
            }
        }
        if self.board_faults != 0 {
            // Before the tick, as for the period: the controller holds the bridge off in it.
            self.trips |= trip::BOARD_CHECK;
            self.controller.latch_fault(FaultCode::PARAMETERS_INVALID);
        }
        if self.timing_suspect.is_some() {
            // Latched before the tick, so that the controller holds the bridge off in it, and
            // again on every tick until a whole window has been judged right: a clear command
            // before that cannot prove the period good again.
            self.controller.latch_fault(FaultCode::TICK_TIMING);
        }
        let raw = RawSample {
            current: AdcCode(current),
            displacement: AdcCode(displacement),
            bus: bus_volts(bus),
            break_tripped: flags || lost,
        };
        let mut out = self.controller.tick(&raw);
        if !out.duty.is_finite() {
            self.trips |= trip::NON_FINITE_DUTY;
            self.trip_now(&mut out, FaultCode::PARAMETERS_INVALID);
        }
        if lost {
            // The controller has latched it from `break_tripped`; whatever it returned, this
            // tick does not write MOE = 1 again.
            self.trip_now(&mut out, FaultCode::BRIDGE_BREAK);
        }
        let (a, b) = self.timing.compare_values(out.duty);
        self.stage.set_compare(a, b);
        let stage = &self.stage;
        match self.gate.decide(out.bridge_enabled, || stage.break_pending()) {
            GateAction::Hold => {}
            GateAction::Enable => {
                self.stage.set_outputs_enabled(true);
                // A break pulse between the pending check and the write left its flag set and
                // the outputs on: off again before the next PWM edge, latched.
                if self.gate.undo_enable(self.stage.break_pending()) {
                    self.stage.set_outputs_enabled(false);
                    self.trips |= trip::ARMING_BLOCKED;
                    self.trip_now(&mut out, FaultCode::BRIDGE_BREAK);
                }
            }
            GateAction::Disable => {
                self.stage.set_outputs_enabled(false);
                if out.bridge_enabled {
                    // The arming tick found a break flag set since the tick began.
                    self.trips |= trip::ARMING_BLOCKED;
                    self.trip_now(&mut out, FaultCode::BRIDGE_BREAK);
                }
            }
        }
        self.stage.feed_watchdog();
        if self.stage.next_conversion_done() {
            DriveCounters::add(&self.counters.deadline_overruns, 1);
            self.late_in_a_row = self.late_in_a_row.saturating_add(1);
            if self.late_in_a_row >= DEADLINE_LATCH_AFTER {
                // Off now, not at the next tick: that one is already late.
                self.trips |= trip::DEADLINE;
                self.trip_now(&mut out, FaultCode::MISSED_DEADLINE);
                self.gate.decide(false, || true);
                self.stage.set_outputs_enabled(false);
            }
        } else {
            self.late_in_a_row = 0;
        }
        self.counters.trips.store(self.trips, Ordering::Relaxed);
        self.counters.period_off.store(self.period.off, Ordering::Relaxed);
        self.counters.last_window_cycles.store(self.period.last_window, Ordering::Relaxed);
        let cycles = self.stage.cycle_count().wrapping_sub(start);
        if cycles > self.counters.max_tick_cycles.load(Ordering::Relaxed) {
            self.counters.max_tick_cycles.store(cycles, Ordering::Relaxed);
        }
        let record = TimedFrame { frame: out.frame, tick_cycles: cycles.min(u16::MAX as u32) as u16 };
        if self.telemetry.enqueue(record).is_err() {
            DriveCounters::add(&self.counters.telemetry_dropped, 1);
        }
        out
    }

    /// Latches `fault` in the controller (it disarms) and takes this tick's output to the safe
    /// state, its record showing the fault.
    fn trip_now(&mut self, out: &mut TickOutput, fault: FaultCode) {
        self.controller.latch_fault(fault);
        out.bridge_enabled = false;
        out.duty = 0.0;
        out.frame.faults |= fault.0;
    }
}

/// Replies waiting for thread mode's UART writer (one slot of the ring stays empty).
pub const REPLY_QUEUE: usize = 8;
/// The reply queue's type.
pub type ReplyQueue = Queue<Reply, REPLY_QUEUE>;

/// Thread-mode work a frame needs before it reaches the controller: a parameter load's
/// compensator is built into `staged` here (a Preisach model takes about 400 000 instructions,
/// more than the 2 ms watchdog), with the interrupt running; other frames leave it empty. Not
/// inlined: the build's temporaries then take stack only while a load runs, not in every
/// caller's frame.
#[inline(never)]
pub fn stage(received: &Received, staged: &mut StagedParameters) {
    if let Received::Command(_, Command::LoadParameters { spec, params }) = received {
        staged.rebuild(&boot_config(), *spec, params);
    }
}

/// Executes one decoded frame on the controller: a command (any valid one is the keep-alive) or
/// the refusal of an intact frame the decoder could not accept; a parameter load is only
/// moved in from `staged` ([`stage`] built it). The board calls it inside a critical section,
/// as the interrupt shares the controller.
pub fn execute<S: PowerStage>(
    drive: &mut DriveLoop<S>,
    received: &Received,
    staged: &mut StagedParameters,
) -> Reply {
    match received {
        Received::Command(tag, Command::LoadParameters { .. }) => {
            // A move holds the interrupt off for about 8 300 instructions (`qemu-bench
            // load-swap`), half a tick, with the bridge off (loads are refused while armed):
            // the late entry could pass the lost-tick limit; it is latency, not the period. A
            // refused load moves nothing and leaves the check running (a host sending loads
            // could otherwise keep it from ever judging a window).
            let reply = drive.controller.load_staged(*tag, staged);
            if reply.outcome.is_ok() {
                drive.period.resettle(2);
            }
            reply
        }
        Received::Command(tag, cmd) => drive.controller.command(*tag, cmd),
        Received::Refused { tag, opcode, reason } => drive.controller.refusal(*tag, *opcode, *reason),
    }
}

/// Thread-mode side of the command channel: the decoder (framing, CRC, version, payload; its
/// counters say what it threw away) and the producer of the replies.
pub struct CommandPort {
    /// The command decoder; `corrupt` counts frames with broken COBS or CRC (no reply: their tag
    /// cannot be trusted), `refused` intact frames refused.
    pub decoder: Decoder,
    replies: Producer<'static, Reply>,
    /// Replies the queue had no room for.
    pub replies_dropped: u32,
}

impl CommandPort {
    /// A port whose replies go to `replies`.
    pub fn new(replies: Producer<'static, Reply>) -> Self {
        Self { decoder: Decoder::default(), replies, replies_dropped: 0 }
    }

    /// Received bytes, split anywhere (COBS frames ended by their 0 delimiters): each frame that
    /// completes is staged ([`stage`], outside any lock) and goes to `execute_frame` — the
    /// board's runs [`execute`] on the controller inside a critical section — and its reply is
    /// queued. `execute_frame` returns `None` when there is no controller to answer (before
    /// start-up). Not inlined, for the same reason as [`stage`]: its frame holds the staged set.
    #[inline(never)]
    pub fn on_bytes(
        &mut self,
        bytes: &[u8],
        mut execute_frame: impl FnMut(&Received, &mut StagedParameters) -> Option<Reply>,
    ) {
        let mut staged = StagedParameters::empty();
        for &b in bytes {
            let Some(received) = self.decoder.push_command(b) else { continue };
            stage(&received, &mut staged);
            let reply = execute_frame(&received, &mut staged);
            // Whatever it held (the replaced compensator, a refused set) is dropped now, outside
            // the critical section.
            staged = StagedParameters::empty();
            let Some(reply) = reply else { continue };
            if self.replies.enqueue(reply).is_err() {
                self.replies_dropped = self.replies_dropped.wrapping_add(1);
            }
        }
    }
}

/// Thread-mode side of the replies: each queued reply COBS-encoded into `out` while it has room;
/// returns the bytes written. The telemetry writer sends them ahead of its next batch.
pub fn encode_replies(queue: &mut Consumer<'static, Reply>, out: &mut [u8]) -> usize {
    let mut n = 0;
    while out.len() - n >= MAX_REPLY_ENCODED {
        let Some(reply) = queue.dequeue() else { break };
        let mut frame = [0u8; MAX_REPLY_ENCODED];
        let len = reply.encode(&mut frame);
        out[n..n + len].copy_from_slice(&frame[..len]);
        n += len;
    }
    n
}

/// Thread-mode side of the telemetry: COBS frames (format 2) of the queued records appended to
/// `out` until it cannot take another frame; returns the bytes written.
pub fn encode_queued(queue: &mut Consumer<'static, TimedFrame>, out: &mut [u8]) -> usize {
    use gma_control::telemetry::MAX_ENCODED;
    let mut n = 0;
    while out.len() - n >= MAX_ENCODED {
        let Some(record) = queue.dequeue() else { break };
        let mut frame = [0u8; MAX_ENCODED];
        let len = record.encode(&mut frame);
        out[n..n + len].copy_from_slice(&frame[..len]);
        n += len;
    }
    n
}

/// Storage for one value that is written once at start-up and has no initial value: it costs
/// no flash (unlike a static with an initialiser) and needs no zeroing, so it can sit in a
/// section the startup code does not touch (CCM SRAM).
pub struct Slot<T>(UnsafeCell<MaybeUninit<T>>);

// SAFETY: the only access is `Slot::write`, whose contract gives the one `&'static mut` out once.
#[allow(unsafe_code)]
unsafe impl<T: Send> Sync for Slot<T> {}

impl<T> Slot<T> {
    /// An empty slot.
    pub const fn new() -> Self {
        Self(UnsafeCell::new(MaybeUninit::uninit()))
    }

    /// Moves `value` in and returns the only reference to it.
    ///
    /// # Safety
    /// Call at most once per slot (a second call would alias the first reference).
    #[allow(unsafe_code)]
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn write(&'static self, value: T) -> &'static mut T {
        // SAFETY: the caller calls this once, so no other reference to the contents exists.
        unsafe { (*self.0.get()).write(value) }
    }
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The power stage of the QEMU binaries: plain memory in place of the registers, with the break
/// and deadline events and the cycle counter set by the test.
#[cfg(feature = "qemu")]
#[derive(Debug, Default)]
pub struct MemoryStage {
    /// Codes the next `read_conversions` returns (current, displacement, bus).
    pub conversions: [u16; 3],
    /// Break flag (set by the test, cleared by the read).
    pub break_flag: bool,
    /// Whether the next conversion is reported as already done.
    pub late: bool,
    /// Last compare values (leg A, leg B).
    pub compare: [u16; 2],
    /// Master output enable (the test clears it as the hardware would on a break).
    pub outputs_enabled: bool,
    /// Writes of MOE = 1.
    pub enable_writes: u32,
    /// Watchdog feeds.
    pub watchdog_feeds: u32,
    /// The cycle counter (the test advances it by a tick period per trigger; QEMU has none).
    pub cycles: u32,
    /// A break that arrives during the next tick, after its flags were read (pending when the
    /// arming write is decided).
    pub break_during_tick: bool,
}

#[cfg(feature = "qemu")]
impl PowerStage for MemoryStage {
    fn read_conversions(&mut self) -> [u16; 3] {
        self.conversions
    }
    fn take_break_flags(&mut self) -> bool {
        let taken = core::mem::take(&mut self.break_flag);
        self.break_flag = core::mem::take(&mut self.break_during_tick);
        taken
    }
    fn break_pending(&self) -> bool {
        self.break_flag
    }
    fn set_compare(&mut self, leg_a: u16, leg_b: u16) {
        self.compare = [leg_a, leg_b];
    }
    fn set_outputs_enabled(&mut self, enabled: bool) {
        if enabled {
            self.enable_writes = self.enable_writes.wrapping_add(1);
        }
        self.outputs_enabled = enabled;
    }
    fn outputs_enabled(&self) -> bool {
        self.outputs_enabled
    }
    fn feed_watchdog(&mut self) {
        self.watchdog_feeds = self.watchdog_feeds.wrapping_add(1);
    }
    fn next_conversion_done(&self) -> bool {
        self.late
    }
    fn cycle_count(&self) -> u32 {
        self.cycles
    }
}

#[cfg(feature = "qemu")]
impl<S: PowerStage> DriveLoop<S> {
    /// The power stage (the QEMU binaries read and set its stand-in registers).
    pub fn stage(&mut self) -> &mut S {
        &mut self.stage
    }
}
