//! Repetitive-error rejection at the reference's fundamental (adaptive feedforward
//! cancellation): a sine reference is periodic, so what the compensator gets wrong (a model 10 %
//! off) returns every period. The PID's gain at 100 Hz leaves 1–2 % of it; this term learns
//! the cosine and sine amplitudes of the current that cancel it, which is a resonant controller
//! with infinite gain at exactly the reference frequency. The learning runs along the
//! regressor advanced by `phase_lead_rad`, the phase of the displacement's response to an added
//! current with the PID loop closed: with an integral-dominated PID that response is about 1/C,
//! +90° less the closed loop's lag (about +70° at 100 Hz for the reference design). Learning
//! converges while the true phase is within 90° of the lead: on our simulated rig leads of
//! 40–70° converge at 200 and 300 Hz and 0°/−40° diverge, so 70° is used throughout; the
//! frequency limit keeps it where that estimate holds.

use model_core::ParamError;

/// Harmonics of the reference frequency learned (1: the fundamental only; hysteresis adds odd
/// and, with a bias, even harmonics).
pub const HARMONICS: usize = 3;

/// Design of the fundamental-rejection term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResonantParams {
    /// Learning gain [A/µm per tick].
    pub gain_a_per_um: f32,
    /// Phase lead of the learning regressor at each harmonic [rad].
    pub phase_lead_rad: [f32; HARMONICS],
    /// Highest reference frequency it runs at [Hz] (above it the phase estimate is not trusted).
    pub max_freq_hz: f32,
    /// Largest amplitude of each learned component [A].
    pub limit_a: f32,
    /// Learning pauses while |error| exceeds this [µm]: a large error is a transient (the power
    /// stage clipping, a step) that the PID handles, not the small repeating residual, and
    /// learning from it would leave a wrong correction to unlearn slowly.
    pub max_error_um: f32,
}

/// The validated term and its learned amplitudes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonant {
    gain: f32,
    lead: [(f32, f32); HARMONICS],
    max_freq_hz: f32,
    limit_a: f32,
    max_error_um: f32,
    cos_a: [f32; HARMONICS],
    sin_a: [f32; HARMONICS],
}

impl Resonant {
    /// Checks the design: gain finite and ≥ 0, limits finite and > 0, the lead within ±π/2.
    pub fn new(p: ResonantParams) -> Result<Self, ParamError> {
        if !(p.gain_a_per_um.is_finite() && p.gain_a_per_um >= 0.0) {
            return Err(ParamError::OutOfRange("resonant.gain_a_per_um", "finite, ≥ 0 A/µm"));
        }
        let half_pi = core::f32::consts::FRAC_PI_2;
        if !p.phase_lead_rad.iter().all(|l| l.is_finite() && l.abs() <= half_pi) {
            return Err(ParamError::OutOfRange("resonant.phase_lead_rad", "within ±π/2"));
        }
        if !(p.max_freq_hz.is_finite() && p.max_freq_hz > 0.0) {
            return Err(ParamError::OutOfRange("resonant.max_freq_hz", "finite, > 0 Hz"));
        }
        if !(p.limit_a.is_finite() && p.limit_a > 0.0) {
            return Err(ParamError::OutOfRange("resonant.limit_a", "finite, > 0 A"));
        }
        if !(p.max_error_um.is_finite() && p.max_error_um > 0.0) {
            return Err(ParamError::OutOfRange("resonant.max_error_um", "finite, > 0 µm"));
        }
        let lead = p.phase_lead_rad.map(|l| {
            let (s, c) = model_core::math::sin_cos(l);
            (c, s)
        });
        Ok(Self {
            gain: p.gain_a_per_um,
            lead,
            max_freq_hz: p.max_freq_hz,
            limit_a: p.limit_a,
            max_error_um: p.max_error_um,
            cos_a: [0.0; HARMONICS],
            sin_a: [0.0; HARMONICS],
        })
    }

    /// Whether it runs at this reference frequency.
    pub fn runs_at(&self, freq_hz: f32) -> bool {
        freq_hz > 0.0 && freq_hz <= self.max_freq_hz
    }

    /// Forgets what it learned (a new reference, or the bridge re-armed).
    pub fn reset(&mut self) {
        self.cos_a = [0.0; HARMONICS];
        self.sin_a = [0.0; HARMONICS];
    }

    /// One tick: the displacement error [µm] and the reference's phasor (cos θ, sin θ) at this
    /// tick in; the current [A] out.
    #[inline]
    pub fn step(&mut self, error_um: f32, phasor: (f32, f32)) -> f32 {
        let g = if error_um.abs() <= self.max_error_um { self.gain * error_um } else { 0.0 };
        let l = self.limit_a;
        let mut out = 0.0;
        // The h-th harmonic's phasor: the fundamental's multiplied in h times.
        let (mut c, mut s) = phasor;
        for h in 0..HARMONICS {
            out += self.cos_a[h] * c + self.sin_a[h] * s;
            let (lc, ls) = self.lead[h];
            self.cos_a[h] = (self.cos_a[h] + g * (c * lc - s * ls)).clamp(-l, l);
            self.sin_a[h] = (self.sin_a[h] + g * (s * lc + c * ls)).clamp(-l, l);
            (c, s) = (c * phasor.0 - s * phasor.1, s * phasor.0 + c * phasor.1);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_design_is_refused_by_name_and_learning_is_bounded() {
        let ok = ResonantParams {
            gain_a_per_um: 0.001,
            phase_lead_rad: [1.0; HARMONICS],
            max_freq_hz: 250.0,
            limit_a: 0.5,
            max_error_um: 100.0,
        };
        assert!(Resonant::new(ok).is_ok());
        let lead = ResonantParams { phase_lead_rad: [1.0, 2.0, 0.0], ..ok };
        assert_eq!(
            Resonant::new(lead),
            Err(ParamError::OutOfRange("resonant.phase_lead_rad", "within ±π/2"))
        );
        let gain = ResonantParams { gain_a_per_um: f32::NAN, ..ok };
        assert!(matches!(Resonant::new(gain), Err(ParamError::OutOfRange("resonant.gain_a_per_um", _))));
        // A persistent error cannot wind the learned amplitudes past their limit.
        let mut r = Resonant::new(ok).unwrap();
        let mut worst = 0.0f32;
        for k in 0..100_000 {
            let (s, c) = model_core::math::sin_cos(k as f32 * 0.0628);
            worst = worst.max(r.step(50.0, (c, s)).abs());
        }
        assert!(worst <= 0.5 * HARMONICS as f32 * core::f32::consts::SQRT_2 + 1e-3, "output {worst} A");
        assert!(r.runs_at(100.0) && !r.runs_at(300.0) && !r.runs_at(0.0));
        // Beyond the error gate nothing is learned.
        let mut r = Resonant::new(ResonantParams { max_error_um: 10.0, ..ok }).unwrap();
        for k in 0..1000 {
            let (s, c) = model_core::math::sin_cos(k as f32 * 0.0628);
            r.step(50.0, (c, s));
        }
        assert_eq!(r.step(0.0, (1.0, 0.0)), 0.0);
    }
}
