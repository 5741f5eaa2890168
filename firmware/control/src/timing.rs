//! The tick period, measured: the control design (the current loop's coil model, the reference's
//! phase steps, the I²t integral) assumes one tick every `tick_s`; the board times each
//! interrupt entry with the CPU's cycle counter and this check judges the intervals.
//!
//! An entry delayed by interrupt latency (a critical section in thread mode: an arm command holds
//! the interrupt off for about 3 500 instructions, a fifth of a tick) lengthens one interval and
//! shortens the next by the same amount, so single intervals cannot be held to ±2 %. Their sum
//! can: over a window of [`WINDOW`] intervals the latencies telescope to the last one minus the
//! first, at most 3 500 / (32 · 17 000) = 0.7 %. So the period is judged on each window's
//! length (±2 %), and any single interval off by half a period or more (a lost or a spurious
//! trigger) latches at once. Intervals outside ±2 % one by one are only counted.

/// Intervals per judged window.
pub const WINDOW: u32 = 32;

/// The check's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickPeriod {
    nominal: u32,
    tolerance: u32,
    settle: u8,
    last: Option<u32>,
    window_start: u32,
    window_intervals: u32,
    /// Intervals outside the tolerance one by one so far (latency included).
    pub off: u32,
    /// The last interval [cycles].
    pub last_interval: u32,
    /// The last complete window's length [cycles] (nominal: [`WINDOW`] periods).
    pub last_window: u32,
    /// Windows judged right so far (a `tick_timing` fault may clear only after one more).
    pub clean_windows: u32,
}

impl TickPeriod {
    /// Expects `nominal` cycles between entries, ± `tolerance` on average over a window; the
    /// first `settle` intervals (start-up: the first conversion, the interrupt unmasked
    /// mid-period) are not judged.
    pub const fn new(nominal: u32, tolerance: u32, settle: u8) -> Self {
        Self {
            nominal,
            tolerance,
            settle,
            last: None,
            window_start: 0,
            window_intervals: 0,
            off: 0,
            last_interval: 0,
            last_window: 0,
            clean_windows: 0,
        }
    }

    /// Leaves the next `n` intervals unjudged and starts a new window after them: for a known
    /// long critical section (a parameter load's move, bridge off), whose late entry may pass
    /// the lost-tick limit.
    pub fn resettle(&mut self, n: u8) {
        self.settle = self.settle.max(n);
    }

    /// One interrupt entry at `now` (a free-running 32-bit cycle counter, wrapping); true when
    /// the period is wrong.
    #[inline]
    pub fn entry(&mut self, now: u32) -> bool {
        let Some(last) = self.last.replace(now) else {
            self.window_start = now;
            return false;
        };
        let d = now.wrapping_sub(last);
        self.last_interval = d;
        if self.settle > 0 {
            self.settle -= 1;
            self.window_start = now;
            self.window_intervals = 0;
            return false;
        }
        if d > self.nominal + self.tolerance || d < self.nominal.saturating_sub(self.tolerance) {
            self.off = self.off.wrapping_add(1);
        }
        let gross = d > self.nominal + self.nominal / 2 || d < self.nominal / 2;
        self.window_intervals += 1;
        if self.window_intervals < WINDOW {
            return gross;
        }
        let length = now.wrapping_sub(self.window_start);
        self.last_window = length;
        self.window_start = now;
        self.window_intervals = 0;
        let (expected, tolerance) = (self.nominal * WINDOW, self.tolerance * WINDOW);
        let wrong = gross || length > expected + tolerance || length < expected - tolerance;
        if !wrong {
            self.clean_windows = self.clean_windows.wrapping_add(1);
        }
        wrong
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOMINAL: u32 = 17_000;

    fn check() -> TickPeriod {
        TickPeriod::new(NOMINAL, NOMINAL / 50, 2)
    }

    /// Feeds entries `interval(k)` cycles apart, starting near the counter's wrap; returns the
    /// index of the first interval judged wrong.
    fn first_fault(p: &mut TickPeriod, n: u32, interval: impl Fn(u32) -> u32) -> Option<u32> {
        let mut now = u32::MAX - 100_000;
        p.entry(now);
        (0..n).find(|&k| {
            now = now.wrapping_add(interval(k));
            p.entry(now)
        })
    }

    #[test]
    fn the_nominal_period_with_jitter_and_the_counter_wrap_passes() {
        let mut p = check();
        // ±1 % jitter (170 cycles) alternating, across the 32-bit wrap (25 s at 170 MHz).
        assert_eq!(first_fault(&mut p, 100_000, |k| if k % 2 == 0 { 17_170 } else { 16_830 }), None);
        assert_eq!(p.off, 0);
        assert_eq!(p.last_window, WINDOW * NOMINAL);
    }

    #[test]
    fn interrupt_latency_is_not_a_wrong_period() {
        let mut p = check();
        // An arm command's critical section (3 548 instructions) delays entry 100; a set-reference
        // (900) delays entry 300 and an arm entry 301: intervals 21 % and 15 % long in a row.
        let f = first_fault(&mut p, 1000, |k| match k {
            100 => NOMINAL + 3548,
            101 => NOMINAL - 3548,
            300 => NOMINAL + 900,
            301 => NOMINAL + 3548 - 900,
            302 => NOMINAL - 3548,
            _ => NOMINAL,
        });
        assert_eq!(f, None);
        assert_eq!(p.off, 5, "each late or early interval counted");
    }

    #[test]
    fn a_period_off_by_more_than_two_percent_latches_at_the_end_of_its_window() {
        for interval in [17_350, 16_650, 20_000, 14_000] {
            let mut p = check();
            // Two settling intervals, then the first window of 32.
            assert_eq!(first_fault(&mut p, 100, |_| interval), Some(2 + WINDOW - 1), "{interval} cycles");
        }
        // Within ±2 % it never latches.
        for interval in [17_335, 16_665] {
            let mut p = check();
            assert_eq!(first_fault(&mut p, 10_000, |_| interval), None, "{interval} cycles");
        }
    }

    #[test]
    fn a_lost_or_a_spurious_tick_latches_at_once() {
        let mut p = check();
        assert_eq!(first_fault(&mut p, 100, |k| if k == 50 { 2 * NOMINAL } else { NOMINAL }), Some(50));
        let mut p = check();
        assert_eq!(first_fault(&mut p, 100, |k| if k == 50 { NOMINAL / 3 } else { NOMINAL }), Some(50));
        // The first intervals after start-up are not judged.
        let mut p = check();
        assert_eq!(first_fault(&mut p, 100, |k| if k < 2 { 5 * NOMINAL } else { NOMINAL }), None);
    }

    #[test]
    fn only_windows_judged_right_count_as_clean() {
        let mut p = check();
        // Two settling intervals, then three windows: right, wrong (3 % long), right.
        let mut now = 0u32;
        p.entry(now);
        let mut wrong = 0;
        for k in 0..2 + 3 * WINDOW {
            let window = k.saturating_sub(2) / WINDOW;
            now = now.wrapping_add(if window == 1 { NOMINAL * 103 / 100 } else { NOMINAL });
            wrong += p.entry(now) as u32;
        }
        assert_eq!((wrong, p.clean_windows), (1, 2));
    }

    #[test]
    fn a_known_long_lock_is_not_judged() {
        // A parameter load holds the interrupt off for 60 % of a period before entry 100.
        let interval = |k: u32| match k {
            100 => NOMINAL + NOMINAL * 3 / 5,
            101 => NOMINAL - NOMINAL * 3 / 5,
            _ => NOMINAL,
        };
        let mut p = check();
        assert_eq!(first_fault(&mut p, 1000, interval), Some(100), "unannounced, it reads as a lost tick");
        let mut p = check();
        let mut now = 0u32;
        p.entry(now);
        for k in 0..1000 {
            if k == 100 {
                p.resettle(2);
            }
            now = now.wrapping_add(interval(k));
            assert!(!p.entry(now), "interval {k} judged wrong after resettle");
        }
    }
}
