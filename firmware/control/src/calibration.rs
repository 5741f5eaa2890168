//! Bridge-off calibration: the current channel's zero and the displacement's rest position, both
//! measured over windows of samples taken while the bridge is off, judged on their spread as
//! well as their mean (an oscillating input can average to a plausible zero), and re-measured
//! after every run: arming takes the latest window completed since the bridge last went off.

use crate::faults::{FaultCode, FaultLimits};
use crate::tick::RawSample;
use crate::units::{Calibration, ADC_FULL_SCALE};

/// What one complete window measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// The current channel's zero (the window's mean) [V].
    pub current_zero_v: f32,
    /// The displacement at rest (the window's mean) [µm, absolute].
    pub rest_um: f32,
    /// Spread of the current codes (max − min) over the window.
    pub current_spread_codes: u16,
    /// Spread of the displacement over the window [µm].
    pub rest_spread_um: f32,
    /// What is wrong with it: [`FaultCode::CURRENT_OFFSET`] (zero outside its window around
    /// the nominal, or spreading too much), [`FaultCode::REST_POSITION`] (displacement at a
    /// rail, or spreading too much); clear when both are usable.
    pub faults: FaultCode,
}

/// Sums and spans of one window.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Window {
    samples: u16,
    current_sum: u32,
    current_span: (u16, u16),
    displacement_sum: u32,
    displacement_span: (u16, u16),
}

impl Window {
    const EMPTY: Window = Window {
        samples: 0,
        current_sum: 0,
        current_span: (u16::MAX, 0),
        displacement_sum: 0,
        displacement_span: (u16::MAX, 0),
    };
}

/// The calibration state: the window being filled and the latest complete one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdleCalibration {
    window_ticks: u16,
    settle_ticks: u16,
    settle_left: u16,
    window: Window,
    latest: Option<Measurement>,
    windows: u32,
}

impl IdleCalibration {
    /// Windows of `window_ticks` samples; after the bridge was on, the first `settle_ticks`
    /// bridge-off samples are skipped (the coil current decaying, the rod settling). At boot
    /// the bridge has never been on: no settling.
    pub const fn new(window_ticks: u16, settle_ticks: u16) -> Self {
        Self { window_ticks, settle_ticks, settle_left: 0, window: Window::EMPTY, latest: None, windows: 0 }
    }

    /// The bridge is about to switch: what was measured no longer describes the next idle
    /// period, and the next window starts `settle_ticks` after the bridge is off again.
    pub fn invalidate(&mut self) {
        self.settle_left = self.settle_ticks;
        self.window = Window::EMPTY;
        self.latest = None;
    }

    /// The latest complete window since the bridge was last on.
    pub fn latest(&self) -> Option<&Measurement> {
        self.latest.as_ref()
    }

    /// Windows completed since boot.
    pub fn windows(&self) -> u32 {
        self.windows
    }

    /// One bridge-off sample; returns the measurement when it completes a window. `nominal` is
    /// the front end's design calibration, `limits` the acceptance limits.
    pub fn sample(
        &mut self,
        raw: &RawSample,
        nominal: &Calibration,
        limits: &FaultLimits,
    ) -> Option<Measurement> {
        if self.settle_left > 0 {
            self.settle_left -= 1;
            return None;
        }
        let w = &mut self.window;
        let (i, y) = (raw.current.0, raw.displacement.0);
        w.samples += 1;
        w.current_sum += i as u32;
        w.current_span = (w.current_span.0.min(i), w.current_span.1.max(i));
        w.displacement_sum += y as u32;
        w.displacement_span = (w.displacement_span.0.min(y), w.displacement_span.1.max(y));
        if w.samples < self.window_ticks.max(1) {
            return None;
        }
        let m = judge(w, nominal, limits);
        self.window = Window::EMPTY;
        self.latest = Some(m);
        self.windows = self.windows.wrapping_add(1);
        Some(m)
    }
}

/// A complete window against the limits.
fn judge(w: &Window, nominal: &Calibration, limits: &FaultLimits) -> Measurement {
    let volts_per_code = nominal.vref / ADC_FULL_SCALE as f32;
    let n = w.samples as f32;
    let current_zero_v = w.current_sum as f32 / n * volts_per_code;
    let current_spread_codes = w.current_span.1 - w.current_span.0;
    let rest_v = w.displacement_sum as f32 / n * volts_per_code;
    let rest_um = (rest_v - nominal.displacement_zero_v) / nominal.displacement_v_per_um;
    let rest_spread_um = (w.displacement_span.1 - w.displacement_span.0) as f32 * volts_per_code
        / nominal.displacement_v_per_um.abs();
    let mut faults = FaultCode::NONE;
    // `!(… <= …)`: a NaN (a zero scale) must fail.
    let zero_ok = (current_zero_v - nominal.current_zero_v).abs() <= limits.current_offset_window_v;
    if !zero_ok || current_spread_codes > limits.current_zero_max_spread_codes {
        faults = faults | FaultCode::CURRENT_OFFSET;
    }
    let margin = limits.adc_margin;
    let at_rail = w.displacement_span.0 <= margin || w.displacement_span.1 >= ADC_FULL_SCALE - margin;
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let spread_bad = !(rest_spread_um <= limits.rest_max_spread_um);
    if at_rail || spread_bad || !rest_um.is_finite() {
        faults = faults | FaultCode::REST_POSITION;
    }
    Measurement { current_zero_v, rest_um, current_spread_codes, rest_spread_um, faults }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{AdcCode, Volts};

    fn raw(current: u16, displacement: u16) -> RawSample {
        RawSample {
            current: AdcCode(current),
            displacement: AdcCode(displacement),
            bus: Volts(24.0),
            break_tripped: false,
        }
    }

    /// Feeds one window of samples from `f(k)`; returns its measurement.
    fn window(c: &mut IdleCalibration, f: impl Fn(u16) -> (u16, u16)) -> Measurement {
        let (cal, limits) = (Calibration::REFERENCE_BOARD, FaultLimits::REFERENCE);
        (0..256)
            .find_map(|k| {
                let (i, y) = f(k);
                c.sample(&raw(i, y), &cal, &limits)
            })
            .expect("a 256-sample window must complete in 256 samples")
    }

    #[test]
    fn a_quiet_zero_and_rest_are_accepted_with_their_means() {
        let mut c = IdleCalibration::new(256, 50);
        // ±2 codes of noise around 2048 (1.650 V) and 820 (20 µm).
        let m = window(&mut c, |k| (2046 + k % 5, 818 + (k * 7) % 5));
        assert!(m.faults.is_clear(), "{:?}", m.faults.names().collect::<Vec<_>>());
        assert!((m.current_zero_v - 2048.0 * 3.3 / 4095.0).abs() < 1e-3, "{}", m.current_zero_v);
        assert!((m.rest_um - 820.0 * 3.3 / 4095.0 / 0.033).abs() < 0.01, "{}", m.rest_um);
        assert_eq!(m.current_spread_codes, 4);
    }

    #[test]
    fn an_oscillating_current_input_with_a_plausible_mean_is_refused() {
        let mut c = IdleCalibration::new(256, 50);
        // 1700 and 2400 codes alternating: mean 2050 (1.652 V, inside ±0.15 V), spread 700.
        let m = window(&mut c, |k| (if k % 2 == 0 { 1700 } else { 2400 }, 820));
        assert!((m.current_zero_v - 1.652).abs() < 0.002, "{}", m.current_zero_v);
        assert_eq!(m.faults, FaultCode::CURRENT_OFFSET, "spread {} codes", m.current_spread_codes);
        // The limit itself: 32 codes pass, 33 do not.
        let m = window(&mut c, |k| (if k % 2 == 0 { 2032 } else { 2064 }, 820));
        assert!(m.faults.is_clear());
        let m = window(&mut c, |k| (if k % 2 == 0 { 2032 } else { 2065 }, 820));
        assert_eq!(m.faults, FaultCode::CURRENT_OFFSET);
    }

    #[test]
    fn a_rest_at_a_rail_or_a_moving_probe_is_refused() {
        let mut c = IdleCalibration::new(256, 0);
        let m = window(&mut c, |_| (2048, 4090));
        assert_eq!(m.faults, FaultCode::REST_POSITION, "at the upper rail");
        let m = window(&mut c, |_| (2048, 5));
        assert_eq!(m.faults, FaultCode::REST_POSITION, "at the lower rail");
        // 1 µm is 41 codes: a probe swinging ±1 µm is refused, a quiet one is not.
        let m = window(&mut c, |k| (2048, if k % 2 == 0 { 800 } else { 882 }));
        assert_eq!(m.faults, FaultCode::REST_POSITION, "spread {} µm", m.rest_spread_um);
        let m = window(&mut c, |k| (2048, if k % 2 == 0 { 800 } else { 840 }));
        assert!(m.faults.is_clear(), "spread {} µm", m.rest_spread_um);
    }

    #[test]
    fn after_the_bridge_was_on_a_new_window_starts_only_after_settling() {
        let (cal, limits) = (Calibration::REFERENCE_BOARD, FaultLimits::REFERENCE);
        let mut c = IdleCalibration::new(256, 50);
        window(&mut c, |_| (2048, 820));
        assert!(c.latest().is_some());
        c.invalidate();
        assert!(c.latest().is_none(), "a run must invalidate the measurement");
        // The decaying coil current in the settling ticks never reaches the window.
        for k in 0..50u16 {
            assert!(c.sample(&raw(3000 - 19 * k, 820), &cal, &limits).is_none());
        }
        let m = window(&mut c, |_| (2050, 821));
        assert!(m.faults.is_clear() && c.latest() == Some(&m) && c.windows() == 2);
    }
}
