//! Hardware-independent drive control for giant-magnetostrictive actuators. The same code runs
//! on the STM32G474 board (called from the ADC interrupt), on the host in closed loop against a
//! simulated rig ([`sim`]), and in the QEMU smoke binary. One call per 10 kHz tick:
//!
//! ```text
//! ADC codes ─calibration→ current, displacement ─faults→ (trip: bridge off)
//! reference generator → inverse compensator (feedforward current) + incremental PID on
//! displacement → current reference → PI current loop → bridge duty;  telemetry frame
//! ```
#![cfg_attr(not(any(test, feature = "std")), no_std)]

pub mod calibration;
pub mod command;
pub mod crash;
pub mod current;
pub mod faults;
pub mod framing;
pub mod gate;
pub mod pid;
pub mod reference;
pub mod resonant;
pub mod sim;
pub mod telemetry;
pub mod tick;
pub mod timing;
pub mod units;
pub mod watchdog;

use model_core::{
    Actuator, ActuatorParams, Compensator, CompensatorState, MagnetizationLaw, ModelSpec, ParamError,
};

use crate::calibration::IdleCalibration;
use crate::command::{Command, Refusal, Reply};
use crate::current::{CurrentLoop, CurrentLoopParams};
use crate::faults::{FaultCode, FaultLimits, FaultMonitor};
use crate::pid::{Pid, PidParams, PidState};
use crate::reference::{Reference, Waveform};
use crate::resonant::{Resonant, ResonantParams};
use crate::telemetry::Frame;
use crate::units::{Amps, Calibration, Micrometres, Volts};

pub use crate::tick::{RawSample, TickOutput};

/// Everything the controller needs besides the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlConfig {
    /// Front-end scaling (the current zero is replaced by the one measured with the bridge off).
    pub calibration: Calibration,
    /// Current loop design.
    pub current_loop: CurrentLoopParams,
    /// Trip levels.
    pub limits: FaultLimits,
    /// Displacement reference at boot [µm, relative to the rest position] (a command replaces it).
    pub reference: Waveform,
    /// Ticks the compensator looks ahead on the reference: the current loop's lag (its pole and
    /// the PWM update's one-tick delay) and the mechanics'.
    pub preview_ticks: u32,
    /// Displacement PID; `None` runs the compensator alone (open loop). The PID sees the current
    /// loop's lag plus the PWM update's tick behind it: an integral gain of 0.02 A/µm per tick
    /// (the earlier design) now rings, 0.04 is unstable. The derivative adds the phase lead that
    /// buys the integral back; the reference gains sit at 0.4× the integral gain that goes
    /// unstable (tuned on our simulated rig with the delay, `tests/closed_loop.rs`).
    pub pid: Option<PidParams>,
    /// Rejection of the repeating error at a sine reference's fundamental and its harmonics;
    /// `None`: PID only.
    pub resonant: Option<ResonantParams>,
    /// Largest current reference [A].
    pub max_current_a: f32,
    /// Ticks without a valid command (or keep-alive) after which an armed bridge disarms.
    pub command_timeout_ticks: u32,
    /// Samples per bridge-off calibration window (current zero and rest position), taken at
    /// boot and again whenever the bridge is off; arming needs one completed since the bridge
    /// was last on.
    pub offset_calibration_ticks: u16,
    /// Bridge-off ticks skipped before such a window after a run (the coil current decays
    /// through the body diodes, the rod comes to rest).
    pub calibration_settle_ticks: u16,
    /// Largest |bias| + amplitude a commanded reference may have [µm].
    pub max_reference_um: f32,
    /// Largest change of the compensator's target per tick [µm]: a step of the reference (a
    /// square wave, a new bias, arming at a bias) reaches the inverse model as a ramp, which
    /// bounds its Jiles–Atherton sub-steps and so the tick's worst-case time; the PID still sees
    /// the step.
    pub max_feedforward_slew_um: f32,
    /// Driving the coil's current to zero before the bridge opens, on a software trip and on a
    /// disarm; [`DrainParams::NONE`] opens it at once (the coil's energy then goes into the bus).
    pub drain: DrainParams,
}

/// How the controller brings the coil's current to zero before it opens the bridge (a software
/// trip, a disarm): the current loop runs on with its reference at 0 A and its regeneration
/// limit ([`current::RegenLimit`]), so the coil's ½ L I² goes into the bus only as far as the
/// bus can take it and the rest into the winding's resistance. The bridge opens when the
/// current is below `done_a` in two ticks in a row, after `max_ticks` whatever the current,
/// and at once on a fault where switching can feed the fault or the loop cannot be trusted
/// ([`FaultCode::OPENS_AT_ONCE`]: a break, a missed deadline, a wrong tick period, an invalid
/// design, the current sensor at a rail), on a non-finite current, above `abort_a` (a short:
/// the loop cannot bring that down), or when the current does not fall once the last duty
/// written before the trip has played out (from the third tick on, a rise of more than
/// `rise_margin_a` from one tick to the next).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrainParams {
    /// Longest drain [ticks]; 0: no drain.
    pub max_ticks: u16,
    /// Current below which the drain is done [A].
    pub done_a: f32,
    /// Current above which the bridge opens at once [A].
    pub abort_a: f32,
    /// Largest rise from one tick to the next the drain tolerates from its third tick [A].
    pub rise_margin_a: f32,
}

impl DrainParams {
    /// The reference coil: 10 ms at most (4 A with no regeneration left decays to 0.05 A in
    /// 4.4 ms at the nominal inductance, 6.6 ms at 1.5 L), done at 50 mA (12 codes; 7.5 µJ left
    /// for the bus), open at once above 4.5 A (the 4 A trip seen one tick late on a short
    /// reads about 4.4 A), a rise of 20 mA (5 codes) tolerated.
    pub const REFERENCE: DrainParams =
        DrainParams { max_ticks: 100, done_a: 0.05, abort_a: 4.5, rise_margin_a: 0.02 };

    /// No drain: the bridge opens in the tick of the trip or the disarm (the design before).
    pub const NONE: DrainParams = DrainParams { max_ticks: 0, ..Self::REFERENCE };
}

impl ControlConfig {
    /// The reference board tracking a 100 Hz sine of 12.5 µm (25 µm peak to peak) about 15 µm,
    /// with the repeating error learned at 100, 200 and 300 Hz (time constant about 1000 ticks);
    /// disarms 200 ms after the last command, averages 256 samples (25.6 ms) for the current
    /// zero and the rest position (after 5 ms of settling once the bridge was on: 4 A decays
    /// against a 12 V bus in 2 ms), accepts references within ±50 µm of rest.
    pub const REFERENCE: ControlConfig = ControlConfig {
        calibration: Calibration::REFERENCE_BOARD,
        current_loop: CurrentLoopParams::REFERENCE,
        limits: FaultLimits::REFERENCE,
        reference: Waveform::Sine { freq_hz: 100.0, amplitude: 12.5, bias: 15.0 },
        preview_ticks: 4,
        pid: Some(PidParams { kp: 0.01, ki: 0.016, kd: 0.04, limit_a: 1.0 }),
        resonant: Some(ResonantParams {
            gain_a_per_um: 0.0005,
            phase_lead_rad: [70.0 * DEGREE; 3],
            max_freq_hz: 250.0,
            limit_a: 1.0,
            max_error_um: 1.0,
        }),
        max_current_a: 3.5,
        command_timeout_ticks: 2000,
        offset_calibration_ticks: 256,
        calibration_settle_ticks: 50,
        max_reference_um: 50.0,
        max_feedforward_slew_um: SLEW_UM_PER_TICK,
        drain: DrainParams::REFERENCE,
    };
}

/// The reference design's feedforward slew limit [µm per tick]: 2 µm per 100 µs = 20 mm/s, above
/// the 7.9 mm/s of the 100 Hz, 25 µm peak-to-peak sine (a 250 Hz sine up to 12.7 µm amplitude
/// passes unchanged).
const SLEW_UM_PER_TICK: f32 = 2.0;

/// One degree [rad].
const DEGREE: f32 = core::f32::consts::PI / 180.0;

/// Why the board last reset (read from the reset controller at boot).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetCause {
    /// Power applied.
    PowerOn,
    /// Supply brown-out.
    Brownout,
    /// The reset pin (button, debugger).
    Pin,
    /// A software reset (requested by the firmware).
    Software,
    /// The independent or window watchdog: the firmware hung. Boots with `WATCHDOG_RESET`
    /// latched.
    Watchdog,
    /// An illegal low-power mode entry (a firmware error, but not a hang).
    LowPower,
    /// No reset flag set (flags cleared without a reset since).
    Unknown,
}

impl ResetCause {
    /// The cause from the STM32 reset controller's flags (RCC_CSR: IWDGRSTF, WWDGRSTF, SFTRSTF,
    /// BORRSTF, PINRSTF, LPWRRSTF). Every internal reset also pulls NRST low, so the pin flag
    /// comes with all of them and counts only alone; a watchdog wins over everything else.
    pub fn from_rcc_flags(
        iwdg: bool,
        wwdg: bool,
        software: bool,
        brown_out: bool,
        pin: bool,
        low_power: bool,
    ) -> Self {
        if iwdg || wwdg {
            Self::Watchdog
        } else if low_power {
            Self::LowPower
        } else if software {
            Self::Software
        } else if brown_out {
            // BORRSTF is set by power-on as well as by a brown-out; the two cannot be told apart.
            Self::PowerOn
        } else if pin {
            Self::Pin
        } else {
            Self::Unknown
        }
    }
}

/// The controller: fixed configuration and model, plus the state stepped every tick. It boots
/// disarmed (bridge off, not switching) and arms only on an explicit command.
pub struct Controller {
    cfg: ControlConfig,
    /// The front end's scaling with the measured current zero.
    calibration: Calibration,
    /// Bridge-off windows for the current zero and the rest position.
    idle: IdleCalibration,
    /// Whether a current zero has been measured and adopted.
    zero_measured: bool,
    /// Whether the first window since boot has been judged (its faults latched).
    boot_window_judged: bool,
    armed: bool,
    /// Whether the configuration (current loop, PID, timing) validated at construction.
    design_valid: bool,
    current_loop: CurrentLoop,
    reference: Reference,
    compensator: Option<(Compensator, CompensatorState)>,
    /// Model displacement at rest [m] (the compensator's zero).
    model_rest_m: f32,
    /// The compensator's target at the last tick [µm from rest], slew-limited.
    feedforward_target_um: f32,
    faults: FaultMonitor,
    seq: u32,
    /// Displacement at rest [µm, absolute], the reference's zero: the latest good bridge-off
    /// window before the first arming (0 before there is one), then fixed.
    rest_um: f32,
    /// Whether the bridge has been armed since boot (the rest position is fixed from then on).
    rest_fixed: bool,
    pid: Option<(Pid, PidState)>,
    resonant: Option<Resonant>,
    ticks_since_command: u32,
    last_raw: RawSample,
    /// While the current is driven to zero before the bridge opens: the ticks so far.
    drain_ticks: Option<u16>,
    /// The current the drain saw last tick [A].
    drain_last_a: f32,
    /// Ticks of the drain below `done_a` in a row.
    drain_quiet: u8,
}

impl Controller {
    /// Builds the controller for `spec` with the identified `params` (from `gma fit`); the
    /// compensator inverts [`compensator_model`]. A rejected parameter set or controller design
    /// (current loop, PID) latches `PARAMETERS_INVALID`; a watchdog `reset` latches
    /// `WATCHDOG_RESET`. Either way it starts disarmed. After any reset but a power-on the coil
    /// I²t starts at its budget (the coil may be hot; BORRSTF also marks a brown-out, which
    /// cannot be told from a power-on and so starts cold).
    pub fn new(cfg: ControlConfig, spec: ModelSpec, params: &ActuatorParams, reset: ResetCause) -> Self {
        let mut faults = FaultMonitor::new(cfg.limits);
        if reset == ResetCause::Watchdog {
            faults.latch(FaultCode::WATCHDOG_RESET);
        }
        if reset != ResetCause::PowerOn {
            faults.start_hot();
        }
        let current_loop = CurrentLoop::new(cfg.current_loop);
        let pid = cfg.pid.map(Pid::new);
        let resonant = cfg.resonant.map(Resonant::new);
        let design_valid = current_loop.is_ok()
            && !matches!(pid, Some(Err(_)))
            && !matches!(resonant, Some(Err(_)))
            && cfg.command_timeout_ticks > 0
            && cfg.offset_calibration_ticks > 0
            && cfg.limits.is_valid()
            && cfg.max_reference_um.is_finite()
            && cfg.max_reference_um > 0.0
            && cfg.max_feedforward_slew_um.is_finite()
            && cfg.max_feedforward_slew_um > 0.0;
        if !design_valid {
            faults.latch(FaultCode::PARAMETERS_INVALID);
        }
        let current_loop = current_loop.unwrap_or(CurrentLoop::idle());
        let pid = pid.and_then(Result::ok).map(|p| (p, PidState::default()));
        let resonant = resonant.and_then(Result::ok);
        let mut c = Self {
            cfg,
            calibration: cfg.calibration,
            idle: IdleCalibration::new(cfg.offset_calibration_ticks, cfg.calibration_settle_ticks),
            zero_measured: false,
            boot_window_judged: false,
            armed: false,
            design_valid,
            current_loop,
            reference: Reference::new(cfg.reference, cfg.current_loop.tick_s),
            compensator: None,
            model_rest_m: 0.0,
            feedforward_target_um: 0.0,
            faults,
            seq: 0,
            rest_um: 0.0,
            rest_fixed: false,
            pid,
            resonant,
            ticks_since_command: 0,
            drain_ticks: None,
            drain_last_a: 0.0,
            drain_quiet: 0,
            last_raw: RawSample {
                current: Default::default(),
                displacement: Default::default(),
                bus: Volts(0.0),
                break_tripped: false,
            },
        };
        if c.install_compensator(spec, params).is_err() {
            c.faults.latch(FaultCode::PARAMETERS_INVALID);
        }
        c
    }

    /// Builds the compensator for `spec` with `params` and moves it into the controller (the one
    /// before stays when the set is refused). One layer: the model holds a Preisach table of
    /// 4 KB, and every layer that returned it by value kept a copy on the stack of a `load`
    /// command, the deepest path.
    fn install_compensator(&mut self, spec: ModelSpec, params: &ActuatorParams) -> Result<(), ParamError> {
        build_compensator_into(&mut self.compensator, &mut self.model_rest_m, spec, params, &self.cfg)
    }

    /// A controller whose parameter set could not even be read: PARAMETERS_INVALID latched, the
    /// bridge never enabled until a valid set is loaded by command.
    pub fn refused(cfg: ControlConfig, reset: ResetCause) -> Self {
        let mut c = Self::new(cfg, ModelSpec::LINEAR, &ActuatorParams::TERFENOL_DEMO, reset);
        c.compensator = None;
        c.faults.latch(FaultCode::PARAMETERS_INVALID);
        c
    }

    /// Latches a fault the firmware detected outside the tick (a missed deadline): the bridge goes
    /// off at the next tick at the latest, and it stays latched until a clear command.
    pub fn latch_fault(&mut self, f: FaultCode) {
        self.faults.latch(f);
        if !f.is_clear() {
            if self.armed {
                self.begin_drain();
            }
            self.armed = false;
            if f.0 & FaultCode::OPENS_AT_ONCE.0 != 0 {
                self.drain_ticks = None;
            }
        }
    }

    /// Starts driving the current to zero (when the design does so), from an armed bridge.
    fn begin_drain(&mut self) {
        if self.cfg.drain.max_ticks > 0 && self.armed {
            self.drain_ticks = Some(0);
            self.drain_quiet = 0;
            self.drain_last_a = f32::INFINITY;
        }
    }

    /// Whether the bridge is still on after a trip or a disarm, driving the coil's current to
    /// zero ([`DrainParams`]).
    pub fn draining(&self) -> bool {
        self.drain_ticks.is_some()
    }

    /// Latched faults.
    pub fn faults(&self) -> FaultCode {
        self.faults.latched()
    }

    /// Whether the bridge is armed (switching).
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// The current channel's zero [V] from the latest good bridge-off window, once there is one.
    pub fn current_zero_v(&self) -> Option<f32> {
        self.zero_measured.then_some(self.calibration.current_zero_v)
    }

    /// The rest position [µm, absolute] the reference is relative to (0 before the first good
    /// bridge-off window; fixed at the first arming).
    pub fn rest_um(&self) -> f32 {
        self.rest_um
    }

    /// The bridge-off calibration (its latest window).
    pub fn idle_calibration(&self) -> &IdleCalibration {
        &self.idle
    }

    /// The explicit recovery command, given the present measurements: clears what is no longer
    /// present and restarts the loops from rest. Returns what stays latched. It never arms.
    pub fn clear_faults(&mut self, raw: &RawSample) -> FaultCode {
        let i = self.calibration.current(raw.current);
        // The calibration faults as the latest window shows them; none since the bridge was on:
        // unknown, so they stay.
        let calibration = match self.idle.latest() {
            Some(m) => m.faults,
            None => FaultCode(self.faults.latched().0 & FaultCode::CALIBRATION.0),
        };
        self.faults.clear(raw, i, calibration)
    }

    /// Executes one command (decoded by [`command::Decoder`]); any valid command is also the
    /// keep-alive. Returns the reply to send.
    pub fn command(&mut self, tag: u8, cmd: &Command) -> Reply {
        self.ticks_since_command = 0;
        let outcome = match cmd {
            Command::Ping => Ok(()),
            Command::Arm => self.arm(),
            Command::Disarm => {
                self.begin_drain();
                self.armed = false;
                Ok(())
            }
            Command::ClearFaults => {
                let raw = self.last_raw;
                if self.clear_faults(&raw).is_clear() {
                    Ok(())
                } else {
                    Err(Refusal::FaultStillPresent)
                }
            }
            Command::SetReference(r) => {
                let max_hz = 1.0 / (6.0 * self.cfg.current_loop.tick_s);
                r.waveform(self.cfg.max_reference_um, max_hz).map(|w| {
                    self.reference = Reference::new(w, self.cfg.current_loop.tick_s);
                    if let Some(res) = self.resonant.as_mut() {
                        res.reset();
                    }
                })
            }
            Command::LoadParameters { spec, params } => self.load(*spec, params),
        };
        self.reply(tag, cmd.opcode(), outcome)
    }

    /// The reply for a frame the decoder refused (its tag and opcode, the reason).
    pub fn refusal(&self, tag: u8, opcode: u8, reason: Refusal) -> Reply {
        self.reply(tag, opcode, Err(reason))
    }

    fn reply(&self, tag: u8, opcode: u8, outcome: Result<(), Refusal>) -> Reply {
        Reply { tag, opcode, outcome, faults: self.faults().0, armed: self.armed }
    }

    fn arm(&mut self) -> Result<(), Refusal> {
        if self.armed {
            return Ok(());
        }
        // Still bringing the current down after the last run: not measured with the bridge off.
        if self.drain_ticks.is_some() {
            return Err(Refusal::NotCalibrated);
        }
        if !self.faults().is_clear() {
            return Err(Refusal::FaultLatched);
        }
        // A current zero and rest position measured since the bridge was last on (adopted when
        // their window completed); a bad one is latched by name.
        match self.idle.latest() {
            None => return Err(Refusal::NotCalibrated),
            Some(m) if !m.faults.is_clear() => {
                let f = m.faults;
                self.faults.latch(f);
                return Err(Refusal::FaultLatched);
            }
            // The kept rest is the reference's zero: a probe that slipped since would move it
            // (a NaN distance counts as too far).
            Some(m)
                if self.rest_fixed && {
                    let shift = (m.rest_um - self.rest_um).abs();
                    shift.is_nan() || shift > self.cfg.limits.rest_max_shift_um
                } =>
            {
                self.faults.latch(FaultCode::REST_POSITION);
                return Err(Refusal::FaultLatched);
            }
            Some(_) => {}
        }
        if !self.cfg.limits.bus_healthy(self.last_raw.bus.0) {
            return Err(Refusal::BusOutOfRange);
        }
        // Start from rest: the loops, the compensator and the reference's phase.
        self.current_loop.reset();
        if let Some((_, s)) = self.pid.as_mut() {
            *s = PidState::default();
        }
        if let Some((c, s)) = self.compensator.as_mut() {
            *s = c.rest_state();
        }
        self.feedforward_target_um = 0.0;
        if let Some(res) = self.resonant.as_mut() {
            res.reset();
        }
        self.reference = Reference::new(self.reference.waveform(), self.cfg.current_loop.tick_s);
        // The next arming needs a new measurement, taken after this run. The rest position
        // stays this one: after a run the rod's zero-current position includes its remanent
        // strain (10 µm on the demo rod), and re-taking it would move the reference's frame
        // by that much from run to run; later windows are checked, not adopted.
        self.idle.invalidate();
        self.rest_fixed = true;
        self.armed = true;
        Ok(())
    }

    /// A new parameter set, validated as at boot; only while disarmed. Clears
    /// `PARAMETERS_INVALID` when the set is good.
    fn load(&mut self, spec: ModelSpec, params: &ActuatorParams) -> Result<(), Refusal> {
        if self.armed {
            return Err(Refusal::Armed);
        }
        // A configuration refused at boot (current loop, PID, timing) stays refused.
        if !self.design_valid {
            return Err(Refusal::InvalidParameters);
        }
        self.install_compensator(spec, params).map_err(|_| Refusal::InvalidParameters)?;
        self.faults.release(FaultCode::PARAMETERS_INVALID);
        Ok(())
    }

    /// A parameter set whose compensator was built outside the controller
    /// ([`StagedParameters::build`], on the board in thread mode with the interrupt running):
    /// refused as [`Controller::command`]'s load is, otherwise moved in (the only work done
    /// where the interrupt is locked out); `staged` is left empty. Also the keep-alive, as any
    /// command. Not inlined: the move's temporary then takes stack only while it runs.
    #[inline(never)]
    pub fn load_staged(&mut self, tag: u8, staged: &mut StagedParameters) -> Reply {
        self.ticks_since_command = 0;
        let outcome = if self.armed {
            Err(Refusal::Armed)
        } else if !self.design_valid || !staged.valid {
            Err(Refusal::InvalidParameters)
        } else {
            // A move, not a swap: the replaced compensator needs no keeping, and one copy is
            // the least time the interrupt is held off.
            self.compensator = staged.compensator.take();
            self.model_rest_m = staged.model_rest_m;
            staged.valid = false;
            self.faults.release(FaultCode::PARAMETERS_INVALID);
            Ok(())
        };
        self.reply(tag, command::LOAD_PARAMETERS, outcome)
    }

    /// A bridge-off sample for the calibration windows. A window's good parts are adopted at
    /// once (the current zero always, the rest position until the first arming); the first
    /// window since boot latches its faults.
    fn calibrate(&mut self, raw: &RawSample) {
        let Some(m) = self.idle.sample(raw, &self.cfg.calibration, &self.cfg.limits) else { return };
        if !self.boot_window_judged {
            self.boot_window_judged = true;
            self.faults.latch(m.faults);
        }
        if !m.faults.contains(FaultCode::CURRENT_OFFSET) {
            self.calibration.current_zero_v = m.current_zero_v;
            self.zero_measured = true;
        }
        if !m.faults.contains(FaultCode::REST_POSITION) && !self.rest_fixed {
            self.rest_um = m.rest_um;
        }
    }

    /// The safe state, in this very tick: disarmed (re-arming takes a clear and an arm
    /// command), the bridge off, the record showing `faults`.
    fn safe_output(&mut self, seq: u32, i: Amps, y: Micrometres, faults: FaultCode) -> TickOutput {
        self.armed = false;
        self.drain_ticks = None;
        self.current_loop.reset();
        TickOutput {
            duty: 0.0,
            bridge_enabled: false,
            frame: Frame {
                seq,
                reference_um: 0.0,
                command_v: 0.0,
                current_a: i.0,
                displacement_um: y.0,
                faults: faults.0,
            },
        }
    }

    /// One tick of the drain, or `None` when the bridge opens now (done, given up, or none).
    fn drain(
        &mut self,
        seq: u32,
        i: Amps,
        y: Micrometres,
        faults: FaultCode,
        bus: Volts,
    ) -> Option<TickOutput> {
        let (n, d) = (self.drain_ticks?, self.cfg.drain);
        let a = i.0.abs();
        let give_up = faults.0 & FaultCode::OPENS_AT_ONCE.0 != 0
            || a.is_nan()
            || a > d.abort_a
            || n >= d.max_ticks
            || (n >= 2 && a > self.drain_last_a + d.rise_margin_a);
        self.drain_quiet = if a < d.done_a { self.drain_quiet.saturating_add(1) } else { 0 };
        if give_up || self.drain_quiet >= 2 {
            self.drain_ticks = None;
            return None;
        }
        self.drain_ticks = Some(n + 1);
        self.drain_last_a = a;
        let cmd = self.current_loop.step(Amps(0.0), i, bus);
        if !cmd.duty.is_finite() {
            self.drain_ticks = None;
            return None;
        }
        Some(TickOutput {
            duty: cmd.duty,
            bridge_enabled: true,
            frame: Frame {
                seq,
                reference_um: 0.0,
                command_v: cmd.voltage.0,
                current_a: i.0,
                displacement_um: y.0,
                faults: faults.0,
            },
        })
    }

    /// One control tick.
    pub fn tick(&mut self, raw: &RawSample) -> TickOutput {
        self.last_raw = *raw;
        if !self.armed && self.drain_ticks.is_none() {
            self.calibrate(raw);
        }
        let cal = &self.calibration;
        let tick_s = self.cfg.current_loop.tick_s;
        let i = cal.current(raw.current);
        let y = Micrometres(cal.displacement(raw.displacement).0 - self.rest_um);
        self.ticks_since_command = self.ticks_since_command.saturating_add(1);
        if self.armed && self.ticks_since_command > self.cfg.command_timeout_ticks {
            self.faults.latch(FaultCode::COMMAND_TIMEOUT);
        }
        let faults = self.faults.check(raw, i, y, tick_s);
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        if self.armed && !faults.is_clear() {
            // A trip: the current is driven to zero first where that is safe.
            self.begin_drain();
            self.armed = false;
        }
        if !self.armed {
            if let Some(out) = self.drain(seq, i, y, faults, raw.bus) {
                return out;
            }
            return self.safe_output(seq, i, y, faults);
        }
        let fundamental = self.reference.fundamental();
        let r = self.reference.advance();
        // Feedforward: the current the inverse model says gives the reference `preview` ticks on.
        let ahead = self.reference.peek_ahead(self.cfg.preview_ticks.saturating_sub(1));
        let slew = self.cfg.max_feedforward_slew_um;
        self.feedforward_target_um += (ahead - self.feedforward_target_um).clamp(-slew, slew);
        let i_ff = match self.compensator.as_mut() {
            Some((c, s)) => c.step(s, self.model_rest_m + self.feedforward_target_um * 1e-6),
            None => 0.0,
        };
        let i_pid = match self.pid.as_mut() {
            Some((pid, s)) => pid.step(s, r - y.0),
            None => 0.0,
        };
        let i_res = match (self.resonant.as_mut(), fundamental) {
            (Some(res), Some((f, phasor))) if res.runs_at(f) => res.step(r - y.0, phasor),
            _ => 0.0,
        };
        let max_i = self.cfg.max_current_a;
        let i_ref = (i_ff + i_pid + i_res).clamp(-max_i, max_i);
        if !i_ref.is_finite() {
            // The model or a loop produced a NaN: the current loop would make it 0 V with the
            // bridge on and nothing latched. Only a valid parameter set clears it.
            self.faults.latch(FaultCode::PARAMETERS_INVALID);
            return self.safe_output(seq, i, y, self.faults.latched());
        }
        let cmd = self.current_loop.step(Amps(i_ref), i, raw.bus);
        TickOutput {
            duty: cmd.duty,
            bridge_enabled: true,
            frame: Frame {
                seq,
                reference_um: r,
                command_v: cmd.voltage.0,
                current_a: i.0,
                displacement_um: y.0,
                faults: 0,
            },
        }
    }
}

/// The model the inverse compensator inverts: `spec` with `params` at the tick period, less the
/// effects the registry leaves to feedback (`Inverse::LeftToFeedback`: the amplifier, as the
/// current loop is the amplifier; the mechanics and the sensor delay, which the PID handles).
/// `firmware/build.rs` and `gma drive load` build it too, so that a set the board would refuse
/// fails the build or is never sent. A Jiles–Atherton set with α·M_s/(3a) ≥ 1 is refused, as
/// every fit refuses it: its anhysteretic curve is multivalued, so the M(H) the compensator
/// inverts would be an artefact of its step size, not of the rod.
pub fn compensator_model(
    spec: ModelSpec,
    params: &ActuatorParams,
    tick_s: f32,
) -> Result<Actuator, ParamError> {
    let mut p = *params;
    p.dt_s = tick_s;
    let model = Actuator::new(spec.for_compensator(), &p)?;
    if spec.law() == MagnetizationLaw::JilesAtherton && params.ja.mean_field_ratio() >= 1.0 {
        return Err(ParamError::OutOfRange(
            "ja.alpha",
            "below 3a/M_s (α·M_s/(3a) < 1: a single-valued anhysteretic curve, which the compensator inverts)",
        ));
    }
    Ok(model)
}

/// The compensator for `spec` with `params` at `cfg`'s tick, moved into `slot` (left as it was
/// when the set is refused), and the model's rest displacement into `rest_m`. It asks for no
/// more than `cfg.max_current_a`, the most the controller applies, so its states never wind up
/// beyond what the coil gets. The one build path of the controller and of a staged load: not
/// inlined, so that its code exists once.
#[inline(never)]
fn build_compensator_into(
    slot: &mut Option<(Compensator, CompensatorState)>,
    rest_m: &mut f32,
    spec: ModelSpec,
    params: &ActuatorParams,
    cfg: &ControlConfig,
) -> Result<(), ParamError> {
    let model = compensator_model(spec, params, cfg.current_loop.tick_s)?;
    let c = Compensator::with_current_limit(model, cfg.max_current_a)?;
    *rest_m = c.model().rest_state().mech.displacement_m;
    let s = c.rest_state();
    *slot = Some((c, s));
    Ok(())
}

/// A parameter set's compensator built ahead of [`Controller::load_staged`]: the model build
/// (about 400 000 instructions for a Preisach set, more than 2 ms) runs without locking the
/// controller, and the controller only moves it in.
pub struct StagedParameters {
    compensator: Option<(Compensator, CompensatorState)>,
    model_rest_m: f32,
    valid: bool,
}

impl StagedParameters {
    /// Builds and validates the compensator for `spec` with `params` at `cfg`'s tick, as
    /// [`Controller::new`] does.
    pub fn build(cfg: &ControlConfig, spec: ModelSpec, params: &ActuatorParams) -> Self {
        let mut s = Self::empty();
        s.rebuild(cfg, spec, params);
        s
    }

    /// Nothing staged (a load with it is refused).
    pub const fn empty() -> Self {
        Self { compensator: None, model_rest_m: 0.0, valid: false }
    }

    /// [`StagedParameters::build`] in place (no second copy of the compensator on the stack).
    pub fn rebuild(&mut self, cfg: &ControlConfig, spec: ModelSpec, params: &ActuatorParams) {
        self.valid =
            build_compensator_into(&mut self.compensator, &mut self.model_rest_m, spec, params, cfg).is_ok();
    }

    /// Whether the set validated (and has not been installed yet).
    pub fn is_valid(&self) -> bool {
        self.valid
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{ReferenceCommand, Shape};
    use crate::sim::{CoilActuator, Rig};

    /// The demo set's controller on its simulated rig, calibrated and armed (tag 1).
    fn armed_on_the_demo_rig() -> (Controller, Rig<CoilActuator>, ControlConfig, ModelSpec, ActuatorParams) {
        let spec = ModelSpec::parse("ja+eddy+mech").unwrap();
        let p = ActuatorParams::TERFENOL_DEMO;
        let mut rig = Rig::new(CoilActuator::new(spec, &p, 1e-4).unwrap(), 1);
        let cfg = ControlConfig::REFERENCE;
        let mut ctl = Controller::new(cfg, spec, &p, ResetCause::PowerOn);
        for _ in 0..cfg.offset_calibration_ticks {
            let out = ctl.tick(&rig.sample());
            rig.apply(&out).unwrap();
        }
        assert_eq!(ctl.command(1, &Command::Arm).outcome, Ok(()));
        (ctl, rig, cfg, spec, p)
    }

    /// A NaN current reference (here from a NaN reference value through the PID; a model can
    /// produce one the same way): before, the current loop turned it into 0 V with the bridge
    /// enabled and nothing latched. Now the tick that sees it is the safe state, with
    /// `parameters_invalid` latched until a valid parameter set is loaded.
    #[test]
    fn a_non_finite_current_reference_is_the_safe_state_with_parameters_invalid() {
        let (mut ctl, mut rig, cfg, spec, p) = armed_on_the_demo_rig();
        for _ in 0..20 {
            let out = ctl.tick(&rig.sample());
            assert!(out.bridge_enabled);
            rig.apply(&out).unwrap();
        }
        ctl.reference = Reference::new(Waveform::Constant { bias: f32::NAN }, cfg.current_loop.tick_s);
        let out = ctl.tick(&rig.sample());
        assert!(!out.bridge_enabled && out.duty == 0.0 && !ctl.armed(), "{out:?}");
        assert_eq!(FaultCode(out.frame.faults), FaultCode::PARAMETERS_INVALID);
        assert_eq!(ctl.command(2, &Command::ClearFaults).outcome, Err(Refusal::FaultStillPresent));
        let load = Command::LoadParameters { spec, params: p };
        assert_eq!(ctl.command(3, &load).outcome, Ok(()));
        assert!(ctl.faults().is_clear());
    }

    /// A square reference's 25 µm steps reach the inverse model as ramps of at most the slew
    /// limit per tick, and the target still arrives at each level.
    #[test]
    fn reference_steps_reach_the_compensator_slew_limited() {
        let (mut ctl, mut rig, cfg, ..) = armed_on_the_demo_rig();
        let square =
            ReferenceCommand { shape: Shape::Square, amplitude_um: 12.5, bias_um: 15.0, freq_hz: 100.0 };
        assert_eq!(ctl.command(2, &Command::SetReference(square)).outcome, Ok(()));
        let slew = cfg.max_feedforward_slew_um;
        let (mut last, mut largest_step, mut levels) = (0.0f32, 0.0f32, Vec::new());
        for k in 0..1000 {
            if k % 500 == 0 {
                ctl.command(3, &Command::Ping);
            }
            let out = ctl.tick(&rig.sample());
            assert!(out.bridge_enabled, "tripped at tick {k}: faults {:#x}", out.frame.faults);
            rig.apply(&out).unwrap();
            let target = ctl.feedforward_target_um;
            largest_step = largest_step.max((target - last).abs());
            last = target;
            // The target runs `preview_ticks` ahead: sample it before it sees the next step.
            if k % 50 == 45 {
                levels.push(target);
            }
        }
        assert!(largest_step <= slew + 1e-4, "target moved {largest_step} µm in one tick");
        assert!(largest_step >= 0.9 * slew, "the steps never reached the limit ({largest_step} µm)");
        // Each half period (50 ticks) reaches its level: 27.5 µm, then 2.5 µm.
        for (i, v) in levels.iter().enumerate() {
            let want = if i % 2 == 0 { 27.5 } else { 2.5 };
            assert!((v - want).abs() < 1e-3, "half period {i} ends at {v} µm, not {want}");
        }
    }
}
