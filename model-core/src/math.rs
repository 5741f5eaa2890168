//! The few transcendental functions the per-sample code uses, in one place so that their
//! accuracy and cost on the target are measured and chosen per function (table in the crate
//! README; `cargo test -p model-core --features math-audit --test f32_accuracy -- --nocapture`).
//!
//! - `exp`: our own single-precision range reduction and polynomial (≤ 2e-7 relative). libm's
//!   `expf` works in f64 internally, which the Cortex-M4F's single-precision FPU emulates in
//!   software — it was most of a J–A sub-step's instructions; micromath's is coarse.
//! - `sqrt`: libm (micromath's bit trick is off by percent).
//! - `sin_cos`: libm (micromath's distorts reference waveforms).
//!
//! With the `math-audit` feature (host only) each function can be switched to an alternative
//! at run time, which is how the table is measured.

/// ln 2 split for an exact k·ln 2 (Cody–Waite): the high part has trailing zero bits.
const LN2_HI: f32 = 0.693_145_75;
const LN2_LO: f32 = 1.428_606_8e-6;

/// e^x in f32: x = k ln 2 + r with |r| ≤ ln2/2, e^r by its degree-7 Taylor polynomial,
/// scaled by 2^k through the exponent bits. 0 below −87.3, +∞ above 88.7.
#[inline]
pub fn exp(x: f32) -> f32 {
    if x < -87.3 {
        return 0.0;
    }
    // (A NaN passes both tests and comes out as NaN from the polynomial.)
    if x > 88.7 {
        return f32::INFINITY;
    }
    exp_in_range(x)
}

/// [`exp`] without the range checks, for callers whose argument is known to lie in
/// [−87.3, 88.7] (the Langevin function's mid range: [−18, −1]).
#[inline]
fn exp_in_range(x: f32) -> f32 {
    #[cfg(feature = "math-audit")]
    if let Some(y) = audit::exp(x) {
        return y;
    }
    let k = (x * core::f32::consts::LOG2_E + 0.5f32.copysign(x)) as i32;
    let kf = k as f32;
    let r = x - kf * LN2_HI - kf * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    p * f32::from_bits(((k + 127) as u32) << 23)
}

/// √x (x ≥ 0; inverse magnetostriction).
#[inline]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(feature = "math-audit")]
    if audit::uses(audit::SQRT, audit::MICROMATH) {
        return micromath::F32Ext::sqrt(x);
    }
    libm::sqrtf(x)
}

/// Sine and cosine (reference waveforms on the board).
#[inline]
pub fn sin_cos(x: f32) -> (f32, f32) {
    #[cfg(feature = "math-audit")]
    if audit::uses(audit::SIN_COS, audit::MICROMATH) {
        return (micromath::F32Ext::sin(x), micromath::F32Ext::cos(x));
    }
    (libm::sinf(x), libm::cosf(x))
}

/// Run-time choice of the implementation behind each function, for the accuracy audit only.
#[cfg(feature = "math-audit")]
pub mod audit {
    use core::sync::atomic::{AtomicU8, Ordering};

    /// [`super::exp`].
    pub const EXP: u8 = 1;
    /// [`super::sqrt`].
    pub const SQRT: u8 = 2;
    /// [`super::sin_cos`].
    pub const SIN_COS: u8 = 4;
    /// Alternative: libm.
    pub const LIBM: usize = 0;
    /// Alternative: micromath.
    pub const MICROMATH: usize = 1;

    static MASKS: [AtomicU8; 2] = [AtomicU8::new(0), AtomicU8::new(0)];

    /// Routes the functions in `mask` to alternative `alt` ([`LIBM`] or [`MICROMATH`]); the
    /// others go back to the crate's choice (process-wide).
    pub fn route(mask: u8, alt: usize) {
        for (i, m) in MASKS.iter().enumerate() {
            m.store(if i == alt { mask } else { 0 }, Ordering::Relaxed);
        }
    }

    /// Back to the crate's choice for every function.
    pub fn reset() {
        route(0, LIBM);
    }

    pub(crate) fn uses(f: u8, alt: usize) -> bool {
        MASKS[alt].load(Ordering::Relaxed) & f != 0
    }

    pub(crate) fn exp(x: f32) -> Option<f32> {
        if uses(EXP, LIBM) {
            Some(libm::expf(x))
        } else if uses(EXP, MICROMATH) {
            Some(micromath::F32Ext::exp(x))
        } else {
            None
        }
    }
}

/// max(v, floor) by compare-and-select. `f32::max` is a library call (`fmaxf`) on the
/// Cortex-M4F, whose FPU has no VMAXNM; a NaN `v` gives `floor`.
#[inline]
pub fn at_least(v: f32, floor: f32) -> f32 {
    if v > floor {
        v
    } else {
        floor
    }
}

/// v limited to ±`limit` (limit ≥ 0) by compare-and-select (see [`at_least`]).
#[inline]
pub fn within(v: f32, limit: f32) -> f32 {
    if v > limit {
        limit
    } else if v < -limit {
        -limit
    } else {
        v
    }
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
        let e = exp_in_range(-2.0 * ax);
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
        let e = exp_in_range(-2.0 * ax);
        let d = 1.0 - e;
        1.0 / (ax * ax) - 4.0 * e / (d * d)
    } else {
        1.0 / (ax * ax)
    }
}

/// L(x) and L'(x) together, sharing one exponential and one reciprocal (the J–A sub-step
/// needs both; this halves its cost on the Cortex-M4F). Same regimes as the two functions.
#[inline]
pub fn langevin_with_slope(x: f32) -> (f32, f32) {
    let ax = x.abs();
    let (l, dl) = if ax < 0.5 {
        let x2 = ax * ax;
        (
            ax * (1.0 / 3.0
                + x2 * (-1.0 / 45.0 + x2 * (2.0 / 945.0 + x2 * (-1.0 / 4725.0 + x2 * (2.0 / 93555.0))))),
            1.0 / 3.0 + x2 * (-1.0 / 15.0 + x2 * (2.0 / 189.0 + x2 * (-1.0 / 675.0 + x2 * (2.0 / 10395.0)))),
        )
    } else {
        if ax < 9.0 {
            let e = exp_in_range(-2.0 * ax);
            // One division for both reciprocals 1/x and 1/(1 − e).
            let d = 1.0 - e;
            let r = 1.0 / (ax * d);
            let (inv, inv_d) = (d * r, ax * r);
            ((1.0 + e) * inv_d - inv, inv * inv - 4.0 * e * inv_d * inv_d)
        } else {
            let inv = 1.0 / ax;
            (1.0 - inv, inv * inv)
        }
    };
    (l.copysign(x), dl)
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
    fn exp_is_accurate_over_the_f32_range() {
        let mut x = -87.0f32;
        let mut worst = 0.0f64;
        while x < 88.0 {
            let r = (x as f64).exp();
            worst = worst.max(((exp(x) as f64 - r) / r).abs());
            x += 0.0137;
        }
        assert!(worst < 2.5e-7, "max relative error {worst:e}");
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-200.0), 0.0);
        assert!(exp(f32::NAN).is_nan());
    }

    #[test]
    fn joint_evaluation_matches_f64() {
        let mut x = -40.0f64;
        while x <= 40.0 {
            let (l, dl) = langevin_with_slope(x as f32);
            let r = langevin_f64(x);
            let dr = if x.abs() < 1e-4 { 1.0 / 3.0 } else { 1.0 / (x * x) - 1.0 / (x.sinh() * x.sinh()) };
            assert!((l as f64 - r).abs() <= 2e-6 * r.abs().max(1e-3), "L({x}) = {l}, f64 {r}");
            assert!((dl as f64 - dr).abs() <= 1e-5 * dr, "L'({x}) = {dl}, f64 {dr}");
            x += 0.0173;
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
