//! Protection: faults are detected in the tick that sees them, latched, reported in every
//! telemetry frame, and cleared only by an explicit command once their cause is gone. While any
//! fault is latched the bridge is off (the safe state).

use crate::tick::RawSample;
use crate::units::{AdcCode, Amps, ADC_FULL_SCALE};

/// Latched fault bits (one `u16`, as sent in telemetry).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultCode(pub u16);

impl FaultCode {
    /// |current| above the trip level.
    pub const OVERCURRENT: FaultCode = FaultCode(1 << 0);
    /// Coil I²t (heating) budget exhausted.
    pub const COIL_I2T: FaultCode = FaultCode(1 << 1);
    /// Current-sense code at a rail (amplifier or wiring fault).
    pub const CURRENT_SENSOR_RANGE: FaultCode = FaultCode(1 << 2);
    /// Displacement-sensor code at a rail (probe disconnected or out of range).
    pub const DISPLACEMENT_SENSOR_RANGE: FaultCode = FaultCode(1 << 3);
    /// Displacement code frozen while the coil current moves (stuck sensor).
    pub const DISPLACEMENT_STUCK: FaultCode = FaultCode(1 << 4);
    /// The model or controller parameter set was rejected at start-up.
    pub const PARAMETERS_INVALID: FaultCode = FaultCode(1 << 5);
    /// Bus voltage too low to control the coil.
    pub const BUS_UNDERVOLTAGE: FaultCode = FaultCode(1 << 6);

    /// No fault.
    pub const NONE: FaultCode = FaultCode(0);

    /// Whether any bit of `other` is set.
    pub fn contains(self, other: FaultCode) -> bool {
        self.0 & other.0 != 0
    }

    /// Whether no fault is set.
    pub fn is_clear(self) -> bool {
        self.0 == 0
    }

    /// Names of the set bits, for logs.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [&str; 7] = [
            "overcurrent",
            "coil_i2t",
            "current_sensor_range",
            "displacement_sensor_range",
            "displacement_stuck",
            "parameters_invalid",
            "bus_undervoltage",
        ];
        (0..NAMES.len()).filter(move |b| self.0 & (1 << b) != 0).map(|b| NAMES[b])
    }
}

impl core::ops::BitOr for FaultCode {
    type Output = FaultCode;
    fn bitor(self, o: FaultCode) -> FaultCode {
        FaultCode(self.0 | o.0)
    }
}

/// Trip levels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultLimits {
    /// Overcurrent trip [A].
    pub overcurrent_a: f32,
    /// Current the coil carries indefinitely [A rms].
    pub continuous_a: f32,
    /// Heating budget above the continuous current [A² s].
    pub i2t_budget_a2s: f32,
    /// Codes within this margin of 0 or full scale count as out of range.
    pub adc_margin: u16,
    /// Ticks a displacement code may stay identical while the current moves.
    pub stuck_ticks: u32,
    /// Current swing [A] over those ticks that must move a working sensor.
    pub stuck_current_swing_a: f32,
    /// Lowest bus voltage [V].
    pub min_bus_v: f32,
}

impl FaultLimits {
    /// The reference board: 4 A trip, 2 A continuous, 4 A²s budget, 20-code margins, a sensor
    /// frozen for 50 ms while the current swings 0.3 A, 12 V minimum bus.
    pub const REFERENCE: FaultLimits = FaultLimits {
        overcurrent_a: 4.0,
        continuous_a: 2.0,
        i2t_budget_a2s: 4.0,
        adc_margin: 20,
        stuck_ticks: 500,
        stuck_current_swing_a: 0.3,
        min_bus_v: 12.0,
    };
}

/// The monitor (limits and detector state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultMonitor {
    limits: FaultLimits,
    latched: FaultCode,
    i2t: f32,
    last_code: AdcCode,
    same_ticks: u32,
    swing_lo: f32,
    swing_hi: f32,
}

impl FaultMonitor {
    /// A monitor with nothing latched.
    pub fn new(limits: FaultLimits) -> Self {
        Self {
            limits,
            latched: FaultCode::NONE,
            i2t: 0.0,
            last_code: AdcCode(u16::MAX),
            same_ticks: 0,
            swing_lo: f32::MAX,
            swing_hi: f32::MIN,
        }
    }

    /// The latched faults.
    pub fn latched(&self) -> FaultCode {
        self.latched
    }

    /// Latches `f` (e.g. a parameter set rejected at start-up).
    pub fn latch(&mut self, f: FaultCode) {
        self.latched = self.latched | f;
    }

    /// The faults present in this tick's measurements (not latched).
    fn present(&mut self, raw: &RawSample, current: Amps, tick_s: f32) -> FaultCode {
        let (current_code, disp_code, bus_v) = (raw.current, raw.displacement, raw.bus.0);
        let l = &self.limits;
        let mut f = FaultCode::NONE;
        let at_rail = |c: AdcCode| c.0 <= l.adc_margin || c.0 >= ADC_FULL_SCALE - l.adc_margin;
        if at_rail(current_code) {
            f = f | FaultCode::CURRENT_SENSOR_RANGE;
        }
        if at_rail(disp_code) {
            f = f | FaultCode::DISPLACEMENT_SENSOR_RANGE;
        }
        if current.0.is_nan() || current.0.abs() > l.overcurrent_a {
            f = f | FaultCode::OVERCURRENT;
        }
        if bus_v.is_nan() || bus_v < l.min_bus_v {
            f = f | FaultCode::BUS_UNDERVOLTAGE;
        }
        // I²t: integrate the excess over the continuous rating; cool down below it.
        self.i2t = (self.i2t + (current.0 * current.0 - l.continuous_a * l.continuous_a) * tick_s).max(0.0);
        if self.i2t > l.i2t_budget_a2s {
            f = f | FaultCode::COIL_I2T;
        }
        // Stuck: the same displacement code for `stuck_ticks` while the current swings.
        if disp_code == self.last_code {
            self.same_ticks = self.same_ticks.saturating_add(1);
            self.swing_lo = self.swing_lo.min(current.0);
            self.swing_hi = self.swing_hi.max(current.0);
            if self.same_ticks >= l.stuck_ticks && self.swing_hi - self.swing_lo >= l.stuck_current_swing_a {
                f = f | FaultCode::DISPLACEMENT_STUCK;
            }
        } else {
            self.last_code = disp_code;
            self.same_ticks = 0;
            self.swing_lo = current.0;
            self.swing_hi = current.0;
        }
        f
    }

    /// Checks one tick's measurements and returns everything latched (old and new).
    pub fn check(&mut self, raw: &RawSample, current: Amps, tick_s: f32) -> FaultCode {
        let f = self.present(raw, current, tick_s);
        self.latch(f);
        self.latched
    }

    /// The explicit recovery command: clears what is latched except what is still present
    /// (the I²t budget must have cooled below half, a rejected parameter set stays).
    pub fn clear(&mut self, raw: &RawSample, current: Amps) -> FaultCode {
        let keep_params = self.latched.contains(FaultCode::PARAMETERS_INVALID);
        let mut still = self.present(raw, current, 0.0);
        if self.i2t > 0.5 * self.limits.i2t_budget_a2s {
            still = still | FaultCode::COIL_I2T;
        }
        if keep_params {
            still = still | FaultCode::PARAMETERS_INVALID;
        }
        self.latched = still;
        self.same_ticks = 0;
        still
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{Calibration, Volts};

    fn raw_at(i: f32) -> (RawSample, Amps) {
        let cal = Calibration::REFERENCE_BOARD;
        let raw =
            RawSample { current: cal.current_code(Amps(i)), displacement: AdcCode(2000), bus: Volts(24.0) };
        (raw, cal.current(raw.current))
    }

    #[test]
    fn i2t_trips_on_sustained_overload_and_cools_before_it_clears() {
        let mut m = FaultMonitor::new(FaultLimits::REFERENCE);
        // 3 A against a 2 A rating: (9 − 4) A² × t reaches 4 A²s after 0.8 s = 8000 ticks.
        let (raw, i) = raw_at(3.0);
        let mut tripped_at = None;
        for k in 0..10_000 {
            // Alternate the displacement code so that the stuck-sensor check stays quiet.
            let raw = RawSample { displacement: AdcCode(2000 + (k % 2) as u16), ..raw };
            if m.check(&raw, i, 1e-4).contains(FaultCode::COIL_I2T) {
                tripped_at = Some(k);
                break;
            }
        }
        let k = tripped_at.expect("no I²t trip");
        assert!((7800..=8200).contains(&k), "tripped after {k} ticks");
        // Cooling at zero current: (0 − 4) A² → below half the budget after 0.5 s.
        let (raw0, i0) = raw_at(0.0);
        assert!(m.clear(&raw0, i0).contains(FaultCode::COIL_I2T), "must not clear while hot");
        for k in 0..6_000 {
            let raw = RawSample { displacement: AdcCode(2000 + (k % 2) as u16), ..raw0 };
            m.present(&raw, i0, 1e-4);
        }
        assert!(m.clear(&raw0, i0).is_clear());
    }
}
