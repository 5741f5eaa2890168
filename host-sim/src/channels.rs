//! Facts of the measured channels that more than one layer reads: the flux-density channel's
//! B = μ0 (H + g M) + c (a search coil on the rod, read through an integrator).

/// Vacuum permeability μ0 [T m/A] of the flux-density channel (CODATA 2018; model-core's
/// `field::MU0` is 4π × 10⁻⁷, 5.5 × 10⁻¹⁰ relative apart).
pub const MU0: f64 = 1.256_637_062_12e-6;

/// Widest ratio of a search coil's magnetization scale to the parameter set's M_s: beyond 10×
/// either way the column is in the wrong unit or is not the rod's flux, not a calibration.
pub const FLUX_SCALE_RANGE: (f64, f64) = (0.1, 10.0);
