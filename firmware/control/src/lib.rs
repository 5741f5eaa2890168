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

pub mod command;
pub mod current;
pub mod faults;
pub mod framing;
pub mod pid;
pub mod reference;
pub mod resonant;
pub mod sim;
pub mod telemetry;
pub mod tick;
pub mod units;

use model_core::{Actuator, ActuatorParams, Compensator, CompensatorState, ModelSpec, ParamError};

use crate::command::{Command, Refusal, Reply};
use crate::current::{CurrentLoop, CurrentLoopParams};
use crate::faults::{FaultCode, FaultLimits, FaultMonitor};
use crate::pid::{Pid, PidParams, PidState};
use crate::reference::{Reference, Waveform};
use crate::resonant::{Resonant, ResonantParams};
use crate::telemetry::Frame;
use crate::units::{Amps, Calibration, Micrometres, Volts, ADC_FULL_SCALE};

pub use crate::tick::{RawSample, TickOutput};

/// Everything the controller needs besides the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlConfig {
    /// Front-end scaling (the current zero is replaced by the one measured at boot).
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
    /// Current samples averaged at boot, bridge off, for the current channel's zero.
    pub offset_calibration_ticks: u16,
    /// Largest |bias| + amplitude a commanded reference may have [µm].
    pub max_reference_um: f32,
    /// Largest change of the compensator's target per tick [µm]: a step of the reference (a
    /// square wave, a new bias, arming at a bias) reaches the inverse model as a ramp, which
    /// bounds its Jiles–Atherton sub-steps and so the tick's worst-case time; the PID still sees
    /// the step.
    pub max_feedforward_slew_um: f32,
}

impl ControlConfig {
    /// The reference board tracking a 100 Hz sine of 12.5 µm (25 µm peak to peak) about 15 µm,
    /// with the repeating error learned at 100, 200 and 300 Hz (time constant about 1000 ticks);
    /// disarms 200 ms after the last command, averages 256 samples (25.6 ms) for the current
    /// zero, accepts references within ±50 µm of rest.
    pub const REFERENCE: ControlConfig = ControlConfig {
        calibration: Calibration::REFERENCE_BOARD,
        current_loop: CurrentLoopParams::REFERENCE,
        limits: FaultLimits::REFERENCE,
        reference: Waveform::Sine { freq_hz: 100.0, amplitude: 12.5, bias: 15.0 },
        preview_ticks: 3,
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
        max_reference_um: 50.0,
        max_feedforward_slew_um: SLEW_UM_PER_TICK,
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

/// Boot-time current-zero calibration: samples summed with the bridge off.
#[derive(Debug, Clone, Copy, PartialEq)]
struct OffsetCalibration {
    sum: u32,
    samples: u16,
    done: bool,
}

/// The controller: fixed configuration and model, plus the state stepped every tick. It boots
/// disarmed (bridge off, not switching) and arms only on an explicit command.
pub struct Controller {
    cfg: ControlConfig,
    calibration: Calibration,
    offset: OffsetCalibration,
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
    rest_um: Option<f32>,
    pid: Option<(Pid, PidState)>,
    resonant: Option<Resonant>,
    ticks_since_command: u32,
    last_raw: RawSample,
}

impl Controller {
    /// Builds the controller for `spec` with the identified `params` (from `gma fit`); the
    /// compensator inverts [`compensator_model`]. A rejected parameter set or controller design
    /// (current loop, PID) latches `PARAMETERS_INVALID`; a watchdog `reset` latches
    /// `WATCHDOG_RESET`. Either way it starts disarmed.
    pub fn new(cfg: ControlConfig, spec: ModelSpec, params: &ActuatorParams, reset: ResetCause) -> Self {
        let mut faults = FaultMonitor::new(cfg.limits);
        if reset == ResetCause::Watchdog {
            faults.latch(FaultCode::WATCHDOG_RESET);
        }
        let current_loop = CurrentLoop::new(cfg.current_loop);
        let pid = cfg.pid.map(Pid::new);
        let resonant = cfg.resonant.map(Resonant::new);
        let design_valid = current_loop.is_ok()
            && !matches!(pid, Some(Err(_)))
            && !matches!(resonant, Some(Err(_)))
            && cfg.command_timeout_ticks > 0
            && cfg.offset_calibration_ticks > 0
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
            offset: OffsetCalibration { sum: 0, samples: 0, done: false },
            armed: false,
            design_valid,
            current_loop,
            reference: Reference::new(cfg.reference, cfg.current_loop.tick_s),
            compensator: None,
            model_rest_m: 0.0,
            feedforward_target_um: 0.0,
            faults,
            seq: 0,
            rest_um: None,
            pid,
            resonant,
            ticks_since_command: 0,
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
        let c = Compensator::new(compensator_model(spec, params, self.cfg.current_loop.tick_s)?);
        self.model_rest_m = c.model().rest_state().mech.displacement_m;
        let s = c.rest_state();
        self.compensator = Some((c, s));
        Ok(())
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
            self.armed = false;
        }
    }

    /// Latched faults.
    pub fn faults(&self) -> FaultCode {
        self.faults.latched()
    }

    /// Whether the bridge is armed (switching).
    pub fn armed(&self) -> bool {
        self.armed
    }

    /// The current channel's zero measured at boot [V], once calibration has finished.
    pub fn current_zero_v(&self) -> Option<f32> {
        self.offset.done.then_some(self.calibration.current_zero_v)
    }

    /// The explicit recovery command, given the present measurements: clears what is no longer
    /// present and restarts the loops from rest. Returns what stays latched. It never arms.
    pub fn clear_faults(&mut self, raw: &RawSample) -> FaultCode {
        let i = self.calibration.current(raw.current);
        self.faults.clear(raw, i)
    }

    /// Executes one command (decoded by [`command::Decoder`]); any valid command is also the
    /// keep-alive. Returns the reply to send.
    pub fn command(&mut self, tag: u8, cmd: &Command) -> Reply {
        self.ticks_since_command = 0;
        let outcome = match cmd {
            Command::Ping => Ok(()),
            Command::Arm => self.arm(),
            Command::Disarm => {
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
        if !self.faults().is_clear() {
            return Err(Refusal::FaultLatched);
        }
        if !self.offset.done {
            return Err(Refusal::NotCalibrated);
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

    /// Boot calibration of the current zero (the bridge is off until it is done): the mean of
    /// the first `offset_calibration_ticks` codes, refused (`CURRENT_OFFSET` latched, the nominal
    /// zero kept) outside the stated window around the nominal mid-scale zero.
    fn calibrate_offset(&mut self, raw: &RawSample) {
        let o = &mut self.offset;
        o.sum += raw.current.0 as u32;
        o.samples += 1;
        if o.samples < self.cfg.offset_calibration_ticks {
            return;
        }
        o.done = true;
        let code = o.sum as f32 / o.samples as f32;
        let zero_v = code * (self.calibration.vref / ADC_FULL_SCALE as f32);
        if (zero_v - self.cfg.calibration.current_zero_v).abs() <= self.cfg.limits.current_offset_window_v {
            self.calibration.current_zero_v = zero_v;
        } else {
            self.faults.latch(FaultCode::CURRENT_OFFSET);
        }
    }

    /// One control tick.
    pub fn tick(&mut self, raw: &RawSample) -> TickOutput {
        self.last_raw = *raw;
        if !self.offset.done && !self.armed {
            self.calibrate_offset(raw);
        }
        let cal = &self.calibration;
        let tick_s = self.cfg.current_loop.tick_s;
        let i = cal.current(raw.current);
        let y_abs = cal.displacement(raw.displacement);
        let rest = *self.rest_um.get_or_insert(y_abs.0);
        let y = Micrometres(y_abs.0 - rest);
        self.ticks_since_command = self.ticks_since_command.saturating_add(1);
        if self.armed && self.ticks_since_command > self.cfg.command_timeout_ticks {
            self.faults.latch(FaultCode::COMMAND_TIMEOUT);
        }
        let faults = self.faults.check(raw, i, y, tick_s);
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        if !faults.is_clear() || !self.armed {
            // The safe state, in this very tick: any fault disarms; re-arming takes a clear
            // and an arm command.
            self.armed = false;
            self.current_loop.reset();
            return TickOutput {
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
            };
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
/// fails the build or is never sent.
pub fn compensator_model(
    spec: ModelSpec,
    params: &ActuatorParams,
    tick_s: f32,
) -> Result<Actuator, ParamError> {
    let mut p = *params;
    p.dt_s = tick_s;
    Actuator::new(spec.for_compensator(), &p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{ReferenceCommand, Shape};
    use crate::sim::{CoilActuator, Rig};

    /// A square reference's 25 µm steps reach the inverse model as ramps of at most the slew
    /// limit per tick, and the target still arrives at each level.
    #[test]
    fn reference_steps_reach_the_compensator_slew_limited() {
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
