//! ARX linear dynamics (003 eq. 3): A(z⁻¹) y[k] = z^{−d} B(z⁻¹) u[k], with
//! A = 1 + a_1 z⁻¹ + … + a_n z⁻ⁿ and B = b_0 + b_1 z⁻¹ + … + b_m z⁻ᵐ, so
//! y[k] = −Σ a_i y[k−i] + Σ b_j u[k−d−j].
//!
//! Fixed orders and delay (const generics `NA` = n, `NB` = m + 1, `D` = d): the history is two
//! small ring-free shift registers, the step is NA + NB multiply-adds. In 003 the input is the
//! compensated "λ" (the desired displacement after the Preisach inverse) and y the measured
//! displacement; d = 1, n = 2, m = 1.

use crate::error::ParamError;

/// ARX coefficients (immutable once validated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArxParams<const NA: usize, const NB: usize, const D: usize> {
    /// a_1 … a_n (A's leading 1 is implicit).
    pub a: [f32; NA],
    /// b_0 … b_m.
    pub b: [f32; NB],
}

impl ArxParams<2, 2, 1> {
    /// 003: A(z⁻¹) = 1 − 0.4877 z⁻¹ − 0.2711 z⁻², B(z⁻¹) = 1.015 − 0.7727 z⁻¹, d = 1.
    pub const DAVINO_003: ArxParams<2, 2, 1> = ArxParams { a: [-0.4877, -0.2711], b: [1.015, -0.7727] };
}

impl<const NA: usize, const NB: usize, const D: usize> ArxParams<NA, NB, D> {
    /// Static (DC) gain B(1) / A(1), in f64.
    pub fn static_gain(&self) -> f64 {
        let b1: f64 = self.b.iter().map(|&v| v as f64).sum();
        let a1: f64 = 1.0 + self.a.iter().map(|&v| v as f64).sum::<f64>();
        b1 / a1
    }
}

/// Validated ARX model (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arx<const NA: usize, const NB: usize, const D: usize> {
    p: ArxParams<NA, NB, D>,
}

/// Past outputs y[k−1…k−n] and inputs u[k−1…k−d−m] (mutable, per sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArxState<const NA: usize, const NU: usize> {
    y: [f32; NA],
    u: [f32; NU],
}

impl<const NA: usize, const NB: usize, const D: usize> Arx<NA, NB, D> {
    /// Validates: finite coefficients, at least one b, and A stable (every root of
    /// zⁿ + a_1 zⁿ⁻¹ + … + a_n inside the unit circle, checked by the Jury/Schur–Cohn
    /// recursion), so that no bounded input drives the output to infinity.
    pub fn new(p: ArxParams<NA, NB, D>) -> Result<Self, ParamError> {
        if NB == 0 {
            return Err(ParamError::OutOfRange("arx.b", "at least one coefficient"));
        }
        if p.a.iter().any(|v| !v.is_finite()) {
            return Err(ParamError::NonFinite("arx.a"));
        }
        if p.b.iter().any(|v| !v.is_finite()) {
            return Err(ParamError::NonFinite("arx.b"));
        }
        if !schur_cohn_stable(&p.a) {
            return Err(ParamError::OutOfRange(
                "arx.a",
                "a stable A(z^-1): every pole inside the unit circle",
            ));
        }
        Ok(Self { p })
    }

    /// The state at rest with constant input `u` (output at the static gain times `u`).
    /// `NU` must be D + NB − 1: the input history the difference equation reads.
    pub fn steady_state<const NU: usize>(&self, u: f32) -> Result<ArxState<NA, NU>, ParamError> {
        if NU != D + NB - 1 {
            return Err(ParamError::OutOfRange("arx state", "an input history of d + m samples"));
        }
        let y = (self.p.static_gain() * u as f64) as f32;
        Ok(ArxState { y: [y; NA], u: [u; NU] })
    }

    /// The coefficients.
    pub fn params(&self) -> &ArxParams<NA, NB, D> {
        &self.p
    }

    /// One sample: shifts `u` in and returns y[k] (state from [`Arx::steady_state`]).
    #[inline]
    pub fn step<const NU: usize>(&self, s: &mut ArxState<NA, NU>, u: f32) -> f32 {
        // Input history after the shift: hist[0] = u[k], hist[i] = u[k−i].
        let mut y = 0.0;
        for (i, a) in self.p.a.iter().enumerate() {
            y -= a * s.y[i];
        }
        for (j, b) in self.p.b.iter().enumerate() {
            let lag = D + j; // u[k − d − j]
            let uj = if lag == 0 { u } else { s.u.get(lag - 1).copied().unwrap_or(0.0) };
            y += b * uj;
        }
        if NU > 0 {
            s.u.copy_within(0..NU - 1, 1);
            s.u[0] = u;
        }
        if NA > 0 {
            s.y.copy_within(0..NA - 1, 1);
            s.y[0] = y;
        }
        y
    }
}

/// Schur–Cohn test: all roots of zⁿ + a_1 zⁿ⁻¹ + … + a_n strictly inside the unit circle.
fn schur_cohn_stable<const NA: usize>(a: &[f32; NA]) -> bool {
    // c[0..=n] = [1, a_1, …, a_n]; reduce the degree while the reflection coefficient |k| < 1.
    let mut c = [0.0f64; 17];
    if NA > 16 {
        return false; // beyond what any model here uses
    }
    c[0] = 1.0;
    for (i, v) in a.iter().enumerate() {
        c[i + 1] = *v as f64;
    }
    let mut n = NA;
    while n > 0 {
        let k = c[n] / c[0];
        if k.is_nan() || k.abs() >= 1.0 {
            return false;
        }
        let mut next = [0.0f64; 17];
        for i in 0..n {
            next[i] = c[i] - k * c[n - i];
        }
        c = next;
        n -= 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn davino_static_gain_is_close_to_one() {
        // 003: B(1)/A(1) = (1.015 − 0.7727)/(1 − 0.4877 − 0.2711) = 0.2423/0.2412.
        let g = ArxParams::DAVINO_003.static_gain();
        assert!((g - 1.00456).abs() < 1e-4, "static gain {g}");
        // The stepped model reaches the same gain.
        let arx = Arx::new(ArxParams::DAVINO_003).unwrap();
        let mut s: ArxState<2, 2> = arx.steady_state(0.0).unwrap();
        let mut y = 0.0;
        for _ in 0..400 {
            y = arx.step(&mut s, 13.0);
        }
        assert!((y as f64 / 13.0 - g).abs() < 1e-5, "stepped gain {}", y / 13.0);
    }

    #[test]
    fn delay_and_first_samples_follow_the_difference_equation() {
        let arx = Arx::new(ArxParams::DAVINO_003).unwrap();
        let mut s: ArxState<2, 2> = arx.steady_state(0.0).unwrap();
        // Unit impulse: y[0] = 0 (d = 1), y[1] = b0, y[2] = −a1 y[1] + b1.
        let y0 = arx.step(&mut s, 1.0);
        let y1 = arx.step(&mut s, 0.0);
        let y2 = arx.step(&mut s, 0.0);
        assert_eq!(y0, 0.0);
        assert!((y1 - 1.015).abs() < 1e-6);
        assert!((y2 - (0.4877 * 1.015 - 0.7727)).abs() < 1e-6);
    }

    #[test]
    fn unstable_denominators_are_rejected() {
        // Pole at z = 1.1.
        let p = ArxParams::<1, 1, 0> { a: [-1.1], b: [1.0] };
        assert!(matches!(Arx::new(p), Err(ParamError::OutOfRange("arx.a", _))));
        // Complex pair on |z| = 1.02.
        let r: f32 = 1.02;
        let p = ArxParams::<2, 1, 1> { a: [-2.0 * r * 0.5, r * r], b: [1.0] };
        assert!(Arx::new(p).is_err());
        let p = ArxParams::<2, 1, 1> { a: [-2.0 * 0.9 * 0.5, 0.81], b: [f32::NAN] };
        assert_eq!(Arx::new(p), Err(ParamError::NonFinite("arx.b")));
        let ok = Arx::new(ArxParams::<2, 1, 1> { a: [-0.9, 0.81], b: [1.0] }).unwrap();
        assert!(ok.steady_state::<3>(0.0).is_err(), "history length d + m = 1 is enforced");
    }
}
