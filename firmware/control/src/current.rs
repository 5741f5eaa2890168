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
//!
//! The coil's inductance is not a constant: it follows the Terfenol-D rod's permeability, which
//! moves with bias, stress and temperature. Designed for the nominal inductance alone (model,
//! gain and zero all at 6 mH), a step overshoots 49 % at 0.5 L and 76 % at 0.4 L (the
//! closed-loop rig, `tests/closed_loop.rs`): with less inductance the loop gain K_p·b rises
//! above what the hidden tick tolerates. So the parts are designed for the range 0.5–1.5 L,
//! each where it is the weak point ([`CurrentLoopParams::REFERENCE`]): the delay model at the
//! low end (0.6 L: a model with more inductance than the coil under-predicts the change the
//! delay hides, and that is what rings), the PI zero toward the high end (1.2 L: a zero faster
//! than the coil's pole leaves a slow overshooting tail, a slower one a slow approach from
//! below), the gain for the nominal coil at the pole 0.45. Over 0.5–1.5 L a 0.5 A step then
//! overshoots at most 8.2 % (2.0 % at 1.0 L; 27 % at 0.4 L, outside the range), and the nominal
//! step still settles to 2 % in six ticks. The price: the loop's lag at the nominal inductance
//! grew by about a tick, so the compensator looks 4 ticks ahead instead of 3
//! (`ControlConfig::preview_ticks`), and the tracking figure moved from 0.70 % to 0.98 %.
//!
//! Regeneration: the supply cannot sink current, so whatever the bridge returns to the bus
//! (bus current d·i < 0, i.e. a voltage against the current) charges the bus capacitance. The
//! loop returns no more than the capacitance can take below `regen.max_bus_v` (30 V on the
//! reference board, under the 34 V trip): v·i ≥ −P with P = (½ C (V_max² − V_bus²) − E)/T,
//! E what the voltage already loaded returns during this period, at most `max_regen_w`
//! (ODrive's `dc_max_negative_current`, with the bus's headroom in place of a fixed current).
//! When the limit binds, the voltage moves toward 0 and the winding's resistance takes the
//! coil's energy instead. The limit is a clamp of the output, so the incremental form's
//! anti-windup covers it, and the Smith model sees the clamped voltage.

use crate::units::{Amps, Volts};

/// How much power the current loop may return to the bus, from the measured bus voltage: no more
/// than the bus capacitance can take before it reaches `max_bus_v`, counting what the voltage
/// already loaded for this period returns (the one-tick delay), and never more than
/// `max_regen_w`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegenLimit {
    /// The bus voltage regeneration must not push the bus beyond [V].
    pub max_bus_v: f32,
    /// The least bus capacitance the board has (after its tolerance) [F].
    pub bus_capacitance_f: f32,
    /// Most power returned to the bus at any voltage [W].
    pub max_regen_w: f32,
}

impl RegenLimit {
    /// The reference board: 24 V nominal, the over-voltage trip at 34 V, 100 µF of bulk
    /// capacitance (80 µF after a −20 % tolerance): the bus held to 30 V, at most 100 W
    /// returned (the coil returns 87 W at 4 A against −21.7 V).
    pub const REFERENCE: RegenLimit =
        RegenLimit { max_bus_v: 30.0, bus_capacitance_f: 80e-6, max_regen_w: 100.0 };

    /// No limit (the loop before the bus model; for comparisons).
    pub const NONE: RegenLimit =
        RegenLimit { max_bus_v: f32::MAX, bus_capacitance_f: f32::MAX, max_regen_w: f32::MAX };

    /// Most power the bridge may return over the next period [W, ≥ 0] at `bus_v`, when
    /// `committed_j` is already on its way for this one; 0 for a NaN reading.
    #[inline]
    pub fn allowed_w(&self, bus_v: f32, committed_j: f32, tick_s: f32) -> f32 {
        if *self == Self::NONE {
            return f32::MAX;
        }
        let headroom_j =
            0.5 * self.bus_capacitance_f * (self.max_bus_v * self.max_bus_v - bus_v * bus_v) - committed_j;
        if headroom_j > 0.0 {
            (headroom_j / tick_s).min(self.max_regen_w)
        } else {
            0.0
        }
    }

    fn is_valid(&self) -> bool {
        *self == Self::NONE
            || (self.max_bus_v.is_finite()
                && self.max_bus_v > 0.0
                && self.bus_capacitance_f.is_finite()
                && self.bus_capacitance_f > 0.0
                && self.max_regen_w.is_finite()
                && self.max_regen_w >= 0.0)
    }
}

/// Current-loop design parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentLoopParams {
    /// Coil resistance R [Ω] (000 Table 1: 6 Ω).
    pub coil_resistance_ohm: f32,
    /// Coil inductance L [H], nominal (000 Table 1: 6 mH).
    pub coil_inductance_h: f32,
    /// Tick period T [s].
    pub tick_s: f32,
    /// Closed-loop pole in (0, 1) when the coil has the nominal inductance and the model and the
    /// zero are exact: 0.4 settles a step to 2 % in 5 ticks (1 % in 6), no overshoot.
    pub pole: f32,
    /// Largest share of the bus voltage the bridge applies (dead time, bootstrap): 0.95.
    pub max_duty: f32,
    /// The inductance the delay model assumes, as a share of `coil_inductance_h`.
    pub model_inductance_ratio: f32,
    /// The inductance whose pole the PI zero cancels, as a share.
    pub zero_inductance_ratio: f32,
    /// The regeneration limit.
    pub regen: RegenLimit,
}

impl CurrentLoopParams {
    /// The reference coil at 10 kHz, robust over 0.5–1.5× its inductance (module docs).
    pub const REFERENCE: CurrentLoopParams = CurrentLoopParams {
        coil_resistance_ohm: 6.0,
        coil_inductance_h: 6e-3,
        tick_s: 1e-4,
        pole: 0.45,
        max_duty: 0.95,
        model_inductance_ratio: 0.6,
        zero_inductance_ratio: 1.2,
        regen: RegenLimit::REFERENCE,
    };

    /// The earlier design: model, gain and zero all at the nominal inductance, no regeneration
    /// limit (50 % overshoot at 0.5 L; kept for the comparison in the tests).
    pub const NOMINAL_ONLY: CurrentLoopParams = CurrentLoopParams {
        pole: 0.4,
        model_inductance_ratio: 1.0,
        zero_inductance_ratio: 1.0,
        regen: RegenLimit::NONE,
        ..Self::REFERENCE
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
    /// The PI zero e^{−TR/L_zero}.
    zero: f32,
    max_duty: f32,
    /// The internal coil model: pole e^{−TR/L_model} and b = (1 − pole)/R [A/V].
    model_p: f32,
    model_b: f32,
    /// The regeneration limit, per tick: ½ C V_max² / T [W], ½ C / T [W/V²], the most [W].
    regen_headroom_w: f32,
    regen_w_per_v2: f32,
    regen_max_w: f32,
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
    /// Whether the regeneration limit clipped it.
    pub regen_limited: bool,
}

/// e^{−T R / (ratio · L)} for the design.
fn coil_pole(p: &CurrentLoopParams, ratio: f32) -> f32 {
    model_core::math::exp(-p.tick_s * p.coil_resistance_ohm / (ratio * p.coil_inductance_h))
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
        for (name, r) in [
            ("model_inductance_ratio", p.model_inductance_ratio),
            ("zero_inductance_ratio", p.zero_inductance_ratio),
        ] {
            if !(r.is_finite() && (0.1..=10.0).contains(&r)) {
                return Err(CurrentLoopError::Parameter(name));
            }
        }
        if !p.regen.is_valid() {
            return Err(CurrentLoopError::Parameter("regen"));
        }
        let r = p.coil_resistance_ohm;
        let gain_b = (1.0 - coil_pole(&p, 1.0)) / r;
        let model_p = coil_pole(&p, p.model_inductance_ratio);
        let unlimited = p.regen == RegenLimit::NONE;
        Ok(Self {
            kp: (1.0 - p.pole) / gain_b,
            zero: coil_pole(&p, p.zero_inductance_ratio),
            max_duty: p.max_duty,
            model_p,
            model_b: (1.0 - model_p) / r,
            regen_headroom_w: if unlimited {
                f32::INFINITY
            } else {
                0.5 * p.regen.bus_capacitance_f * p.regen.max_bus_v * p.regen.max_bus_v / p.tick_s
            },
            regen_w_per_v2: if unlimited { 0.0 } else { 0.5 * p.regen.bus_capacitance_f / p.tick_s },
            regen_max_w: p.regen.max_regen_w,
            last_error: 0.0,
            last_voltage: 0.0,
            model_a: 0.0,
        })
    }

    /// A loop that always outputs 0 V (for a controller whose design was refused: it never
    /// enables the bridge anyway).
    pub const fn idle() -> Self {
        Self {
            kp: 0.0,
            zero: 0.0,
            max_duty: 0.0,
            model_p: 0.0,
            model_b: 0.0,
            regen_headroom_w: 0.0,
            regen_w_per_v2: 0.0,
            regen_max_w: 0.0,
            last_error: 0.0,
            last_voltage: 0.0,
            model_a: 0.0,
        }
    }

    /// Proportional gain K_p [V/A].
    pub fn kp(&self) -> f32 {
        self.kp
    }

    /// Forgets the integrator and the delay model (after a trip: the bridge restarts from zero
    /// volts, and the coil is at zero current by the time it does).
    pub fn reset(&mut self) {
        self.last_error = 0.0;
        self.last_voltage = 0.0;
        self.model_a = 0.0;
    }

    /// One tick: reference and measured current, measured bus voltage.
    #[inline]
    pub fn step(&mut self, reference: Amps, measured: Amps, bus: Volts) -> BridgeCommand {
        // The model's undelayed current x̂[k] from last tick's (clamped) voltage.
        let model_now = self.model_p * self.model_a + self.model_b * self.last_voltage;
        let e = reference.0 - (measured.0 + model_now - self.model_a);
        self.model_a = model_now;
        let v_max = self.max_duty * bus.0.max(0.0);
        let mut v = self.last_voltage + self.kp * (e - self.zero * self.last_error);
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
        // Power returned to the bus: −v·i where v opposes i. Held to the bus's allowance by
        // moving v toward 0 (never past it: |p_min / i| < |v| when the limit binds).
        // (RegenLimit::allowed_w with the constants folded in at design time.)
        let committed_w = (-self.last_voltage * measured.0).max(0.0);
        let headroom_w = self.regen_headroom_w - self.regen_w_per_v2 * bus.0 * bus.0 - committed_w;
        let p_min = if headroom_w > 0.0 { -headroom_w.min(self.regen_max_w) } else { 0.0 };
        let regen_limited = v * measured.0 < p_min;
        if regen_limited {
            v = p_min / measured.0;
        }
        self.last_error = e;
        self.last_voltage = v;
        let duty = if bus.0 > 1.0 { v / bus.0 } else { 0.0 };
        BridgeCommand { voltage: Volts(v), duty, saturated, regen_limited }
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

    /// The loop's folded-in regeneration limit is `RegenLimit::allowed_w`: ½·80 µF·(30² − V²)
    /// per 100 µs less what is committed: 38.4 W at 27 V with 30 W committed, 129.6 W (cut to
    /// 100 W) at 24 V, 2.4 W at 29.9 V, none at 29.9 V with 30 W committed.
    #[test]
    fn the_regeneration_limit_is_the_bus_headroom() {
        let r = RegenLimit::REFERENCE;
        assert!(
            (r.allowed_w(27.0, 30.0 * 1e-4, 1e-4) - 38.4).abs() < 1e-3,
            "{}",
            r.allowed_w(27.0, 3e-3, 1e-4)
        );
        assert_eq!(r.allowed_w(24.0, 0.0, 1e-4), 100.0);
        assert!((r.allowed_w(29.9, 0.0, 1e-4) - 2.396).abs() < 0.01);
        assert_eq!(r.allowed_w(29.9, 30.0 * 1e-4, 1e-4), 0.0);
        assert_eq!(r.allowed_w(f32::NAN, 0.0, 1e-4), 0.0);
        assert_eq!(RegenLimit::NONE.allowed_w(40.0, 1.0, 1e-4), f32::MAX);
        // The loop, from rest: a step down from 3 A asks for a large negative voltage. At 29.9 V
        // it returns at most the 2.4 W headroom, and says so; at 24 V the limit does not bind.
        let mut pi = CurrentLoop::new(CurrentLoopParams::REFERENCE).unwrap();
        let cmd = pi.step(Amps(0.0), Amps(3.0), Volts(29.9));
        assert!(cmd.regen_limited && cmd.voltage.0 * 3.0 >= -2.41 && cmd.voltage.0 < 0.0, "{cmd:?}");
        let mut pi = CurrentLoop::new(CurrentLoopParams::REFERENCE).unwrap();
        let cmd = pi.step(Amps(0.0), Amps(3.0), Volts(24.0));
        assert!(!cmd.regen_limited && cmd.voltage.0 < -20.0, "{cmd:?}");
        // With 30 W already committed at 27 V: 38.4 W more, v = −12.8 V against 3 A.
        let mut pi = CurrentLoop::new(CurrentLoopParams::REFERENCE).unwrap();
        pi.last_voltage = -10.0;
        let cmd = pi.step(Amps(0.0), Amps(3.0), Volts(27.0));
        assert!(cmd.regen_limited && (cmd.voltage.0 + 12.8).abs() < 0.01, "{cmd:?}");
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
