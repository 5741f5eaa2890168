//! n-degree-of-freedom mechanics: a chain of masses joined by spring–damper links (002 eq. 5,
//! the TSMA's three rods, two sleeves, output rod and disc spring), discretised exactly by
//! zero-order hold like the single-mass model.
//!
//! Mass 0 is tied to the frame by link 0; link i (1 ≤ i < N) joins masses i−1 and i; the last
//! mass is tied to the frame again by the end link (the disc spring). Each mass takes an
//! external force (the rods are force sources). With x = [q; v]:
//! ẋ = A x + B f, A = [[0, I], [−M⁻¹K, −M⁻¹C]], B = [0; M⁻¹], and per sample
//! x[n+1] = Φ x[n] + Γ f[n] with Φ = e^{AT}, Γ = ∫₀ᵀ e^{As} ds B, computed once in f64 by
//! scaling and squaring of a Taylor series (Φ(2τ) = Φ(τ)², Ψ(2τ) = (I + Φ(τ)) Ψ(τ)).

// Block-matrix index loops read clearer than iterator chains.
#![allow(clippy::needless_range_loop)]

use crate::error::{non_negative, positive, ParamError};

/// Physical parameters of an N-mass chain (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainParams<const N: usize> {
    /// Masses [kg], from the fixed base to the output.
    pub masses_kg: [f32; N],
    /// Stiffness of link i [N/m]: frame–mass 0 for i = 0, else mass i−1 – mass i.
    pub link_stiffness_n_per_m: [f32; N],
    /// Damping of link i [N s/m].
    pub link_damping_n_s_per_m: [f32; N],
    /// Stiffness from the last mass to the frame [N/m] (disc spring; 0 for a free end).
    pub end_stiffness_n_per_m: f32,
    /// Damping from the last mass to the frame [N s/m].
    pub end_damping_n_s_per_m: f32,
}

impl ChainParams<6> {
    /// 002 Table II (TSMA): rod 1, sleeve 1, rod 2, sleeve 2, rod 3, output rod; disc spring
    /// at the end. Masses m_1, m_t1, m_2, m_t2, m_3, m_s; links k_1, k_t1, k_2, k_t2, k_3, k_s
    /// (N/µm → N/m) with their dampings; end k_dh, c_dh.
    pub const TSMA_002: ChainParams<6> = ChainParams {
        masses_kg: [0.081, 0.019, 0.063, 0.011, 0.037, 0.022],
        link_stiffness_n_per_m: [290e6, 280e6, 220e6, 160e6, 130e6, 949e6],
        link_damping_n_s_per_m: [2900.0, 4600.0, 1510.0, 2700.0, 880.0, 9000.0],
        end_stiffness_n_per_m: 0.8e6,
        end_damping_n_s_per_m: 2500.0,
    };

    /// The force on each mass for rod forces F_1, F_2, F_3 (002 eq. 5): rod 1 pushes mass 0;
    /// rod 2 pushes rod-2 mass and reacts on sleeve 1; rod 3 likewise on sleeve 2.
    pub fn tsma_forces(rod_forces_n: [f32; 3]) -> [f32; 6] {
        let [f1, f2, f3] = rod_forces_n;
        [f1, -f2, f2, -f3, f3, 0.0]
    }
}

/// One N×N block of the 2N×2N state matrices, in f64 for the discretisation.
type Block<const N: usize> = [[f64; N]; N];

/// A 2N×2N matrix as four N×N blocks `b[row][col]`.
#[derive(Clone, Copy)]
struct Mat2<const N: usize> {
    b: [[Block<N>; 2]; 2],
}

impl<const N: usize> Mat2<N> {
    const ZERO: Self = Self { b: [[[[0.0; N]; N]; 2]; 2] };

    fn identity() -> Self {
        let mut m = Self::ZERO;
        for i in 0..N {
            m.b[0][0][i][i] = 1.0;
            m.b[1][1][i][i] = 1.0;
        }
        m
    }

    fn get(&self, i: usize, j: usize) -> f64 {
        self.b[i / N][j / N][i % N][j % N]
    }

    fn set(&mut self, i: usize, j: usize, v: f64) {
        self.b[i / N][j / N][i % N][j % N] = v;
    }

    fn mul(&self, o: &Self) -> Self {
        let mut r = Self::ZERO;
        for i in 0..2 * N {
            for j in 0..2 * N {
                let mut acc = 0.0;
                for k in 0..2 * N {
                    acc += self.get(i, k) * o.get(k, j);
                }
                r.set(i, j, acc);
            }
        }
        r
    }

    fn axpy(&self, s: f64, o: &Self) -> Self {
        let mut r = *self;
        for i in 0..2 * N {
            for j in 0..2 * N {
                r.set(i, j, self.get(i, j) + s * o.get(i, j));
            }
        }
        r
    }

    fn max_row_sum(&self) -> f64 {
        (0..2 * N).map(|i| (0..2 * N).map(|j| libm::fabs(self.get(i, j))).sum::<f64>()).fold(0.0, f64::max)
    }
}

/// Exact ZOH discretisation of an N-mass chain (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainZoh<const N: usize> {
    /// Φ blocks: [[q←q, q←v], [v←q, v←v]].
    phi: [[[[f32; N]; N]; 2]; 2],
    /// Γ blocks: [q←f, v←f].
    gamma: [[[f32; N]; N]; 2],
    params: ChainParams<N>,
}

/// Displacements [m] and velocities [m/s] of every mass (mutable, per sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainState<const N: usize> {
    /// Displacement of each mass [m].
    pub displacement_m: [f32; N],
    /// Velocity of each mass [m/s].
    pub velocity_m_per_s: [f32; N],
}

impl<const N: usize> Default for ChainState<N> {
    fn default() -> Self {
        Self { displacement_m: [0.0; N], velocity_m_per_s: [0.0; N] }
    }
}

impl<const N: usize> ChainZoh<N> {
    /// Validates the parameters and discretises at sample period `dt_s`.
    pub fn new(p: ChainParams<N>, dt_s: f32) -> Result<Self, ParamError> {
        if N == 0 {
            return Err(ParamError::OutOfRange("chain", "at least one mass"));
        }
        let t = positive("dt_s", dt_s)? as f64;
        for i in 0..N {
            positive("chain.masses_kg", p.masses_kg[i])?;
            non_negative("chain.link_stiffness_n_per_m", p.link_stiffness_n_per_m[i])?;
            non_negative("chain.link_damping_n_s_per_m", p.link_damping_n_s_per_m[i])?;
        }
        non_negative("chain.end_stiffness_n_per_m", p.end_stiffness_n_per_m)?;
        non_negative("chain.end_damping_n_s_per_m", p.end_damping_n_s_per_m)?;
        if p.link_stiffness_n_per_m[0] == 0.0 && p.end_stiffness_n_per_m == 0.0 {
            return Err(ParamError::OutOfRange(
                "chain.link_stiffness_n_per_m",
                "> 0 for link 0 or the end link (else the chain floats free)",
            ));
        }
        // K and C of the chain (tridiagonal), then A = [[0, I], [−M⁻¹K, −M⁻¹C]].
        let (mut k, mut c): (Block<N>, Block<N>) = ([[0.0; N]; N], [[0.0; N]; N]);
        let couple = |m: &mut Block<N>, i: usize, j: Option<usize>, v: f64| {
            m[i][i] += v;
            if let Some(j) = j {
                m[j][j] += v;
                m[i][j] -= v;
                m[j][i] -= v;
            }
        };
        for i in 0..N {
            let other = if i == 0 { None } else { Some(i - 1) };
            couple(&mut k, i, other, p.link_stiffness_n_per_m[i] as f64);
            couple(&mut c, i, other, p.link_damping_n_s_per_m[i] as f64);
        }
        couple(&mut k, N - 1, None, p.end_stiffness_n_per_m as f64);
        couple(&mut c, N - 1, None, p.end_damping_n_s_per_m as f64);
        let mut a = Mat2::<N>::ZERO;
        for i in 0..N {
            let inv_m = 1.0 / p.masses_kg[i] as f64;
            a.b[0][1][i][i] = 1.0;
            for j in 0..N {
                a.b[1][0][i][j] = -k[i][j] * inv_m;
                a.b[1][1][i][j] = -c[i][j] * inv_m;
            }
        }
        // Scale so that ‖A τ‖ ≤ 1/2, Taylor to order 14, then square back up.
        let norm = a.max_row_sum() * t;
        let mut squarings = 0u32;
        while norm / libm::pow(2.0, squarings as f64) > 0.5 && squarings < 60 {
            squarings += 1;
        }
        let tau = t / libm::pow(2.0, squarings as f64);
        let id = Mat2::<N>::identity();
        // Φ(τ) = Σ (Aτ)^k / k!,  Ψ(τ) = Σ A^k τ^{k+1} / (k+1)!
        let mut phi = id;
        let mut psi = Mat2::ZERO.axpy(tau, &id);
        let mut term = id; // (Aτ)^k / k!
        for kk in 1..=14 {
            term = term.mul(&a);
            term = Mat2::ZERO.axpy(tau / kk as f64, &term);
            phi = phi.axpy(1.0, &term);
            psi = psi.axpy(tau / (kk + 1) as f64, &term);
        }
        for _ in 0..squarings {
            psi = id.axpy(1.0, &phi).mul(&psi);
            phi = phi.mul(&phi);
        }
        // Γ = Ψ B, B = [0; M⁻¹]: column j of Γ is column N+j of Ψ divided by m_j.
        let mut out = Self { phi: [[[[0.0; N]; N]; 2]; 2], gamma: [[[0.0; N]; N]; 2], params: p };
        let mut finite = true;
        for r in 0..2 {
            for cc in 0..2 {
                for i in 0..N {
                    for j in 0..N {
                        let v = phi.b[r][cc][i][j];
                        finite &= v.is_finite();
                        out.phi[r][cc][i][j] = v as f32;
                    }
                }
            }
            for i in 0..N {
                for j in 0..N {
                    let v = psi.b[r][1][i][j] / p.masses_kg[j] as f64;
                    finite &= v.is_finite();
                    out.gamma[r][i][j] = v as f32;
                }
            }
        }
        if !finite {
            return Err(ParamError::OutOfRange("chain", "such that the discretisation is finite"));
        }
        Ok(out)
    }

    /// The physical parameters.
    pub fn params(&self) -> &ChainParams<N> {
        &self.params
    }

    /// One sample with the forces `f` [N] on each mass held over the period; returns the
    /// output (last mass) displacement [m].
    #[inline]
    pub fn step(&self, s: &mut ChainState<N>, f: &[f32; N]) -> f32 {
        let (q, v) = (s.displacement_m, s.velocity_m_per_s);
        for (r, out) in [&mut s.displacement_m, &mut s.velocity_m_per_s].into_iter().enumerate() {
            for i in 0..N {
                let mut acc = 0.0;
                for j in 0..N {
                    acc += self.phi[r][0][i][j] * q[j]
                        + self.phi[r][1][i][j] * v[j]
                        + self.gamma[r][i][j] * f[j];
                }
                out[i] = acc;
            }
        }
        s.displacement_m[N - 1]
    }

    /// Force the end link (disc spring) exerts on the frame [N].
    pub fn end_force_n(&self, s: &ChainState<N>) -> f32 {
        self.params.end_stiffness_n_per_m * s.displacement_m[N - 1]
            + self.params.end_damping_n_s_per_m * s.velocity_m_per_s[N - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};

    /// ẍ from the continuous equations of motion (002 eq. 5 in chain form), f64.
    fn accel<const N: usize>(p: &ChainParams<N>, q: &[f64; N], v: &[f64; N], f: &[f64; N]) -> [f64; N] {
        let mut a = [0.0; N];
        for i in 0..N {
            let mut force = f[i];
            // Link below mass i.
            let (qb, vb) = if i == 0 { (0.0, 0.0) } else { (q[i - 1], v[i - 1]) };
            force -= p.link_stiffness_n_per_m[i] as f64 * (q[i] - qb)
                + p.link_damping_n_s_per_m[i] as f64 * (v[i] - vb);
            // Link above mass i.
            if i + 1 < N {
                force += p.link_stiffness_n_per_m[i + 1] as f64 * (q[i + 1] - q[i])
                    + p.link_damping_n_s_per_m[i + 1] as f64 * (v[i + 1] - v[i]);
            } else {
                force -= p.end_stiffness_n_per_m as f64 * q[i] + p.end_damping_n_s_per_m as f64 * v[i];
            }
            a[i] = force / p.masses_kg[i] as f64;
        }
        a
    }

    /// Fine-step RK4 over one sample period with constant forces.
    fn rk4_sample<const N: usize>(
        p: &ChainParams<N>,
        q: &mut [f64; N],
        v: &mut [f64; N],
        f: &[f64; N],
        t: f64,
        n: usize,
    ) {
        let h = t / n as f64;
        for _ in 0..n {
            let add =
                |x: &[f64; N], d: &[f64; N], s: f64| core::array::from_fn::<f64, N, _>(|i| x[i] + s * d[i]);
            let k1v = accel(p, q, v, f);
            let k1q = *v;
            let k2v = accel(p, &add(q, &k1q, h / 2.0), &add(v, &k1v, h / 2.0), f);
            let k2q = add(v, &k1v, h / 2.0);
            let k3v = accel(p, &add(q, &k2q, h / 2.0), &add(v, &k2v, h / 2.0), f);
            let k3q = add(v, &k2v, h / 2.0);
            let k4v = accel(p, &add(q, &k3q, h), &add(v, &k3v, h), f);
            let k4q = add(v, &k3v, h);
            for i in 0..N {
                q[i] += h / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + k4q[i]);
                v[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
            }
        }
    }

    #[test]
    fn tsma_chain_matches_fine_rk4() {
        let p = ChainParams::TSMA_002;
        let dt = 1e-4;
        let zoh = ChainZoh::new(p, dt as f32).unwrap();
        let mut s = ChainState::default();
        let (mut q, mut v) = ([0.0f64; 6], [0.0f64; 6]);
        let mut worst = 0.0f64;
        let mut peak = 0.0f64;
        for n in 0..150 {
            // Rod forces: a step, then a 700 Hz sine on rod 2.
            let t = n as f64 * dt;
            let rods = [100.0, 60.0 * libm::sin(2.0 * core::f64::consts::PI * 700.0 * t), 80.0];
            let f = ChainParams::tsma_forces(rods.map(|x| x as f32));
            let y = zoh.step(&mut s, &f) as f64;
            rk4_sample(&p, &mut q, &mut v, &f.map(|x| x as f64), dt, 2000);
            worst = worst.max((y - q[5]).abs());
            peak = peak.max(q[5].abs());
        }
        assert!(worst <= 1e-4 * peak, "ZOH vs RK4: {worst:e} m against peak {peak:e} m");
    }

    #[test]
    fn one_mass_chain_equals_the_single_dof_zoh() {
        let msd = MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 300.0, stiffness_n_per_m: 9.9e6 };
        let chain = ChainParams {
            masses_kg: [0.1],
            link_stiffness_n_per_m: [9.9e6],
            link_damping_n_s_per_m: [300.0],
            end_stiffness_n_per_m: 0.0,
            end_damping_n_s_per_m: 0.0,
        };
        let single = SecondOrderZoh::new(msd, 1e-4).unwrap();
        let multi = ChainZoh::new(chain, 1e-4).unwrap();
        let (mut a, mut b) = (MechState::default(), ChainState::default());
        for n in 0..200 {
            let f = if n < 100 { 50.0 } else { -20.0 };
            let ya = single.step(&mut a, f);
            let yb = multi.step(&mut b, &[f]);
            assert!((ya - yb).abs() <= 1e-4 * ya.abs() + 1e-12, "sample {n}: {ya} vs {yb}");
        }
    }

    #[test]
    fn settles_to_the_static_deflection() {
        // Equal rod forces: the static solution of K q = f, checked through the link forces.
        let p = ChainParams::TSMA_002;
        let zoh = ChainZoh::new(p, 1e-4).unwrap();
        let f = ChainParams::tsma_forces([100.0, 100.0, 100.0]);
        let mut s = ChainState::default();
        for _ in 0..20_000 {
            zoh.step(&mut s, &f);
        }
        let a = accel(&p, &s.displacement_m.map(|x| x as f64), &[0.0; 6], &f.map(|x| x as f64));
        for (i, ai) in a.iter().enumerate() {
            assert!((ai * p.masses_kg[i] as f64).abs() < 1e-3, "mass {i}: residual force {ai}");
        }
        // The disc spring carries the whole stack's output: F_dh = k_dh y_s > 0.
        assert!(zoh.end_force_n(&s) > 0.0);
    }

    #[test]
    fn a_floating_chain_is_rejected() {
        let mut p = ChainParams::TSMA_002;
        p.link_stiffness_n_per_m[0] = 0.0;
        p.end_stiffness_n_per_m = 0.0;
        assert!(matches!(
            ChainZoh::new(p, 1e-4),
            Err(ParamError::OutOfRange("chain.link_stiffness_n_per_m", _))
        ));
        p.masses_kg[2] = f32::NAN;
        assert_eq!(ChainZoh::new(p, 1e-4), Err(ParamError::NonFinite("chain.masses_kg")));
    }
}
