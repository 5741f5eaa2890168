//! Linearized magnetization M = a + bH (001 eq. 32). The paper's least-squares line (eq. 33)
//! through its Table 6 is reproduced by a test below; the workbench identifies a and b with the
//! rest of a model.

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

    /// The least-squares line through `points` by the normal equations [n ΣH; ΣH ΣH²][a b]ᵀ =
    /// [ΣM ΣHM]ᵀ (001 eq. 33), in f64.
    fn least_squares(points: &[(f32, f32)]) -> (f64, f64) {
        let n = points.len() as f64;
        let sum =
            |f: &dyn Fn(f64, f64) -> f64| points.iter().map(|&(h, m)| f(h as f64, m as f64)).sum::<f64>();
        let (sh, sm, shh, shm) = (sum(&|h, _| h), sum(&|_, m| m), sum(&|h, _| h * h), sum(&|h, m| h * m));
        let b = (n * shm - sh * sm) / (n * shh - sh * sh);
        ((sm - b * sh) / n, b)
    }

    /// 001 eq. 34 states a = −5.8, b = 7.07 "from Table 5/6". The normal equations over the
    /// table give something else; this test pins what the table actually gives.
    #[test]
    fn table6_least_squares_is_what_the_table_gives() {
        let (a10, b10) = least_squares(&TABLE6[..10]);
        let (a20, b20) = least_squares(&TABLE6);
        // The table's own sums for i = 1..10: ΣH = 275, ΣM = 1901, ΣH² = 9625, ΣHM = 66965. The
        // table prints ΣH² = 38500, which is not the sum of its column.
        let h: f64 = TABLE6[..10].iter().map(|p| p.0 as f64 * p.0 as f64).sum();
        assert_eq!(h, 9625.0);
        // What the table gives (the paper prints a = −5.8, b = 7.07 for eq. 34):
        assert!((a10 - (-5.7333)).abs() < 1e-3, "a over i=1..10 = {a10}");
        assert!((b10 - 7.1212).abs() < 1e-3, "b over i=1..10 = {b10}");
        assert!((a20 - (-6.3632)).abs() < 1e-3, "a over i=1..20 = {a20}");
        assert!((b20 - 7.1698).abs() < 1e-3, "b over i=1..20 = {b20}");
        assert!((b10 - 7.07).abs() > 0.04 && (a10 - (-5.8)).abs() > 0.05);
    }

    /// M must rise with H for the inverse: a zero or subnormal susceptibility (1e-45 made the
    /// inverse's field infinite) is refused by name; at the floor the inverse is finite.
    #[test]
    fn a_flat_susceptibility_is_refused_by_name() {
        assert!(LinearMagnetization::new(0.0, 0.0).is_err());
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
