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

pub mod current;
pub mod faults;
pub mod pid;
pub mod reference;
pub mod sim;
pub mod telemetry;
pub mod tick;
pub mod units;

use model_core::{Actuator, ActuatorParams, Compensator, CompensatorState, ModelSpec, ParamError};

use crate::current::{CurrentLoop, CurrentLoopParams};
use crate::faults::{FaultCode, FaultLimits, FaultMonitor};
use crate::pid::{Pid, PidParams, PidState};
use crate::reference::{Reference, Waveform};
use crate::telemetry::Frame;
use crate::units::{Amps, Calibration, Micrometres};

pub use crate::tick::{RawSample, TickOutput};

/// Everything the controller needs besides the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlConfig {
    /// Front-end scaling.
    pub calibration: Calibration,
    /// Current loop design.
    pub current_loop: CurrentLoopParams,
    /// Trip levels.
    pub limits: FaultLimits,
    /// Displacement reference [µm, relative to the rest position].
    pub reference: Waveform,
    /// Ticks the compensator looks ahead on the reference (current-loop and mechanics lag).
    pub preview_ticks: u32,
    /// Displacement PID; `None` runs the compensator alone (open loop).
    pub pid: Option<PidParams>,
    /// Largest current reference [A].
    pub max_current_a: f32,
}

impl ControlConfig {
    /// The reference board tracking a 100 Hz sine of 12.5 µm (25 µm peak to peak) about 15 µm.
    pub const REFERENCE: ControlConfig = ControlConfig {
        calibration: Calibration::REFERENCE_BOARD,
        current_loop: CurrentLoopParams::REFERENCE,
        limits: FaultLimits::REFERENCE,
        reference: Waveform::Sine { freq_hz: 100.0, amplitude: 12.5, bias: 15.0 },
        preview_ticks: 2,
        pid: Some(PidParams { kp: 0.02, ki: 0.02, kd: 0.0, limit_a: 1.0 }),
        max_current_a: 3.5,
    };
}

/// The controller: fixed configuration and model, plus the state stepped every tick.
pub struct Controller {
    cfg: ControlConfig,
    current_loop: CurrentLoop,
    reference: Reference,
    compensator: Option<(Compensator, CompensatorState)>,
    /// Model displacement at rest [m] (the compensator's zero).
    model_rest_m: f32,
    faults: FaultMonitor,
    seq: u32,
    rest_um: Option<f32>,
    pid: Option<(Pid, PidState)>,
}

impl Controller {
    /// Builds the controller for `spec` with the identified `params` (from `gma fit`); the
    /// compensator inverts [`compensator_model`]. A rejected parameter set or controller design
    /// (current loop, PID) starts the controller with `PARAMETERS_INVALID` latched (bridge off).
    pub fn new(cfg: ControlConfig, spec: ModelSpec, params: &ActuatorParams) -> Self {
        let mut faults = FaultMonitor::new(cfg.limits);
        let compensator = match compensator_model(spec, params, cfg.current_loop.tick_s) {
            Ok(model) => {
                let c = Compensator::new(model);
                let s = c.rest_state();
                Some((c, s))
            }
            Err(_) => {
                faults.latch(FaultCode::PARAMETERS_INVALID);
                None
            }
        };
        let model_rest_m =
            compensator.as_ref().map(|(c, _)| c.model().rest_state().mech.displacement_m).unwrap_or(0.0);
        let current_loop = match CurrentLoop::new(cfg.current_loop) {
            Ok(c) => c,
            Err(_) => {
                faults.latch(FaultCode::PARAMETERS_INVALID);
                CurrentLoop::idle()
            }
        };
        let pid = match cfg.pid.map(Pid::new) {
            Some(Ok(pid)) => Some((pid, PidState::default())),
            Some(Err(_)) => {
                faults.latch(FaultCode::PARAMETERS_INVALID);
                None
            }
            None => None,
        };
        Self {
            cfg,
            current_loop,
            reference: Reference::new(cfg.reference, cfg.current_loop.tick_s),
            compensator,
            model_rest_m,
            faults,
            seq: 0,
            rest_um: None,
            pid,
        }
    }

    /// A controller whose parameter set could not even be read: PARAMETERS_INVALID latched, the
    /// bridge never enabled.
    pub fn refused(cfg: ControlConfig) -> Self {
        let mut c = Self::new(cfg, ModelSpec::LINEAR, &ActuatorParams::TERFENOL_DEMO);
        c.compensator = None;
        c.faults.latch(FaultCode::PARAMETERS_INVALID);
        c
    }

    /// Latched faults.
    pub fn faults(&self) -> FaultCode {
        self.faults.latched()
    }

    /// The explicit recovery command, given the present measurements: clears what is no longer
    /// present and restarts the loops from rest. Returns what stays latched.
    pub fn clear_faults(&mut self, raw: &RawSample) -> FaultCode {
        let i = self.cfg.calibration.current(raw.current);
        let left = self.faults.clear(raw, i);
        if left.is_clear() {
            self.current_loop.reset();
            if let Some((_, s)) = self.pid.as_mut() {
                *s = PidState::default();
            }
            if let Some((c, s)) = self.compensator.as_mut() {
                *s = c.rest_state();
            }
        }
        left
    }

    /// One control tick.
    pub fn tick(&mut self, raw: &RawSample) -> TickOutput {
        let cal = &self.cfg.calibration;
        let tick_s = self.cfg.current_loop.tick_s;
        let i = cal.current(raw.current);
        let y_abs = cal.displacement(raw.displacement);
        let rest = *self.rest_um.get_or_insert(y_abs.0);
        let y = Micrometres(y_abs.0 - rest);
        let faults = self.faults.check(raw, i, tick_s);
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        let r = self.reference.advance();
        if !faults.is_clear() {
            self.current_loop.reset();
            return TickOutput {
                duty: 0.0,
                bridge_enabled: false,
                frame: Frame {
                    seq,
                    reference_um: r,
                    command_v: 0.0,
                    current_a: i.0,
                    displacement_um: y.0,
                    faults: faults.0,
                },
            };
        }
        // Feedforward: the current the inverse model says gives the reference `preview` ticks on.
        let ahead = self.reference.peek_ahead(self.cfg.preview_ticks.saturating_sub(1));
        let i_ff = match self.compensator.as_mut() {
            Some((c, s)) => c.step(s, self.model_rest_m + ahead * 1e-6),
            None => 0.0,
        };
        let i_pid = match self.pid.as_mut() {
            Some((pid, s)) => pid.step(s, r - y.0),
            None => 0.0,
        };
        let max_i = self.cfg.max_current_a;
        let i_ref = (i_ff + i_pid).clamp(-max_i, max_i);
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
/// current loop is the amplifier; the mechanics and the sensor delay, which the PID handles). `firmware/build.rs` builds it too, so that a bad parameter set fails the
/// build.
pub fn compensator_model(
    spec: ModelSpec,
    params: &ActuatorParams,
    tick_s: f32,
) -> Result<Actuator, ParamError> {
    let spec = spec.for_compensator();
    let mut p = *params;
    p.dt_s = tick_s;
    Actuator::new(spec, &p)
}
