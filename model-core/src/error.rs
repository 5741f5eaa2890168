//! Typed, `Copy` errors that name what is wrong.

use core::fmt;

/// A parameter set was rejected when a model was built. The `&'static str` names the parameter
/// as written in parameter files (e.g. `"ja.k"`), so the message points at the line to fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamError {
    /// NaN or infinite.
    NonFinite(&'static str),
    /// Finite but outside the physically meaningful range; the second field says the range.
    OutOfRange(&'static str, &'static str),
}

impl ParamError {
    /// The parameter (as in parameter files, e.g. `mech.damping_ratio`) or table (`mech`) at fault.
    pub fn name(&self) -> &'static str {
        match self {
            ParamError::NonFinite(name) | ParamError::OutOfRange(name, _) => name,
        }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamError::NonFinite(name) => write!(f, "parameter `{name}` is not a finite number"),
            ParamError::OutOfRange(name, range) => {
                write!(f, "parameter `{name}` is out of range: must be {range}")
            }
        }
    }
}

impl core::error::Error for ParamError {}

/// Checks that `value` is finite and satisfies `ok`; `range` describes `ok` for the message.
pub(crate) fn check(
    name: &'static str,
    value: f32,
    ok: impl Fn(f32) -> bool,
    range: &'static str,
) -> Result<f32, ParamError> {
    if !value.is_finite() {
        Err(ParamError::NonFinite(name))
    } else if !ok(value) {
        Err(ParamError::OutOfRange(name, range))
    } else {
        Ok(value)
    }
}

/// `value > 0` and finite.
pub(crate) fn positive(name: &'static str, value: f32) -> Result<f32, ParamError> {
    check(name, value, |v| v > 0.0, "> 0")
}

/// Largest saturation magnetization accepted [A/m] (iron: 1.7e6; Terfenol-D: about 7.6e5).
pub const MS_MAX: f32 = 1.0e7;
/// Smallest saturation magnetization accepted [A/m]: M/M_s must stay representable.
pub const MS_MIN: f32 = 1.0e3;

/// A saturation magnetization within [[`MS_MIN`], [`MS_MAX`]].
pub(crate) fn saturation(name: &'static str, value: f32) -> Result<f32, ParamError> {
    check(name, value, |v| (MS_MIN..=MS_MAX).contains(&v), "in [1e3, 1e7] A/m")
}

/// A characteristic field (J–A a and k, Langevin a, Preisach widths) within [1, 1e7] A/m:
/// its inverse scales every slope, so it must not be subnormal or astronomically large.
pub(crate) fn field_scale(name: &'static str, value: f32) -> Result<f32, ParamError> {
    check(name, value, |v| (1.0..=1.0e7).contains(&v), "in [1, 1e7] A/m")
}

/// `value >= 0` and finite.
pub(crate) fn non_negative(name: &'static str, value: f32) -> Result<f32, ParamError> {
    check(name, value, |v| v >= 0.0, ">= 0")
}
