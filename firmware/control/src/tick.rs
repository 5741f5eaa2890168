//! What one tick exchanges with the board: the measurements it reads, and the bridge command and
//! telemetry frame it writes. Below the controller, so that the fault monitor and the simulated
//! rig use the same types.

use crate::telemetry::Frame;
use crate::units::{AdcCode, Volts};

/// One tick's measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawSample {
    /// Coil current channel.
    pub current: AdcCode,
    /// Displacement channel.
    pub displacement: AdcCode,
    /// Bus voltage, measured (its own ADC channel, converted with the divider ratio).
    pub bus: Volts,
    /// The timer's break flag: the gate driver's fault pin or the current comparator has already
    /// switched the outputs off in hardware.
    pub break_tripped: bool,
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
