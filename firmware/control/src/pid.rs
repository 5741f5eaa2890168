//! The displacement PID: incremental (velocity) form on the error [µm], its output the current
//! correction [A]. Clamping the accumulated output is the anti-windup.

use model_core::ParamError;

/// PID design parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidParams {
    /// Proportional [A/µm].
    pub kp: f32,
    /// Integral per tick [A/µm].
    pub ki: f32,
    /// Derivative [A/µm].
    pub kd: f32,
    /// Largest correction [A].
    pub limit_a: f32,
}

/// The PID's validated gains (fixed at construction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    kp: f32,
    ki: f32,
    kd: f32,
    limit_a: f32,
}

/// What the PID carries from tick to tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PidState {
    output_a: f32,
    e1: f32,
    e2: f32,
}

impl Pid {
    /// Checks the parameters: gains finite and ≥ 0, the limit finite and > 0.
    pub fn new(p: PidParams) -> Result<Self, ParamError> {
        for (name, v) in [("pid.kp", p.kp), ("pid.ki", p.ki), ("pid.kd", p.kd)] {
            if !v.is_finite() {
                return Err(ParamError::NonFinite(name));
            }
            if v < 0.0 {
                return Err(ParamError::OutOfRange(name, "≥ 0 A/µm"));
            }
        }
        if !p.limit_a.is_finite() {
            return Err(ParamError::NonFinite("pid.limit_a"));
        }
        if p.limit_a <= 0.0 {
            return Err(ParamError::OutOfRange("pid.limit_a", "> 0 A"));
        }
        Ok(Self { kp: p.kp, ki: p.ki, kd: p.kd, limit_a: p.limit_a })
    }

    /// One tick: the displacement error (reference − measured) [µm] in, the correction [A] out.
    #[inline]
    pub fn step(&self, s: &mut PidState, error_um: f32) -> f32 {
        let e = error_um;
        let d = self.kp * (e - s.e1) + self.ki * e + self.kd * (e - 2.0 * s.e1 + s.e2);
        s.output_a = (s.output_a + d).clamp(-self.limit_a, self.limit_a);
        s.e2 = s.e1;
        s.e1 = e;
        s.output_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_parameter_is_refused_by_name() {
        let ok = PidParams { kp: 0.02, ki: 0.02, kd: 0.0, limit_a: 1.0 };
        assert!(Pid::new(ok).is_ok());
        assert_eq!(Pid::new(PidParams { ki: f32::NAN, ..ok }), Err(ParamError::NonFinite("pid.ki")));
        assert_eq!(Pid::new(PidParams { kp: -0.1, ..ok }), Err(ParamError::OutOfRange("pid.kp", "≥ 0 A/µm")));
        assert_eq!(
            Pid::new(PidParams { limit_a: 0.0, ..ok }),
            Err(ParamError::OutOfRange("pid.limit_a", "> 0 A"))
        );
    }

    #[test]
    fn the_output_is_clamped_without_winding_up() {
        let pid = Pid::new(PidParams { kp: 0.0, ki: 0.5, kd: 0.0, limit_a: 1.0 }).unwrap();
        let mut s = PidState::default();
        for _ in 0..10 {
            pid.step(&mut s, 1.0);
        }
        assert_eq!(s.output_a, 1.0);
        // Clamped, not accumulated: one tick of opposite error already comes off the limit.
        assert_eq!(pid.step(&mut s, -1.0), 0.5);
    }
}
