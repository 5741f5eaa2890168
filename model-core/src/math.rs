//! The few transcendental functions the per-sample code uses, in one place so that their
//! accuracy and cost on the target are measured and chosen per function (table in the crate
//! README; `cargo test -p model-core --features math-audit --test f32_accuracy -- --nocapture`).
//!
//! - `exp`: our own single precision, a 32-entry table of 2^(j/32) and a cubic (≤ 1.5e-7
//!   relative), written for a short dependency chain. libm's `expf` works in f64 internally,
//!   which the Cortex-M4F's single-precision FPU emulates in software — it was most of a J–A
//!   sub-step's instructions; micromath's is coarse.
//! - `sqrt`: libm (micromath's bit trick is off by percent).
//! - `sin_cos`: libm (micromath's distorts reference waveforms).
//!
//! With the `math-audit` feature (host only) each function can be switched to an alternative
//! at run time, which is how the table is measured.

/// 2^(j/32), j = 0..31, rounded to f32: e^x = 2^k · 2^(j/32) · e^r. (Entry 16 is √2, written out
/// like its neighbours.)
#[allow(clippy::approx_constant)]
const EXP2_FRACTIONS: [f32; 32] = [
    1.0, 1.0218972, 1.0442737, 1.0671405, 1.0905077, 1.1143868, 1.1387886, 1.1637249, 1.1892071, 1.2152474,
    1.2418578, 1.269051, 1.2968396, 1.3252367, 1.3542556, 1.38391, 1.4142135, 1.4451808, 1.4768262,
    1.5091645, 1.5422108, 1.5759809, 1.6104903, 1.6457555, 1.6817929, 1.7186193, 1.7562522, 1.7947091,
    1.8340081, 1.8741677, 1.9152066, 1.9571441,
];
/// 32/ln 2.
const INV_LN2_32: f32 = 46.16624;
/// ln2/32 split for an exact n·ln2/32 (Cody–Waite): the high part has 12 significant bits, so
/// n·LN2_32_HI is exact for every |n| < 4096 (the whole f32 range of exp).
const LN2_32_HI: f32 = 0.021_659_851;
const LN2_32_LO: f32 = 9.983182e-7;
/// 1.5·2²³: adding it rounds an f32 of magnitude < 2²² to an integer, held in the low mantissa bits.
const ROUNDING_SHIFTER: f32 = 12_582_912.0;

/// e^x in f32: x = n ln2/32 + r with |r| ≤ ln2/64 and n = 32k + j, so e^x = 2^k · 2^(j/32) · e^r
/// with 2^(j/32) from a 32-entry table, e^r by its cubic Taylor polynomial (truncation below
/// 1e-9) and 2^k through the exponent bits (≤ 1.5e-7 relative). 0 below −87.3, +∞ above 88.7.
#[inline]
pub fn exp(x: f32) -> f32 {
    if x < -87.3 {
        return 0.0;
    }
    // (A NaN passes both tests and comes out as NaN from the polynomial.)
    if x > 88.7 {
        return f32::INFINITY;
    }
    exp_reduced(x, x * INV_LN2_32)
}

/// e^{−2a} for a in the Langevin function's mid range [0.5, 9]. The same as
/// `exp(-2.0 * a)` bit for bit (scaling by −2 is exact), one multiplication shorter.
#[inline]
fn exp_minus_twice(a: f32) -> f32 {
    exp_reduced(-2.0 * a, a * (-2.0 * INV_LN2_32))
}

/// e^x given x·32/ln 2. Written for latency (the J–A sub-step waits on it): n is rounded by the
/// shifter instead of float→int→float conversions, and the table value is scaled by 2^k while
/// the short polynomial is evaluated.
#[inline]
fn exp_reduced(x: f32, x_times_inv_ln2_32: f32) -> f32 {
    #[cfg(feature = "math-audit")]
    if let Some(y) = audit::exp(x) {
        return y;
    }
    let shifted = x_times_inv_ln2_32 + ROUNDING_SHIFTER;
    let n = (shifted.to_bits() as i32).wrapping_sub(ROUNDING_SHIFTER.to_bits() as i32);
    let nf = shifted - ROUNDING_SHIFTER;
    let r = x - nf * LN2_32_HI - nf * LN2_32_LO;
    // 2^k · 2^(j/32): exact (a power-of-two scaling of a table value).
    let base = EXP2_FRACTIONS[(n & 31) as usize] * f32::from_bits(((n >> 5).wrapping_add(127) as u32) << 23);
    // e^r − 1 = r + r²(1/2 + r/6); adding it to the base last keeps its low bits.
    let em1 = r + r * r * (0.5 + r * (1.0 / 6.0));
    base + base * em1
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

/// tanh x = (1 − e^{−2|x|})/(1 + e^{−2|x|}) with the sign of x (absolute error ≲ 2e-7; ±1 for
/// infinite x, NaN for NaN).
#[inline]
pub fn tanh(x: f32) -> f32 {
    let e = exp(-2.0 * x.abs());
    ((1.0 - e) / (1.0 + e)).copysign(x)
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
        let e = exp_minus_twice(ax);
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
        let e = exp_minus_twice(ax);
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
            let e = exp_minus_twice(ax);
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
        let mut x = -87.3f32;
        let mut worst = 0.0f64;
        while x < 88.7 {
            let r = (x as f64).exp();
            worst = worst.max(((exp(x) as f64 - r) / r).abs());
            x += 0.00137;
        }
        // Every argument in the Langevin mid range, where the J–A sub-step uses it.
        let mut bits = (-18.0f32).to_bits();
        while bits >= (-1.0f32).to_bits() {
            let x = f32::from_bits(bits);
            let r = (x as f64).exp();
            worst = worst.max(((exp(x) as f64 - r) / r).abs());
            bits -= 7;
        }
        assert!(worst < 1.5e-7, "max relative error {worst:e}");
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-200.0), 0.0);
        assert_eq!(exp(100.0), f32::INFINITY);
        assert!(exp(88.7).is_finite() && exp(-87.3) > 0.0);
        assert!(exp(f32::NAN).is_nan());
    }

    #[test]
    fn exp_minus_twice_is_exp_of_minus_twice_bit_for_bit() {
        let mut a = 0.5f32;
        while a < 9.0 {
            assert_eq!(exp_minus_twice(a).to_bits(), exp(-2.0 * a).to_bits(), "a = {a}");
            a = f32::from_bits(a.to_bits() + 97);
        }
    }

    #[test]
    fn exp_table_holds_the_correctly_rounded_powers_of_two() {
        for (j, &t) in EXP2_FRACTIONS.iter().enumerate() {
            assert_eq!(t, 2.0f64.powf(j as f64 / 32.0) as f32, "2^({j}/32)");
        }
        assert_eq!((LN2_32_HI.to_bits() & 0xfff), 0, "n·LN2_32_HI must be exact for |n| < 4096");
        assert!(((LN2_32_HI as f64 + LN2_32_LO as f64) - core::f64::consts::LN_2 / 32.0).abs() < 1e-13);
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

    #[test]
    fn tanh_matches_f64() {
        let mut x = -30.0_f64;
        while x <= 30.0 {
            let t = tanh(x as f32) as f64;
            assert!((t - x.tanh()).abs() <= 2e-7, "tanh({x}) = {t}, f64 {}", x.tanh());
            x += 0.0071;
        }
        assert_eq!(tanh(0.0), 0.0);
        assert_eq!(tanh(f32::INFINITY), 1.0);
        assert_eq!(tanh(f32::NEG_INFINITY), -1.0);
        assert!(tanh(f32::NAN).is_nan());
    }
}
