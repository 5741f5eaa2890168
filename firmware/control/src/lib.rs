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
pub mod reference;
pub mod sim;
pub mod telemetry;
pub mod units;

use model_core::{Actuator, ActuatorParams, Compensator, CompensatorState, Effect, ModelSpec};

use crate::current::{CurrentLoop, CurrentLoopParams};
use crate::faults::{FaultCode, FaultLimits, FaultMonitor};
use crate::reference::{Reference, Waveform};
use crate::telemetry::Frame;
use crate::units::{AdcCode, Amps, Calibration, Micrometres, Volts};

/// Incremental PID on displacement error [µm] → current correction [A].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains {
    /// Proportional [A/µm].
    pub kp: f32,
    /// Integral per tick [A/µm].
    pub ki: f32,
    /// Derivative [A/µm].
    pub kd: f32,
    /// Largest correction [A].
    pub limit_a: f32,
}

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
    pub pid: Option<PidGains>,
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
        pid: Some(PidGains { kp: 0.02, ki: 0.02, kd: 0.0, limit_a: 1.0 }),
        max_current_a: 3.5,
    };
}

/// One tick's measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSample {
    /// Coil current channel.
    pub current: AdcCode,
    /// Displacement channel.
    pub displacement: AdcCode,
    /// Bus voltage (measured, or nominal where the board has no divider).
    pub bus: Volts,
}

/// What the tick asks of the power stage, and its telemetry record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickOutput {
    /// Signed duty of the full bridge.
    pub duty: f32,
    /// Whether the bridge outputs are enabled (false: the safe state).
    pub bridge_enabled: bool,
    /// The record of this tick.
    pub frame: Frame,
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
    pid_i: f32,
    e1: f32,
    e2: f32,
}

impl Controller {
    /// Builds the controller for `spec` with the identified `params` (from `gma fit`). The
    /// amplifier, sensor delay and mechanics are left out of the inverse: the current loop is
    /// the amplifier, and the PID handles the rest. A rejected parameter set or controller design
    /// starts the controller with `PARAMETERS_INVALID` latched (bridge off).
    pub fn new(cfg: ControlConfig, spec: ModelSpec, params: &ActuatorParams) -> Self {
        let mut faults = FaultMonitor::new(cfg.limits);
        let comp_spec = spec
            .without(Effect::AmplifierDynamics)
            .without(Effect::SensorDelay)
            .without(Effect::MechanicalDynamics);
        let mut p = *params;
        p.dt_s = cfg.current_loop.tick_s;
        let compensator = match Actuator::new(comp_spec, &p) {
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
        Self {
            cfg,
            current_loop,
            reference: Reference::new(cfg.reference, cfg.current_loop.tick_s),
            compensator,
            model_rest_m,
            faults,
            seq: 0,
            rest_um: None,
            pid_i: 0.0,
            e1: 0.0,
            e2: 0.0,
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
            self.pid_i = 0.0;
            self.e1 = 0.0;
            self.e2 = 0.0;
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
        // Incremental PID on the displacement error.
        if let Some(g) = self.cfg.pid {
            let e = r - y.0;
            let d = g.kp * (e - self.e1) + g.ki * e + g.kd * (e - 2.0 * self.e1 + self.e2);
            self.pid_i = (self.pid_i + d).clamp(-g.limit_a, g.limit_a);
            self.e2 = self.e1;
            self.e1 = e;
        }
        let max_i = self.cfg.max_current_a;
        let i_ref = (i_ff + self.pid_i).clamp(-max_i, max_i);
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
