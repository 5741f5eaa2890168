//! Mechanics between rod strain and output displacement: `m ÿ + c ẏ + k y = F`, with the drive
//! force `F = g_F λ` (`g_F = A_r E^H`, the rod's blocked force per unit strain; 001 eq. 8–10).
//!
//! Discretised exactly for a piecewise-constant input (zero-order hold, 001 eq. 16–23):
//! `x[n+1] = Φ x[n] + Γ F[n]` with `Φ = e^{AT}`, `Γ = ∫₀ᵀ e^{As} ds B`. Φ and Γ are computed once,
//! in f64, in a closed form valid for every damping regime (under-, critically and over-damped);
//! the per-sample step is four multiply-adds in f32. The state is x = [y, ẏ/ω_n]: with the
//! velocity over the natural angular frequency every entry of Φ is of order one and the state no
//! larger than the displacement's swing (ẏ in m/s is ω_n times it: a stiff, fast mode driven
//! hard overflowed f32 at the first sample while its displacement was finite).

use crate::error::{positive, ParamError};

mod ndof;
pub use ndof::{ChainParams, ChainState, ChainZoh};

/// Physical parameters of the single-degree-of-freedom actuator mechanics (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct MassSpringDamper {
    /// Moving mass m [kg] (rod share ρ A l / 3 plus load masses).
    pub mass_kg: f32,
    /// Viscous damping c [N s/m].
    pub damping_n_s_per_m: f32,
    /// Stiffness k [N/m] (rod A E / l plus springs and load).
    pub stiffness_n_per_m: f32,
}

impl MassSpringDamper {
    /// Undamped natural frequency f_n = √(k/m) / 2π [Hz] (001 eq. 14).
    pub fn natural_frequency_hz(&self) -> f64 {
        libm::sqrt(self.stiffness_n_per_m as f64 / self.mass_kg as f64) / (2.0 * core::f64::consts::PI)
    }

    /// Damping ratio ζ = c / (2 √(k m)) (001 eq. 15).
    pub fn damping_ratio(&self) -> f64 {
        self.damping_n_s_per_m as f64
            / (2.0 * libm::sqrt(self.stiffness_n_per_m as f64 * self.mass_kg as f64))
    }
}

/// Exact ZOH discretisation of a mass-spring-damper at a fixed sample period (immutable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecondOrderZoh {
    /// Φ and Γ for the state [y, ẏ/ω_n].
    phi: [[f32; 2]; 2],
    gamma: [f32; 2],
    /// ω_n [rad/s].
    omega_n: f32,
    physical: MassSpringDamper,
}

/// Displacement and velocity of a [`SecondOrderZoh`] (mutable, stepped per sample).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MechState {
    /// Displacement y [m].
    pub displacement_m: f32,
    /// Velocity over the natural angular frequency, ẏ/ω_n [m/rad]: in these units as large as
    /// the displacement's swing ([`SecondOrderZoh::velocity_m_per_s`] gives ẏ).
    pub velocity_m_per_rad: f32,
}

impl SecondOrderZoh {
    /// Validates the parameters and discretises at sample period `dt_s`.
    pub fn new(p: MassSpringDamper, dt_s: f32) -> Result<Self, ParamError> {
        let m = positive("mech.mass_kg", p.mass_kg)? as f64;
        let c = crate::error::non_negative("mech.damping_n_s_per_m", p.damping_n_s_per_m)? as f64;
        let k = positive("mech.stiffness_n_per_m", p.stiffness_n_per_m)? as f64;
        let t = positive("dt_s", dt_s)? as f64;
        let (phi, gamma) = zoh_second_order(m, c, k, t);
        // To the state [y, ẏ/ω_n]: Φ' = D Φ D⁻¹, Γ' = D Γ with D = diag(1, 1/ω_n).
        let w = libm::sqrt(k / m);
        let phi = [[phi[0][0], phi[0][1] * w], [phi[1][0] / w, phi[1][1]]];
        let gamma = [gamma[0], gamma[1] / w];
        let all_finite = phi.iter().flatten().chain(gamma.iter()).all(|v| v.is_finite());
        if !all_finite {
            // Only reachable for absurd combinations (e.g. ω_n T ~ 1e300); say which knob.
            return Err(ParamError::OutOfRange("mech", "such that ω_n·dt and ζ·ω_n·dt are moderate"));
        }
        Ok(Self {
            phi: phi.map(|row| row.map(|v| v as f32)),
            gamma: gamma.map(|v| v as f32),
            omega_n: w as f32,
            physical: p,
        })
    }

    /// Whether a free oscillation decays as the step runs in f32: the spectral radius of Φ as
    /// rounded to f32 below 1. A mode very slow against the sample rate decays by ζ ω_n T per
    /// sample, and below about 1e-7 the rounding of Φ's entries can outweigh that.
    pub fn decays(&self) -> bool {
        let [[a, b], [c, d]] = self.phi.map(|row| row.map(f64::from));
        let (trace, det) = (a + d, a * d - b * c);
        let disc = trace * trace - 4.0 * det;
        // Complex pair: |λ|² = det; real pair: the larger |λ|.
        if disc < 0.0 {
            det < 1.0
        } else {
            0.5 * (libm::fabs(trace) + libm::sqrt(disc)) < 1.0
        }
    }

    /// ẏ [m/s] of a state.
    pub fn velocity_m_per_s(&self, s: &MechState) -> f32 {
        self.omega_n * s.velocity_m_per_rad
    }

    /// The physical parameters this discretisation was built from.
    pub fn physical(&self) -> &MassSpringDamper {
        &self.physical
    }

    /// One sample with force `force_n` held over the period; returns the new displacement [m].
    #[inline]
    pub fn step(&self, s: &mut MechState, force_n: f32) -> f32 {
        let (y, v) = (s.displacement_m, s.velocity_m_per_rad);
        s.displacement_m = self.phi[0][0] * y + self.phi[0][1] * v + self.gamma[0] * force_n;
        s.velocity_m_per_rad = self.phi[1][0] * y + self.phi[1][1] * v + self.gamma[1] * force_n;
        s.displacement_m
    }

    /// The ramp term R = (1/T) ∫₀ᵀ Γ(τ) dτ at sample period `dt_s` (Γ(τ) the zero-order hold's
    /// input vector for a period τ): with it a step is exact for a force that runs linearly
    /// across the sample, x[n+1] = Φ x[n] + Γ F[n] + R (F[n+1] − F[n]) ([`SecondOrderZoh::step_ramp`]).
    /// Formed once in f64 by 8-point Gauss–Legendre on panels of at most a tenth of a period of
    /// the mode.
    pub fn ramp_term(&self, dt_s: f32) -> [f32; 2] {
        let p = &self.physical;
        let (m, c, k) = (p.mass_kg as f64, p.damping_n_s_per_m as f64, p.stiffness_n_per_m as f64);
        let t = dt_s as f64;
        let w = libm::sqrt(k / m);
        let panels = libm::ceil(w * t / (0.1 * 2.0 * core::f64::consts::PI)).clamp(1.0, 4096.0) as usize;
        let width = t / panels as f64;
        let mut sum = [0.0f64; 2];
        for j in 0..panels {
            for (x, weight) in GAUSS_LEGENDRE_8 {
                let tau = width * (j as f64 + 0.5 * (x + 1.0));
                let (_, gamma) = zoh_second_order(m, c, k, tau);
                sum[0] += 0.5 * width * weight * gamma[0];
                sum[1] += 0.5 * width * weight * gamma[1];
            }
        }
        // To the state [y, ẏ/ω_n], as Γ.
        [(sum[0] / t) as f32, (sum[1] / t / w) as f32]
    }

    /// One sample under a force that runs linearly from `f0` (this sample's) to `f1` (the
    /// next's), with `ramp` = [`SecondOrderZoh::ramp_term`]; returns the new displacement [m].
    #[inline]
    pub fn step_ramp(&self, s: &mut MechState, f0: f32, f1: f32, ramp: &[f32; 2]) -> f32 {
        let (y, v) = (s.displacement_m, s.velocity_m_per_rad);
        let rise = f1 - f0;
        s.displacement_m = self.phi[0][0] * y + self.phi[0][1] * v + self.gamma[0] * f0 + ramp[0] * rise;
        s.velocity_m_per_rad = self.phi[1][0] * y + self.phi[1][1] * v + self.gamma[1] * f0 + ramp[1] * rise;
        s.displacement_m
    }

    /// Acceleration ÿ [m/s²] at the start of a sample with force `force_n` (for force outputs,
    /// 001 eq. 11–13: F_v = m_e ÿ + c_o ẏ + k_e y).
    #[inline]
    pub fn acceleration(&self, s: &MechState, force_n: f32) -> f32 {
        let p = &self.physical;
        (force_n - p.damping_n_s_per_m * self.velocity_m_per_s(s) - p.stiffness_n_per_m * s.displacement_m)
            / p.mass_kg
    }
}

/// Nodes and weights of 8-point Gauss–Legendre quadrature on [−1, 1].
const GAUSS_LEGENDRE_8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

/// Φ = e^{AT} and Γ = A⁻¹(Φ − I)B for A = [[0, 1], [−k/m, −c/m]], B = [0, 1/m]ᵀ.
///
/// With σ = ζω_n and q = ω_n²(1 − ζ²) (the squared damped frequency, negative when overdamped):
/// e^{AT} = e^{−σT} [C I + S (A + σI)], where C = cos(√q T), S = sin(√q T)/√q — both entire in q,
/// so one formula covers all regimes; near q = 0 their Taylor series are used, and for the
/// overdamped case the products e^{−σT}C, e^{−σT}S are formed from the real eigenvalues so that
/// nothing overflows.
fn zoh_second_order(m: f64, c: f64, k: f64, t: f64) -> ([[f64; 2]; 2], [f64; 2]) {
    let wn2 = k / m;
    let sigma = 0.5 * c / m;
    let q = wn2 - sigma * sigma;
    let (ec, es) = if libm::fabs(q) * t * t < 1e-4 {
        // Series: C = Σ (−q)^n T^{2n}/(2n)!, S = Σ (−q)^n T^{2n+1}/(2n+1)!
        let x = -q * t * t;
        let cs = 1.0 + x / 2.0 * (1.0 + x / 12.0 * (1.0 + x / 30.0));
        let ss = t * (1.0 + x / 6.0 * (1.0 + x / 20.0 * (1.0 + x / 42.0)));
        let e = libm::exp(-sigma * t);
        (e * cs, e * ss)
    } else if q > 0.0 {
        let wd = libm::sqrt(q);
        let e = libm::exp(-sigma * t);
        (e * libm::cos(wd * t), e * libm::sin(wd * t) / wd)
    } else {
        let w = libm::sqrt(-q);
        let e1 = libm::exp((-sigma + w) * t);
        let e2 = libm::exp((-sigma - w) * t);
        (0.5 * (e1 + e2), 0.5 * (e1 - e2) / w)
    };
    let phi = [[ec + sigma * es, es], [-wn2 * es, ec - sigma * es]];
    let gamma = [(1.0 - phi[1][1] - 2.0 * sigma * phi[0][1]) / k, wn2 * phi[0][1] / k];
    (phi, gamma)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fine-step RK4 reference of m ÿ + c ẏ + k y = F for constant F over `t`.
    fn rk4(p: &MassSpringDamper, y0: [f64; 2], f: f64, t: f64, n: usize) -> [f64; 2] {
        let (m, c, k) = (p.mass_kg as f64, p.damping_n_s_per_m as f64, p.stiffness_n_per_m as f64);
        let d = |x: [f64; 2]| [x[1], (f - c * x[1] - k * x[0]) / m];
        let h = t / n as f64;
        let mut x = y0;
        for _ in 0..n {
            let k1 = d(x);
            let k2 = d([x[0] + h / 2.0 * k1[0], x[1] + h / 2.0 * k1[1]]);
            let k3 = d([x[0] + h / 2.0 * k2[0], x[1] + h / 2.0 * k2[1]]);
            let k4 = d([x[0] + h * k3[0], x[1] + h * k3[1]]);
            for i in 0..2 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        x
    }

    fn check_against_rk4(zeta: f64) {
        let m = 0.1_f64;
        let k = 9.9e6_f64;
        let c = zeta * 2.0 * (k * m).sqrt();
        let p =
            MassSpringDamper { mass_kg: m as f32, damping_n_s_per_m: c as f32, stiffness_n_per_m: k as f32 };
        let dt = 1e-4_f32;
        let zoh = SecondOrderZoh::new(p, dt).unwrap();
        let mut s = MechState::default();
        let mut reference = [0.0_f64; 2];
        let mut max_err = 0.0_f64;
        let mut max_y = 0.0_f64;
        for n in 0..200 {
            // A force sequence with steps and sign changes.
            let f = if n % 50 < 25 { 100.0 } else { -40.0 };
            zoh.step(&mut s, f as f32);
            reference = rk4(&p, reference, f, dt as f64, 2000);
            max_err = max_err.max((s.displacement_m as f64 - reference[0]).abs());
            max_y = max_y.max(reference[0].abs());
        }
        let rel = max_err / max_y;
        assert!(rel <= 1e-4, "ζ = {zeta}: relative error {rel:e} > 1e-4");
    }

    #[test]
    fn zoh_matches_rk4_underdamped() {
        check_against_rk4(0.05);
        check_against_rk4(0.59);
    }

    #[test]
    fn zoh_matches_rk4_critically_damped() {
        check_against_rk4(1.0);
        check_against_rk4(1.0 + 1e-9);
    }

    #[test]
    fn zoh_matches_rk4_overdamped() {
        check_against_rk4(1.5);
        check_against_rk4(40.0);
    }

    #[test]
    fn static_gain_is_one_over_k() {
        let p = MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 };
        let zoh = SecondOrderZoh::new(p, 1e-4).unwrap();
        let mut s = MechState::default();
        for _ in 0..1000 {
            zoh.step(&mut s, 99.0);
        }
        assert!((s.displacement_m - 1e-5).abs() < 1e-10, "{}", s.displacement_m);
    }

    /// 001 eq. 14–15 with Table 1: the paper prints f_n = 1742 Hz and ζ = 0.5; the table's own
    /// numbers (m_r = ρ A_r l_r / 3) give f_n ≈ 1729 Hz and ζ ≈ 0.59.
    #[test]
    fn vibrator_001_natural_frequency_and_damping_from_table_1() {
        let (l_r, d_r, rho) = (0.1_f64, 0.03_f64, 9250.0_f64);
        let area = core::f64::consts::PI * d_r * d_r / 4.0;
        let m_r = rho * area * l_r / 3.0;
        let (k_r, c_r, k_s, c_o, k_o) = (4.2e8, 2.1e4, 3.5e5, 2.2e5, 1.8e9);
        let (m_o, m_b, m_a) = (0.4, 6.8, 11.4);
        let p = MassSpringDamper {
            mass_kg: (m_a + m_r + m_o + m_b) as f32,
            damping_n_s_per_m: (c_r + c_o) as f32,
            stiffness_n_per_m: (k_r + k_s + k_o) as f32,
        };
        let (f_n, zeta) = (p.natural_frequency_hz(), p.damping_ratio());
        assert!((f_n - 1728.8).abs() < 1.0, "f_n = {f_n} Hz (paper: 1742 Hz)");
        assert!((zeta - 0.5895).abs() < 0.001, "ζ = {zeta} (paper: 0.5)");
        // c_r is consistent with the table's c_d: c_r = c_d A_r / l_r.
        assert!((3e6 * area / l_r - c_r).abs() / c_r < 0.02);
    }

    /// 000 Table 1: √(K/m)/2π ≈ 1584 Hz and ζ ≈ 1.5 (overdamped).
    #[test]
    fn transducer_000_natural_frequency_and_damping() {
        let p = MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 };
        assert!((p.natural_frequency_hz() - 1583.6).abs() < 0.5);
        assert!((p.damping_ratio() - 1.508).abs() < 0.001);
    }

    #[test]
    fn rejects_bad_parameters_by_name() {
        let good = MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 };
        let e = SecondOrderZoh::new(MassSpringDamper { mass_kg: -1.0, ..good }, 1e-4).unwrap_err();
        assert_eq!(e, ParamError::OutOfRange("mech.mass_kg", "> 0"));
        let e =
            SecondOrderZoh::new(MassSpringDamper { stiffness_n_per_m: f32::NAN, ..good }, 1e-4).unwrap_err();
        assert_eq!(e, ParamError::NonFinite("mech.stiffness_n_per_m"));
        assert!(SecondOrderZoh::new(good, 0.0).is_err());
    }

    /// The first-order hold's step is exact for a force running linearly across each sample:
    /// against fine RK4 of that piecewise-linear force, in every damping regime and for a mode
    /// well below and well above the sample rate.
    #[test]
    fn ramp_step_matches_rk4_of_a_piecewise_linear_force() {
        for (zeta, f_n, dt) in
            [(0.2, 1200.0, 1e-4), (1.0, 800.0, 1e-4), (3.0, 500.0, 1e-4), (0.05, 9000.0, 1e-4)]
        {
            let m = 0.1_f64;
            let k = m * (2.0 * core::f64::consts::PI * f_n) * (2.0 * core::f64::consts::PI * f_n);
            let c = zeta * 2.0 * (k * m).sqrt();
            let p = MassSpringDamper {
                mass_kg: m as f32,
                damping_n_s_per_m: c as f32,
                stiffness_n_per_m: k as f32,
            };
            let zoh = SecondOrderZoh::new(p, dt as f32).unwrap();
            let ramp = zoh.ramp_term(dt as f32);
            let force = |n: usize| 100.0 * libm::sin(n as f64 * 0.7) + if n % 40 < 20 { 50.0 } else { -30.0 };
            let (mut s, mut x) = (MechState::default(), [0.0_f64; 2]);
            let (mut max_err, mut max_y) = (0.0_f64, 0.0_f64);
            for n in 0..200 {
                let (f0, f1) = (force(n), force(n + 1));
                zoh.step_ramp(&mut s, f0 as f32, f1 as f32, &ramp);
                // RK4 of the linear force: 400 sub-steps, the force at each stage's instant.
                let steps = 400;
                let h = dt / steps as f64;
                let (mm, cc, kk) = (m, c, k);
                let d = |x: [f64; 2], tau: f64| {
                    let f = f0 + (f1 - f0) * tau / dt;
                    [x[1], (f - cc * x[1] - kk * x[0]) / mm]
                };
                for j in 0..steps {
                    let t = j as f64 * h;
                    let k1 = d(x, t);
                    let k2 = d([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]], t + 0.5 * h);
                    let k3 = d([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]], t + 0.5 * h);
                    let k4 = d([x[0] + h * k3[0], x[1] + h * k3[1]], t + h);
                    for i in 0..2 {
                        x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                    }
                }
                max_err = max_err.max((s.displacement_m as f64 - x[0]).abs());
                max_y = max_y.max(x[0].abs());
            }
            let rel = max_err / max_y;
            assert!(rel <= 1e-4, "ζ = {zeta}, f_n = {f_n} Hz: relative error {rel:e} > 1e-4");
        }
    }
}
