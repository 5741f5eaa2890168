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
    /// The current channel's zero measured with the bridge off is implausible or unsteady
    /// (front end or reference fault), at boot or at an arm.
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
    /// The interval between two ticks, timed by the CPU's cycle counter, is not the tick period
    /// the control design assumes ([`crate::timing::TickPeriod`]).
    pub const TICK_TIMING: FaultCode = FaultCode(1 << 13);
    /// The rest position measured with the bridge off is unusable: the displacement code sits
    /// at a rail, or spreads more than `rest_max_spread_um` over the window, or (at an arming)
    /// lies more than `rest_max_shift_um` from the rest position kept since the first one.
    pub const REST_POSITION: FaultCode = FaultCode(1 << 14);
    /// `rearm_trips` trips whose cause cannot be seen with the bridge off
    /// ([`FaultCode::UNVERIFIABLE`]) within `rearm_window_ticks`: they and this stay latched
    /// until a reset.
    pub const REPEATED_TRIPS: FaultCode = FaultCode(1 << 15);

    /// Trips whose cause the board cannot observe once the bridge is off (a short, a gate-driver
    /// fault, a probe that stopped following, an overrun tick): a clear command cannot prove
    /// them gone, so re-arming after them is rationed ([`FaultLimits::rearm_trips`]).
    pub const UNVERIFIABLE: FaultCode = FaultCode(
        Self::OVERCURRENT.0 | Self::BRIDGE_BREAK.0 | Self::DISPLACEMENT_STUCK.0 | Self::MISSED_DEADLINE.0,
    );
    /// Faults of the bridge-off calibration (current zero, rest position): they clear when the
    /// latest measurement window is good.
    pub const CALIBRATION: FaultCode = FaultCode(Self::CURRENT_OFFSET.0 | Self::REST_POSITION.0);

    /// Faults after which the bridge opens in the tick that sees them, without first driving
    /// the coil's current to zero ([`crate::DrainParams`]): where switching can feed the fault
    /// (a gate-driver fault on the break input, MOE lost), where the loop's timing cannot be
    /// trusted (a missed deadline, a wrong tick period), where the loop itself is invalid
    /// (`parameters_invalid`: a non-finite duty) or cannot see the current (the current
    /// sensor at a rail, a bad current zero).
    pub const OPENS_AT_ONCE: FaultCode = FaultCode(
        Self::BRIDGE_BREAK.0
            | Self::MISSED_DEADLINE.0
            | Self::TICK_TIMING.0
            | Self::PARAMETERS_INVALID.0
            | Self::CURRENT_SENSOR_RANGE.0
            | Self::CURRENT_OFFSET.0,
    );

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
        const NAMES: [&str; 16] = [
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
            "tick_timing",
            "rest_position",
            "repeated_trips",
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
    /// The current channel's zero measured with the bridge off must lie within this of its
    /// nominal (mid-scale) value [V].
    pub current_offset_window_v: f32,
    /// Largest spread (max − min) of the current codes over a zero-measurement window: the mean
    /// of an oscillating input can look like a good zero.
    pub current_zero_max_spread_codes: u16,
    /// Largest spread of the displacement over the rest-position window [µm].
    pub rest_max_spread_um: f32,
    /// Largest distance [µm] of a later bridge-off window's rest from the rest position kept
    /// since the first arming (the reference's zero): more is a probe that slipped or a rod
    /// that moved, and the displacement loop would regulate about the wrong zero. It must pass
    /// the rod's remanent strain at zero current (10 µm on the demo rod).
    pub rest_max_shift_um: f32,
    /// Trips of [`FaultCode::UNVERIFIABLE`] within `rearm_window_ticks` after which they stay
    /// latched until a reset ([`FaultCode::REPEATED_TRIPS`]); at most [`MAX_REARM_TRIPS`].
    pub rearm_trips: u8,
    /// The window those trips are counted over [ticks].
    pub rearm_window_ticks: u32,
}

/// Most trips [`FaultLimits::rearm_trips`] may allow (the monitor keeps their times).
pub const MAX_REARM_TRIPS: usize = 8;

impl FaultLimits {
    /// The reference board: 4 A trip, 2 A continuous, 4 A²s budget, 20-code margins; a probe
    /// whose span over 50 ms stays below 2 µm per ampere of a ≥ 0.3 A current swing is stuck
    /// (the reference actuator tracking its 25 µm sine spans 18 µm per ampere of current span
    /// on our simulated rig, nine times the limit; ±2 codes of noise span 0.1 µm, a sixth of
    /// the least span a 0.3 A swing demands); bus 12–34 V with 1 V hysteresis, 3 ticks
    /// (300 µs) to qualify (a 24 V supply; 34 V leaves margin to 40 V parts). A software trip
    /// drives the current to zero before the bridge opens ([`crate::DrainParams`]; the bus
    /// then stays under the current loop's 30 V regeneration limit). A hardware break does NOT
    /// stay under 34 V: with all four switches off the coil's ½·L·I² returns through the body
    /// diodes into the 100 µF bus, less what the winding's 6 Ω take on the way (the L–R–C
    /// discharge, [`crate::sim::diode_discharge_peak_v`]): 34.7 V from 4 A (48 mJ) and 36.3 V
    /// from 4.4 A (58 mJ) with ideal diodes (√(24² + L·I²/C) = 39.2 / 41.7 V without the
    /// resistance); any break above 3.83 A passes 34 V, and also latches `bus_overvoltage`
    /// unless the board absorbs the energy (firmware/README.md, "Safe
    /// state"). Current zero within ±0.15 V (±0.75 A, ±186 codes) of 1.65 V and spreading at
    /// most 32 codes (0.13 A) over its window; rest position spreading at most 1 µm, and at
    /// most 20 µm from the one kept since the first arming. The
    /// third overcurrent, break, stuck-probe or deadline trip within a minute (600 000
    /// ticks) needs a reset.
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
        current_zero_max_spread_codes: 32,
        rest_max_spread_um: 1.0,
        rest_max_shift_um: 20.0,
        rearm_trips: 3,
        rearm_window_ticks: 600_000,
    };

    /// Whether the bus is far enough inside its limits to clear a bus fault or arm.
    pub fn bus_healthy(&self, bus_v: f32) -> bool {
        bus_v >= self.min_bus_v + self.bus_hysteresis_v && bus_v <= self.max_bus_v - self.bus_hysteresis_v
    }

    /// Whether the limits are usable (the re-arm count within what the monitor can hold).
    pub fn is_valid(&self) -> bool {
        (1..=MAX_REARM_TRIPS as u8).contains(&self.rearm_trips)
            && self.rearm_window_ticks > 0
            && self.rest_max_spread_um.is_finite()
            && self.rest_max_spread_um > 0.0
            && self.rest_max_shift_um.is_finite()
            && self.rest_max_shift_um > 0.0
    }
}

/// The monitor (limits and detector state).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultMonitor {
    limits: FaultLimits,
    latched: FaultCode,
    /// Ticks checked since boot (64 bits: a trip time never aliases one from days before).
    ticks: u64,
    /// Tick of each recent [`FaultCode::UNVERIFIABLE`] trip, newest at `trips % MAX_REARM_TRIPS`.
    trip_ticks: [u64; MAX_REARM_TRIPS],
    /// Such trips since boot.
    trips: u32,
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
            ticks: 0,
            trip_ticks: [0; MAX_REARM_TRIPS],
            trips: 0,
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

    /// Latches `f` (e.g. a parameter set rejected at start-up). A trip of
    /// [`FaultCode::UNVERIFIABLE`] (none of them latched before) is counted; the
    /// `rearm_trips`-th within `rearm_window_ticks` latches [`FaultCode::REPEATED_TRIPS`].
    pub fn latch(&mut self, f: FaultCode) {
        let before = self.latched;
        self.latched = before | f;
        if f.contains(FaultCode::UNVERIFIABLE) && !before.contains(FaultCode::UNVERIFIABLE) {
            self.trip_ticks[self.trips as usize % MAX_REARM_TRIPS] = self.ticks;
            self.trips = self.trips.wrapping_add(1);
            let n = (self.limits.rearm_trips as usize).clamp(1, MAX_REARM_TRIPS);
            if self.trips as usize >= n {
                // The n-th trip back (n − 1 before this one) within the window.
                let oldest = self.trip_ticks[(self.trips as usize - n) % MAX_REARM_TRIPS];
                if self.ticks - oldest < u64::from(self.limits.rearm_window_ticks) {
                    self.latched = self.latched | FaultCode::REPEATED_TRIPS;
                }
            }
        }
    }

    /// Starts the I²t integrator at its budget: after a reset that was not a power-on the coil
    /// may still be as hot as the budget allows (it cools back at the continuous rating, 1 s
    /// for the reference coil at zero current).
    pub fn start_hot(&mut self) {
        self.i2t = self.limits.i2t_budget_a2s;
    }

    /// The I²t integrator [A² s above the continuous rating].
    pub fn i2t_a2s(&self) -> f32 {
        self.i2t
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
        self.ticks += 1;
        let f = self.present(raw, current, tick_s) | self.bus(raw.bus.0) | self.stuck(current, displacement);
        self.latch(f);
        self.latched
    }

    /// The explicit recovery command: clears what is latched except what is still present
    /// (the I²t budget must have cooled below half, the bus must be inside its limits by the
    /// hysteresis; `calibration` are the calibration faults the latest bridge-off measurement
    /// still shows). A rejected parameter set stays (a valid load clears it); after
    /// [`FaultCode::REPEATED_TRIPS`] the unverifiable trips stay with it until a reset. The
    /// other unverifiable trips (overcurrent, break, stuck probe, deadline) clear, as their
    /// cause cannot be seen with the bridge off; `rearm_trips` rations them.
    pub fn clear(&mut self, raw: &RawSample, current: Amps, calibration: FaultCode) -> FaultCode {
        let sticky = FaultCode::PARAMETERS_INVALID.0 | FaultCode::REPEATED_TRIPS.0;
        let mut keep = FaultCode(self.latched.0 & sticky);
        if self.latched.contains(FaultCode::REPEATED_TRIPS) {
            keep = keep | FaultCode(self.latched.0 & FaultCode::UNVERIFIABLE.0);
        }
        let mut still =
            self.present(raw, current, 0.0) | keep | FaultCode(calibration.0 & FaultCode::CALIBRATION.0);
        // A latched I²t trip clears once the coil has cooled to half its budget; a coil that
        // is merely warm (a warm start) latches nothing here.
        if self.latched.contains(FaultCode::COIL_I2T) && self.i2t > 0.5 * self.limits.i2t_budget_a2s {
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
        assert!(
            m.clear(&raw0, i0, FaultCode::NONE).contains(FaultCode::COIL_I2T),
            "must not clear while hot"
        );
        for _ in 0..6_000 {
            m.present(&raw0, i0, 1e-4);
        }
        assert!(m.clear(&raw0, i0, FaultCode::NONE).is_clear());
    }

    /// Ticks at `i` amperes until the monitor latches something; returns the ticks taken.
    fn run_at(m: &mut FaultMonitor, i: f32, ticks: u32) -> Option<u32> {
        let (raw, amps) = raw_at(i);
        (1..=ticks).find(|_| !m.check(&raw, amps, Micrometres(0.0), 1e-4).is_clear())
    }

    #[test]
    fn a_reset_other_than_power_on_starts_the_coil_hot() {
        // 2.5 A against 2 A continuous: (6.25 − 4) A² → the 4 A²s budget in 1.78 s cold.
        let mut cold = FaultMonitor::new(FaultLimits::REFERENCE);
        assert_eq!(run_at(&mut cold, 2.5, 17_000), None, "cold coil tripped early");
        let mut hot = FaultMonitor::new(FaultLimits::REFERENCE);
        hot.start_hot();
        assert_eq!(run_at(&mut hot, 2.5, 17_000), Some(1), "a warm start must trip at the first excess");
        assert!(hot.latched().contains(FaultCode::COIL_I2T));
        // At zero current it cools at the continuous rating: the whole budget back after 1 s.
        let mut resting = FaultMonitor::new(FaultLimits::REFERENCE);
        resting.start_hot();
        assert_eq!(run_at(&mut resting, 0.0, 10_000), None);
        assert!(resting.i2t_a2s() < 1e-3, "still {} A²s after 1 s at rest", resting.i2t_a2s());
    }

    /// Trips `m` by overcurrent, lets the current decay and sends the clear command; returns
    /// what stays latched.
    fn overcurrent_trip_and_clear(m: &mut FaultMonitor) -> FaultCode {
        assert_eq!(run_at(m, 5.0, 1), Some(1));
        assert!(m.latched().contains(FaultCode::OVERCURRENT));
        let (raw0, i0) = raw_at(0.0);
        m.check(&raw0, i0, Micrometres(0.0), 1e-4);
        m.clear(&raw0, i0, FaultCode::NONE)
    }

    #[test]
    fn the_third_unverifiable_trip_within_a_minute_needs_a_reset() {
        let l = FaultLimits::REFERENCE;
        let mut m = FaultMonitor::new(l);
        assert!(overcurrent_trip_and_clear(&mut m).is_clear(), "first trip must clear");
        run_at(&mut m, 0.0, 1000);
        assert!(overcurrent_trip_and_clear(&mut m).is_clear(), "second trip must clear");
        run_at(&mut m, 0.0, 1000);
        let still = overcurrent_trip_and_clear(&mut m);
        assert!(
            still.contains(FaultCode::REPEATED_TRIPS) && still.contains(FaultCode::OVERCURRENT),
            "third trip in 0.2 s cleared: {:?}",
            still.names().collect::<Vec<_>>()
        );
        // Nothing but a reset: a minute later the clear still refuses.
        run_at(&mut m, 0.0, l.rearm_window_ticks + 10);
        let (raw0, i0) = raw_at(0.0);
        assert!(m.clear(&raw0, i0, FaultCode::NONE).contains(FaultCode::REPEATED_TRIPS));

        // The same three trips spread over more than the window each clear.
        let mut m = FaultMonitor::new(l);
        for k in 0..3 {
            assert!(overcurrent_trip_and_clear(&mut m).is_clear(), "trip {k} a half window apart");
            run_at(&mut m, 0.0, l.rearm_window_ticks / 2 + 1);
        }
    }

    #[test]
    fn a_break_with_overcurrent_counts_as_one_trip_and_a_stuck_probe_counts() {
        let mut m = FaultMonitor::new(FaultLimits::REFERENCE);
        // One event seen twice (the break input, then the current the next tick): one trip.
        m.latch(FaultCode::BRIDGE_BREAK);
        m.latch(FaultCode::OVERCURRENT);
        let (raw0, i0) = raw_at(0.0);
        assert!(m.clear(&raw0, i0, FaultCode::NONE).is_clear());
        m.latch(FaultCode::DISPLACEMENT_STUCK);
        assert!(m.clear(&raw0, i0, FaultCode::NONE).is_clear(), "the second trip must clear");
        m.latch(FaultCode::MISSED_DEADLINE);
        let still = m.clear(&raw0, i0, FaultCode::NONE);
        assert_eq!(still, FaultCode::MISSED_DEADLINE | FaultCode::REPEATED_TRIPS);
        // Faults that the board sees with the bridge off are not rationed.
        let mut m = FaultMonitor::new(FaultLimits::REFERENCE);
        for _ in 0..10 {
            m.latch(FaultCode::COMMAND_TIMEOUT | FaultCode::BUS_UNDERVOLTAGE);
            assert!(m.clear(&raw0, i0, FaultCode::NONE).is_clear());
        }
    }

    /// The bus after a hardware break (all four switches off): the coil's ½ L I² into the bus
    /// capacitance on top of 24 V, less the winding's resistive loss during the discharge. The
    /// figures firmware/README.md and `FaultLimits::REFERENCE` state, and their consequence:
    /// the bus over-voltage trip sees every break from above 3.83 A.
    #[test]
    fn the_coil_energy_of_a_hardware_break_exceeds_the_bus_limit() {
        use crate::sim::diode_discharge_peak_v;
        let (bus_v, bus_f) = (24.0f64, 100e-6f64); // the reference board's supply and bulk capacitance
        let p = crate::current::CurrentLoopParams::REFERENCE;
        let (l_h, r_ohm) = (p.coil_inductance_h as f64, p.coil_resistance_ohm as f64);
        let peak = |i: f64, c: f64| diode_discharge_peak_v(i, r_ohm, l_h, c, bus_v);
        let lossless = |i: f64| (bus_v * bus_v + l_h * i * i / bus_f).sqrt();
        let limits = FaultLimits::REFERENCE;
        let trip = limits.overcurrent_a as f64;
        assert!((peak(trip, bus_f) - 34.67).abs() < 0.02, "{}", peak(trip, bus_f));
        assert!((peak(4.4, bus_f) - 36.27).abs() < 0.02, "{}", peak(4.4, bus_f));
        // Without the resistance (the figures before): 39.2 and 41.7 V.
        assert!((lossless(trip) - 39.19).abs() < 0.01 && (lossless(4.4) - 41.68).abs() < 0.01);
        assert!((0.5 * l_h * 16.0 - 0.048).abs() < 1e-9);
        assert!(
            peak(trip, bus_f) > limits.max_bus_v as f64,
            "a break no longer passes the bus limit: update the docs"
        );
        // The largest current whose break stays under the trip on this bus: 3.83 A.
        let max_v = limits.max_bus_v as f64;
        assert!(peak(3.82, bus_f) < max_v && peak(3.84, bus_f) > max_v);
        // The bulk capacitance that keeps a 4.4 A break under the 34 V trip: 126 µF (108 µF
        // for 4 A); 201 µF without the resistance.
        assert!(peak(4.4, 125e-6) > max_v && peak(4.4, 127e-6) < max_v);
        assert!(peak(4.0, 107e-6) > max_v && peak(4.0, 109e-6) < max_v);
    }
}
