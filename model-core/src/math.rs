//! The few transcendental functions the models use, in one place so that their accuracy on the
//! target can be measured and chosen per function (see the table in the crate README).
//!
//! `sqrt` uses the FPU instruction through `libm` (micromath's bit trick is off by percent);
//! `exp` and `ln` use libm's correctly-rounded-ish single-precision versions.

/// e^x.
#[inline]
pub fn exp(x: f32) -> f32 {
    libm::expf(x)
}

/// √x (x ≥ 0).
#[inline]
pub fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}

/// Natural logarithm.
#[inline]
pub fn ln(x: f32) -> f32 {
    libm::logf(x)
}

/// Sine and cosine.
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    (libm::sinf(x), libm::cosf(x))
}

/// Langevin function L(x) = coth x − 1/x, accurate over the whole f32 range: odd Taylor series
/// for |x| < 0.5 (where coth x − 1/x cancels), the exact exponential form in between, and
/// 1 − 1/|x| once e^{−2|x|} is below f32 resolution.
#[inline]
pub fn langevin(x: f32) -> f32 {
    let ax = x.abs();
    let l = if ax < 0.5 {
        let x2 = ax * ax;
        // x/3 − x³/45 + 2x⁵/945 − x⁷/4725 + 2x⁹/93555
        ax * (1.0 / 3.0
            + x2 * (-1.0 / 45.0 + x2 * (2.0 / 945.0 + x2 * (-1.0 / 4725.0 + x2 * (2.0 / 93555.0)))))
    } else if ax < 9.0 {
        let e = exp(-2.0 * ax);
        (1.0 + e) / (1.0 - e) - 1.0 / ax
    } else {
        1.0 - 1.0 / ax
    };
    l.copysign(x)
}

/// Derivative L'(x) = 1/x² − 1/sinh² x (even, 1/3 at 0, ~1/x² for large |x|), same three regimes.
#[inline]
pub fn langevin_slope(x: f32) -> f32 {
    let ax = x.abs();
    if ax < 0.5 {
        let x2 = ax * ax;
        // 1/3 − x²/15 + 2x⁴/189 − x⁶/675 + 2x⁸/10395
        1.0 / 3.0 + x2 * (-1.0 / 15.0 + x2 * (2.0 / 189.0 + x2 * (-1.0 / 675.0 + x2 * (2.0 / 10395.0))))
    } else if ax < 9.0 {
        let e = exp(-2.0 * ax);
        let d = 1.0 - e;
        1.0 / (ax * ax) - 4.0 * e / (d * d)
    } else {
        1.0 / (ax * ax)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn langevin_f64(x: f64) -> f64 {
        if x.abs() < 1e-4 {
            x / 3.0
        } else {
            1.0 / x.tanh() - 1.0 / x
        }
    }

    #[test]
    fn langevin_matches_f64_everywhere() {
        let mut x = -60.0_f64;
        while x <= 60.0 {
            let l = langevin(x as f32) as f64;
            let r = langevin_f64(x);
            assert!((l - r).abs() <= 2e-6 * r.abs().max(1e-3), "L({x}) = {l}, f64 {r}");
            // Slope against a central difference of the f64 function.
            let h = 1e-5 * x.abs().max(1.0);
            let dr = (langevin_f64(x + h) - langevin_f64(x - h)) / (2.0 * h);
            let d = langevin_slope(x as f32) as f64;
            assert!((d - dr).abs() <= 1e-4 * dr.abs() + 1e-7, "L'({x}) = {d}, f64 {dr}");
            x += 0.013;
        }
        assert_eq!(langevin(0.0), 0.0);
        assert!((langevin_slope(0.0) - 1.0 / 3.0).abs() < 1e-7);
        assert_eq!(langevin(f32::MAX), 1.0);
    }
}
