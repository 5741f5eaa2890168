//! Protection: faults are detected in the tick that sees them, latched, reported in every
//! telemetry frame, and cleared only by an explicit command once their cause is gone. While any
//! fault is latched the bridge is off (the safe state).

use crate::tick::RawSample;
use crate::units::{AdcCode, Amps, Micrometres, ADC_FULL_SCALE};

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
    /// The displacement reading does not follow the coil current (stuck or frozen probe).
    pub const DISPLACEMENT_STUCK: FaultCode = FaultCode(1 << 4);
    /// The model or controller parameter set was rejected at start-up.
    pub const PARAMETERS_INVALID: FaultCode = FaultCode(1 << 5);
    /// Bus voltage too low to control the coil.
    pub const BUS_UNDERVOLTAGE: FaultCode = FaultCode(1 << 6);
    /// Bus voltage too high (the coil's energy pumped back into the bus, or a wrong supply).
    pub const BUS_OVERVOLTAGE: FaultCode = FaultCode(1 << 7);
    /// The current channel's zero measured at boot is implausible (front end or reference fault).
    pub const CURRENT_OFFSET: FaultCode = FaultCode(1 << 8);
    /// The last reset was the watchdog's: something hung; an operator must clear it.
    pub const WATCHDOG_RESET: FaultCode = FaultCode(1 << 9);
    /// No valid command or keep-alive within the timeout while armed: disarmed.
    pub const COMMAND_TIMEOUT: FaultCode = FaultCode(1 << 10);
    /// The timer's break input switched the bridge off in hardware (gate driver or comparator).
    pub const BRIDGE_BREAK: FaultCode = FaultCode(1 << 11);
    /// The firmware saw consecutive ticks overrun their period (the next conversion already
    /// done when the interrupt ended): the loop no longer runs at its rate.
    pub const MISSED_DEADLINE: FaultCode = FaultCode(1 << 12);

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
        const NAMES: [&str; 13] = [
            "overcurrent",
            "coil_i2t",
            "current_sensor_range",
            "displacement_sensor_range",
            "displacement_stuck",
            "parameters_invalid",
            "bus_undervoltage",
            "bus_overvoltage",
            "current_offset",
            "watchdog_reset",
            "command_timeout",
            "bridge_break",
            "missed_deadline",
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
    /// Stuck-probe window [ticks]: the displacement's span is compared with the current's.
    pub stuck_ticks: u32,
    /// Current span [A] within a window below which the window proves nothing.
    pub stuck_current_swing_a: f32,
    /// Smallest displacement span per ampere of current span [µm/A] a working probe shows.
    pub stuck_min_um_per_a: f32,
    /// Under-voltage trip [V]; arming needs this plus the hysteresis.
    pub min_bus_v: f32,
    /// Over-voltage trip [V].
    pub max_bus_v: f32,
    /// A bus fault clears (and arming is allowed) only this far inside the limits [V].
    pub bus_hysteresis_v: f32,
    /// Consecutive ticks a bus reading must stay outside a limit before it trips.
    pub bus_qualify_ticks: u16,
    /// The current channel's zero measured at boot must lie within this of its nominal
    /// (mid-scale) value [V].
    pub current_offset_window_v: f32,
}

impl FaultLimits {
    /// The reference board: 4 A trip, 2 A continuous, 4 A²s budget, 20-code margins; a probe
    /// whose span over 50 ms stays below 2 µm per ampere of a ≥ 0.3 A current swing is stuck
    /// (the reference actuator tracking its 25 µm sine spans 18 µm per ampere of current span
    /// on our simulated rig, nine times the limit; ±2 codes of noise span 0.1 µm, a sixth of
    /// the least span a 0.3 A swing demands); bus 12–34 V with 1 V hysteresis,
    /// 3 ticks (300 µs) to qualify (a 24 V supply; the 100 µF bus absorbs a 4 A coil's 48 mJ at
    /// about 31 V, below the trip, and 34 V leaves margin to 40 V parts); current zero within
    /// ±0.15 V (±0.75 A, ±186 codes) of 1.65 V.
    pub const REFERENCE: FaultLimits = FaultLimits {
        overcurrent_a: 4.0,
        continuous_a: 2.0,
        i2t_budget_a2s: 4.0,
        adc_margin: 20,
        stuck_ticks: 500,
        stuck_current_swing_a: 0.3,
        stuck_min_um_per_a: 2.0,
        min_bus_v: 12.0,
        max_bus_v: 34.0,
        bus_hysteresis_v: 1.0,
        bus_qualify_ticks: 3,
        current_offset_window_v: 0.15,
    };

    /// Whether the bus is far enough inside its limits to clear a bus fault or arm.
    pub fn bus_healthy(&self, bus_v: f32) -> bool {
        bus_v >= self.min_bus_v + self.bus_hysteresis_v && bus_v <= self.max_bus_v - self.bus_hysteresis_v
    }
}

/// The monitor (limits and detector state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultMonitor {
    limits: FaultLimits,
    latched: FaultCode,
    i2t: f32,
    under_ticks: u16,
    over_ticks: u16,
    window_ticks: u32,
    window_current: (f32, f32),
    window_displacement: (f32, f32),
}

/// An empty span (min, max).
const EMPTY: (f32, f32) = (f32::MAX, f32::MIN);

fn widen(span: (f32, f32), v: f32) -> (f32, f32) {
    (span.0.min(v), span.1.max(v))
}

impl FaultMonitor {
    /// A monitor with nothing latched.
    pub fn new(limits: FaultLimits) -> Self {
        Self {
            limits,
            latched: FaultCode::NONE,
            i2t: 0.0,
            under_ticks: 0,
            over_ticks: 0,
            window_ticks: 0,
            window_current: EMPTY,
            window_displacement: EMPTY,
        }
    }

    /// The limits.
    pub fn limits(&self) -> &FaultLimits {
        &self.limits
    }

    /// The latched faults.
    pub fn latched(&self) -> FaultCode {
        self.latched
    }

    /// Latches `f` (e.g. a parameter set rejected at start-up).
    pub fn latch(&mut self, f: FaultCode) {
        self.latched = self.latched | f;
    }

    /// Unlatches `f` whose cause was removed by command (a valid parameter set loaded).
    pub fn release(&mut self, f: FaultCode) {
        self.latched = FaultCode(self.latched.0 & !f.0);
    }

    /// The faults this tick's measurements show on their own (not latched).
    fn present(&mut self, raw: &RawSample, current: Amps, tick_s: f32) -> FaultCode {
        let l = &self.limits;
        let mut f = FaultCode::NONE;
        let at_rail = |c: AdcCode| c.0 <= l.adc_margin || c.0 >= ADC_FULL_SCALE - l.adc_margin;
        if raw.break_tripped {
            f = f | FaultCode::BRIDGE_BREAK;
        }
        if at_rail(raw.current) {
            f = f | FaultCode::CURRENT_SENSOR_RANGE;
        }
        if at_rail(raw.displacement) {
            f = f | FaultCode::DISPLACEMENT_SENSOR_RANGE;
        }
        if current.0.is_nan() || current.0.abs() > l.overcurrent_a {
            f = f | FaultCode::OVERCURRENT;
        }
        // I²t: integrate the excess over the continuous rating; cool down below it.
        self.i2t = (self.i2t + (current.0 * current.0 - l.continuous_a * l.continuous_a) * tick_s).max(0.0);
        if self.i2t > l.i2t_budget_a2s {
            f = f | FaultCode::COIL_I2T;
        }
        f
    }

    /// Bus limits, qualified: one bad conversion does not trip, `bus_qualify_ticks` in a row do.
    /// A reading that is not a number counts as outside both.
    fn bus(&mut self, bus_v: f32) -> FaultCode {
        let l = &self.limits;
        let count = |n: u16, outside: bool| if outside { n.saturating_add(1) } else { 0 };
        let nan = bus_v.is_nan();
        self.under_ticks = count(self.under_ticks, nan || bus_v < l.min_bus_v);
        self.over_ticks = count(self.over_ticks, nan || bus_v > l.max_bus_v);
        let mut f = FaultCode::NONE;
        if self.under_ticks >= l.bus_qualify_ticks {
            f = f | FaultCode::BUS_UNDERVOLTAGE;
        }
        if self.over_ticks >= l.bus_qualify_ticks {
            f = f | FaultCode::BUS_OVERVOLTAGE;
        }
        f
    }

    /// Stuck probe, model-based: over each window the displacement must span at least
    /// `stuck_min_um_per_a` times the current's span (the actuator's least sensitivity). A frozen
    /// reading with a few codes of noise spans a fraction of that; a window whose current hardly
    /// moves proves nothing and is skipped.
    fn stuck(&mut self, current: Amps, displacement: Micrometres) -> FaultCode {
        self.window_current = widen(self.window_current, current.0);
        self.window_displacement = widen(self.window_displacement, displacement.0);
        self.window_ticks += 1;
        if self.window_ticks < self.limits.stuck_ticks {
            return FaultCode::NONE;
        }
        let di = self.window_current.1 - self.window_current.0;
        let dy = self.window_displacement.1 - self.window_displacement.0;
        self.restart_window();
        if di >= self.limits.stuck_current_swing_a && dy < self.limits.stuck_min_um_per_a * di {
            FaultCode::DISPLACEMENT_STUCK
        } else {
            FaultCode::NONE
        }
    }

    fn restart_window(&mut self) {
        self.window_ticks = 0;
        self.window_current = EMPTY;
        self.window_displacement = EMPTY;
    }

    /// Checks one tick's measurements and returns everything latched (old and new).
    pub fn check(
        &mut self,
        raw: &RawSample,
        current: Amps,
        displacement: Micrometres,
        tick_s: f32,
    ) -> FaultCode {
        let f = self.present(raw, current, tick_s) | self.bus(raw.bus.0) | self.stuck(current, displacement);
        self.latch(f);
        self.latched
    }

    /// The explicit recovery command: clears what is latched except what is still present
    /// (the I²t budget must have cooled below half, the bus must be inside its limits by the
    /// hysteresis; a rejected parameter set and an implausible current zero stay).
    pub fn clear(&mut self, raw: &RawSample, current: Amps) -> FaultCode {
        let keep =
            FaultCode(self.latched.0 & (FaultCode::PARAMETERS_INVALID.0 | FaultCode::CURRENT_OFFSET.0));
        let mut still = self.present(raw, current, 0.0) | keep;
        if self.i2t > 0.5 * self.limits.i2t_budget_a2s {
            still = still | FaultCode::COIL_I2T;
        }
        if !self.limits.bus_healthy(raw.bus.0) {
            let l = &self.limits;
            still = still
                | if raw.bus.0 > l.max_bus_v - l.bus_hysteresis_v {
                    FaultCode::BUS_OVERVOLTAGE
                } else {
                    FaultCode::BUS_UNDERVOLTAGE
                };
        }
        self.latched = still;
        self.restart_window();
        still
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{Calibration, Volts};

    fn raw_at(i: f32) -> (RawSample, Amps) {
        let cal = Calibration::REFERENCE_BOARD;
        let raw = RawSample {
            current: cal.current_code(Amps(i)),
            displacement: AdcCode(2000),
            bus: Volts(24.0),
            break_tripped: false,
        };
        (raw, cal.current(raw.current))
    }

    #[test]
    fn i2t_trips_on_sustained_overload_and_cools_before_it_clears() {
        let mut m = FaultMonitor::new(FaultLimits::REFERENCE);
        // 3 A against a 2 A rating: (9 − 4) A² × t reaches 4 A²s after 0.8 s = 8000 ticks.
        let (raw, i) = raw_at(3.0);
        let mut tripped_at = None;
        for k in 0..10_000 {
            if m.check(&raw, i, Micrometres(0.0), 1e-4).contains(FaultCode::COIL_I2T) {
                tripped_at = Some(k);
                break;
            }
        }
        let k = tripped_at.expect("no I²t trip");
        assert!((7800..=8200).contains(&k), "tripped after {k} ticks");
        // Cooling at zero current: (0 − 4) A² → below half the budget after 0.5 s.
        let (raw0, i0) = raw_at(0.0);
        assert!(m.clear(&raw0, i0).contains(FaultCode::COIL_I2T), "must not clear while hot");
        for _ in 0..6_000 {
            m.present(&raw0, i0, 1e-4);
        }
        assert!(m.clear(&raw0, i0).is_clear());
    }
}
