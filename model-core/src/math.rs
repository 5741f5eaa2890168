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
