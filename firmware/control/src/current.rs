//! The 10 kHz coil current loop: a discrete PI whose zero cancels the coil's electrical pole,
//! in incremental (velocity) form so that clamping the output is the anti-windup, and the bridge
//! duty computed from the measured bus voltage (bus-voltage feedforward).
//!
//! Coil: L di/dt = v − R i, held voltage over a tick T. On the board the voltage computed in
//! tick k loads at the next PWM update, so it is across the coil from k + 1 to k + 2:
//! i[k+1] = p i[k] + b v[k−1], p = e^{−TR/L}, b = (1 − p)/R — a pure one-tick delay in the loop.
//! A PI tuned without it (pole 0.4) overshoots 44 % with it, and re-tuning the PI alone for the
//! delay gives a loop several times slower. The delay is known exactly (one tick, set by the
//! timer), so it is compensated instead, Smith-predictor style: an internal coil model x̂ driven
//! by the voltages actually commanded gives the current the loop would see without the delay,
//! and the PI acts on y = i[k] + (x̂[k] − x̂[k−1]) — the measurement plus the model's change that
//! the delay still hides. With an exact model y equals the undelayed current, so
//! v[k] = v[k−1] + K_p (e[k] − p e[k−1]) again makes the loop first order with its pole at
//! 1 − K_p b (chosen as `pole`), followed by the one-tick delay: no overshoot. The correction is
//! a difference of the model, zero in steady state, so a wrong R or L cannot leave a steady
//! error (the integrator still sees the measured current).

use crate::units::{Amps, Volts};

/// Current-loop design parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentLoopParams {
    /// Coil resistance R [Ω] (000 Table 1: 6 Ω).
    pub coil_resistance_ohm: f32,
    /// Coil inductance L [H] (000 Table 1: 6 mH).
    pub coil_inductance_h: f32,
    /// Tick period T [s].
    pub tick_s: f32,
    /// Closed-loop pole in (0, 1): 0.4 settles a step to 2 % in 5 ticks (1 % in 6), no overshoot.
    pub pole: f32,
    /// Largest share of the bus voltage the bridge applies (dead time, bootstrap): 0.95.
    pub max_duty: f32,
}

impl CurrentLoopParams {
    /// The reference coil at 10 kHz.
    pub const REFERENCE: CurrentLoopParams = CurrentLoopParams {
        coil_resistance_ohm: 6.0,
        coil_inductance_h: 6e-3,
        tick_s: 1e-4,
        pole: 0.4,
        max_duty: 0.95,
    };
}

/// Why a current-loop design was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CurrentLoopError {
    /// A parameter is not finite or out of its range (named).
    Parameter(&'static str),
}

/// The current controller (gains fixed at construction) and its state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentLoop {
    kp: f32,
    p: f32,
    max_duty: f32,
    /// b = (1 − p)/R of the internal coil model [A/V].
    b: f32,
    last_error: f32,
    /// The voltage commanded last tick (across the coil during the coming period) [V].
    last_voltage: f32,
    /// The internal model's undelayed current x̂[k−1] [A].
    model_a: f32,
}

/// What one current-loop step produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BridgeCommand {
    /// Coil voltage asked of the bridge [V].
    pub voltage: Volts,
    /// Signed bridge duty in [−max_duty, max_duty] (voltage / bus voltage).
    pub duty: f32,
    /// Whether the voltage limit clipped the PI output this tick.
    pub saturated: bool,
}

impl CurrentLoop {
    /// Designs the loop.
    pub fn new(p: CurrentLoopParams) -> Result<Self, CurrentLoopError> {
        let ok = |v: f32| v.is_finite() && v > 0.0;
        if !ok(p.coil_resistance_ohm) {
            return Err(CurrentLoopError::Parameter("coil_resistance_ohm"));
        }
        if !ok(p.coil_inductance_h) {
            return Err(CurrentLoopError::Parameter("coil_inductance_h"));
        }
        if !ok(p.tick_s) {
            return Err(CurrentLoopError::Parameter("tick_s"));
        }
        if !(p.pole.is_finite() && p.pole > 0.0 && p.pole < 1.0) {
            return Err(CurrentLoopError::Parameter("pole"));
        }
        if !(p.max_duty.is_finite() && p.max_duty > 0.0 && p.max_duty <= 1.0) {
            return Err(CurrentLoopError::Parameter("max_duty"));
        }
        let pole = model_core::math::exp(-p.tick_s * p.coil_resistance_ohm / p.coil_inductance_h);
        let b = (1.0 - pole) / p.coil_resistance_ohm;
        Ok(Self {
            kp: (1.0 - p.pole) / b,
            p: pole,
            max_duty: p.max_duty,
            b,
            last_error: 0.0,
            last_voltage: 0.0,
            model_a: 0.0,
        })
    }

    /// A loop that always outputs 0 V (for a controller whose design was refused: it never
    /// enables the bridge anyway).
    pub const fn idle() -> Self {
        Self { kp: 0.0, p: 0.0, max_duty: 0.0, b: 0.0, last_error: 0.0, last_voltage: 0.0, model_a: 0.0 }
    }

    /// Proportional gain K_p [V/A].
    pub fn kp(&self) -> f32 {
        self.kp
    }

    /// Forgets the integrator and the delay model (after a trip: the bridge restarts from zero
    /// volts, and the freewheeling coil is at zero current by the time it does).
    pub fn reset(&mut self) {
        self.last_error = 0.0;
        self.last_voltage = 0.0;
        self.model_a = 0.0;
    }

    /// One tick: reference and measured current, measured bus voltage.
    #[inline]
    pub fn step(&mut self, reference: Amps, measured: Amps, bus: Volts) -> BridgeCommand {
        // The model's undelayed current x̂[k] from last tick's (clamped) voltage.
        let model_now = self.p * self.model_a + self.b * self.last_voltage;
        let e = reference.0 - (measured.0 + model_now - self.model_a);
        self.model_a = model_now;
        let v_max = self.max_duty * bus.0.max(0.0);
        let mut v = self.last_voltage + self.kp * (e - self.p * self.last_error);
        let saturated = v.is_nan() || v > v_max || v < -v_max;
        v = if v > v_max {
            v_max
        } else if v < -v_max {
            -v_max
        } else if v.is_nan() {
            0.0
        } else {
            v
        };
        self.last_error = e;
        self.last_voltage = v;
        let duty = if bus.0 > 1.0 { v / bus.0 } else { 0.0 };
        BridgeCommand { voltage: Volts(v), duty, saturated }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 0 → 1 A step on a coil with the one-tick PWM delay, resistance `r_ohm`, inductance
    /// `l_h` (the design assumes 6 Ω, 6 mH); returns the current over 200 ticks.
    fn step_on(r_ohm: f32, l_h: f32) -> Vec<f32> {
        let mut pi = CurrentLoop::new(CurrentLoopParams::REFERENCE).unwrap();
        let p = model_core::math::exp(-1e-4 * r_ohm / l_h);
        let (mut i, mut loaded_v) = (0.0f32, 0.0f32);
        (0..200)
            .map(|_| {
                let v = pi.step(Amps(1.0), Amps(i), Volts(24.0)).voltage.0;
                i = p * i + (1.0 - p) / r_ohm * loaded_v;
                loaded_v = v;
                i
            })
            .collect()
    }

    #[test]
    fn the_delay_compensation_leaves_no_steady_error_on_a_wrong_coil_model() {
        let exact = step_on(6.0, 6e-3);
        assert!(exact.iter().all(|&i| i <= 1.0 + 1e-4), "exact model overshoots: {exact:?}");
        // A hot winding (+25 % R) and 20 % less inductance than designed for.
        let off = step_on(7.5, 4.8e-3);
        let peak = off.iter().fold(0.0f32, |m, &i| m.max(i));
        assert!((off[199] - 1.0).abs() < 1e-3, "steady error with a wrong model: {}", off[199]);
        assert!(peak < 1.15, "wrong model overshoots {:.1} %", (peak - 1.0) * 100.0);
    }
}
