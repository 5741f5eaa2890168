//! Linearized magnetization M = a + bH (001 eq. 32) and its least-squares fit on fixed-size
//! accumulators (normal equations, 001 eq. 33).

use crate::error::{check, ParamError};

/// M = a + bH, valid in the unsaturated range it was fitted on.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct LinearMagnetization {
    /// Offset a [A/m].
    pub offset_a_per_m: f32,
    /// Slope b = dM/dH (relative susceptibility, dimensionless), in [1e-3, 1e5]: a material
    /// whose magnetization barely moves (below 1e-3: a paramagnet's scale; Terfenol-D's is about
    /// 7) strains nothing, and the inverse divides by it.
    pub susceptibility: f32,
}

impl LinearMagnetization {
    /// Validates: offset within ±1e7 A/m, susceptibility in [1e-3, 1e5] (M must rise with H for
    /// the inverse).
    pub fn new(offset_a_per_m: f32, susceptibility: f32) -> Result<Self, ParamError> {
        check("linear.offset_a_per_m", offset_a_per_m, |a| a.abs() <= 1e7, "within ±1e7 A/m")?;
        check("linear.susceptibility", susceptibility, |b| (1e-3..=1e5).contains(&b), "in [1e-3, 1e5]")?;
        Ok(Self { offset_a_per_m, susceptibility })
    }

    /// M(H).
    #[inline]
    pub fn magnetization(&self, h: f32) -> f32 {
        self.offset_a_per_m + self.susceptibility * h
    }

    /// H(M), the closed-form inverse.
    #[inline]
    pub fn field_for(&self, m: f32) -> f32 {
        (m - self.offset_a_per_m) / self.susceptibility
    }
}

/// Running sums for the least-squares line M = a + bH (001 eq. 33), in f64 so that long
/// recordings do not lose the small differences the normal equations rely on.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LinearFit {
    n: u32,
    sh: f64,
    sm: f64,
    shh: f64,
    shm: f64,
}

/// Why a least-squares line could not be formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitError {
    /// Fewer than two points.
    TooFewPoints,
    /// All H equal: the slope is undetermined.
    ConstantField,
    /// A point was NaN or infinite (its index).
    NonFinitePoint(u32),
}

impl core::fmt::Display for FitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FitError::TooFewPoints => write!(f, "a line needs at least two (H, M) points"),
            FitError::ConstantField => {
                write!(f, "all points have the same field H: the slope is undetermined")
            }
            FitError::NonFinitePoint(i) => write!(f, "point {i} is not a finite number"),
        }
    }
}

impl core::error::Error for FitError {}

impl LinearFit {
    /// Adds one (H, M) point.
    pub fn push(&mut self, h: f32, m: f32) -> Result<(), FitError> {
        if !(h.is_finite() && m.is_finite()) {
            return Err(FitError::NonFinitePoint(self.n));
        }
        let (h, m) = (h as f64, m as f64);
        self.n += 1;
        self.sh += h;
        self.sm += m;
        self.shh += h * h;
        self.shm += h * m;
        Ok(())
    }

    /// Solves the normal equations [n ΣH; ΣH ΣH²][a b]ᵀ = [ΣM ΣHM]ᵀ; returns (a, b) in f64.
    pub fn solve(&self) -> Result<(f64, f64), FitError> {
        if self.n < 2 {
            return Err(FitError::TooFewPoints);
        }
        let n = self.n as f64;
        let det = n * self.shh - self.sh * self.sh;
        if det <= 1e-12 * n * self.shh.max(f64::MIN_POSITIVE) {
            return Err(FitError::ConstantField);
        }
        let b = (n * self.shm - self.sh * self.sm) / det;
        let a = (self.sm - b * self.sh) / n;
        Ok((a, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 001 Table 6 (H_i, M_i), i = 1..20.
    const TABLE6: [(f32, f32); 20] = [
        (5.0, 15.0),
        (10.0, 48.0),
        (15.0, 113.0),
        (20.0, 166.0),
        (25.0, 179.0),
        (30.0, 203.0),
        (35.0, 246.0),
        (40.0, 279.0),
        (45.0, 308.0),
        (50.0, 344.0),
        (55.0, 386.0),
        (60.0, 422.0),
        (65.0, 459.0),
        (70.0, 486.0),
        (75.0, 539.0),
        (80.0, 602.0),
        (85.0, 618.0),
        (90.0, 624.0),
        (95.0, 659.0),
        (100.0, 705.0),
    ];

    /// 001 eq. 34 states a = −5.8, b = 7.07 "from Table 5/6". The normal equations over the
    /// table give something else; this test pins what the table actually gives.
    #[test]
    fn table6_least_squares_is_what_the_table_gives() {
        let mut first10 = LinearFit::default();
        let mut all20 = LinearFit::default();
        for (i, &(h, m)) in TABLE6.iter().enumerate() {
            if i < 10 {
                first10.push(h, m).unwrap();
            }
            all20.push(h, m).unwrap();
        }
        let (a10, b10) = first10.solve().unwrap();
        let (a20, b20) = all20.solve().unwrap();
        // Closed form from the table's own sums (ΣH = 275, ΣM = 1901, ΣH² = 9625, ΣHM = 66965 for
        // i = 1..10). The table prints ΣH² = 38500, which is not the sum of its column.
        let n = 10.0;
        let (sh, sm, shh, shm) = (275.0, 1901.0, 9625.0, 66965.0);
        let b = (n * shm - sh * sm) / (n * shh - sh * sh);
        let a = (sm - b * sh) / n;
        assert!((b10 - b).abs() < 1e-9 && (a10 - a).abs() < 1e-9);
        // What the table gives (the paper prints a = −5.8, b = 7.07 for eq. 34):
        assert!((a10 - (-5.7333)).abs() < 1e-3, "a over i=1..10 = {a10}");
        assert!((b10 - 7.1212).abs() < 1e-3, "b over i=1..10 = {b10}");
        assert!((a20 - (-6.3632)).abs() < 1e-3, "a over i=1..20 = {a20}");
        assert!((b20 - 7.1698).abs() < 1e-3, "b over i=1..20 = {b20}");
        assert!((b10 - 7.07).abs() > 0.04 && (a10 - (-5.8)).abs() > 0.05);
    }

    #[test]
    fn degenerate_data_is_refused() {
        let mut f = LinearFit::default();
        assert_eq!(f.solve(), Err(FitError::TooFewPoints));
        f.push(3.0, 1.0).unwrap();
        f.push(3.0, 2.0).unwrap();
        assert_eq!(f.solve(), Err(FitError::ConstantField));
        assert_eq!(f.push(f32::NAN, 0.0), Err(FitError::NonFinitePoint(2)));
        assert!(LinearMagnetization::new(0.0, 0.0).is_err());
        // A subnormal susceptibility (1e-45) made the inverse's field infinite.
        for bad in [1e-45, 5e-4] {
            let e = LinearMagnetization::new(0.0, bad).err().map(|e| e.name());
            assert_eq!(e, Some("linear.susceptibility"));
        }
        assert!(LinearMagnetization::new(1e7, 1e-3).unwrap().field_for(-1e7).is_finite());
    }

    #[test]
    fn inverse_is_exact() {
        let l = LinearMagnetization::new(-5.8, 7.07).unwrap();
        for h in [-100.0, 0.0, 12.5, 1e4] {
            assert!((l.field_for(l.magnetization(h)) - h).abs() <= 1e-5 * h.abs().max(1.0));
        }
    }
}
