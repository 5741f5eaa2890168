//! Measurement chain: what the data-acquisition system records of the true signals.
//!
//! Displacement (µm): `y_meas[k] = Q(y_true[k − d] + offset + drift(t_k) + n_k)`, with a
//! transport delay of d samples, Gaussian noise n_k, a drift that is a linear ramp plus a
//! Gaussian random walk, and quantisation Q(x) = q·round(x/q). Current: the same without
//! delay and drift. Temperature: noise only.
//!
//! Flux density (T), when the rig has a search coil ([`SearchCoil`]): the coil's voltage
//! integrated from t = 0, so `B_meas[k] = Q(B_true[k] − B_true[0] + ṙ_B t_k + n_k)` — an
//! integrator starts at zero and drifts with its input offset. Its noise comes from a random
//! stream of its own, so a rig with a search coil records the other channels exactly as one
//! without.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::collections::VecDeque;

/// Sensor parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    /// Standard deviation of the displacement noise (µm).
    pub displacement_noise_um: f64,
    /// Displacement quantisation step (µm) (0: none).
    pub displacement_quantum_um: f64,
    /// Constant displacement offset (µm).
    pub displacement_offset_um: f64,
    /// Linear displacement drift [µm/s].
    pub drift_rate_um_per_s: f64,
    /// Random-walk drift intensity [µm/√s].
    pub drift_walk_um_per_sqrt_s: f64,
    /// Transport delay of the displacement channel (samples).
    pub delay_samples: usize,
    /// Standard deviation of the current noise (A).
    pub current_noise_a: f64,
    /// Current quantisation step (A) (0: none).
    pub current_quantum_a: f64,
    /// Current offset (A).
    pub current_offset_a: f64,
    /// Standard deviation of the temperature noise [°C].
    pub temperature_noise_c: f64,
}

/// A search coil wound on the rod, read through an integrator: what a magnetics lab records to
/// see the rod's flux directly (the B of a B–H loop), independent of the mechanics and the
/// displacement probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchCoil {
    /// Area enclosed by the coil over the rod's cross-section (≥ 1): the annulus between rod
    /// and winding carries μ0 H_s, and the lab divides the flux by the rod's area.
    pub area_ratio: f64,
    /// Standard deviation of the flux-density noise (T).
    pub noise_t: f64,
    /// Quantisation step (T) (0: none).
    pub quantum_t: f64,
    /// Integrator drift [T/s] (its input offset).
    pub drift_t_per_s: f64,
}

impl SearchCoil {
    /// A coil on a thin bobbin (5 % more area than the rod), a 0.5 mT noise floor, 0.05 mT
    /// steps and 0.5 mT/s of integrator drift.
    pub const LAB: SearchCoil =
        SearchCoil { area_ratio: 1.05, noise_t: 0.5e-3, quantum_t: 0.05e-3, drift_t_per_s: 0.5e-3 };
}

/// Running state of the search coil's integrator (zeroed at the first sample).
pub(crate) struct FluxChain {
    p: SearchCoil,
    sw: SensorSwitches,
    rng: ChaCha8Rng,
    zero: Option<f64>,
}

impl FluxChain {
    /// The flux channel's random stream is seeded apart from the other channels'.
    pub fn new(p: SearchCoil, sw: SensorSwitches, seed: u64) -> Self {
        FluxChain { p, sw, rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EA2_C011), zero: None }
    }

    /// The measured flux density at time `t` for the true mean flux density `b_t` over the
    /// coil's area (divided by the rod's). Draws one random number per call.
    pub fn measure(&mut self, t: f64, b_t: f64) -> f64 {
        let n: f64 = StandardNormal.sample(&mut self.rng);
        let zero = *self.zero.get_or_insert(b_t);
        let mut b = b_t;
        if self.sw.offset_drift {
            b += -zero + self.p.drift_t_per_s * t;
        }
        if self.sw.noise {
            b += self.p.noise_t * n;
        }
        if self.sw.quantisation {
            b = quantise(b, self.p.quantum_t);
        }
        b
    }
}

/// Which parts of the measurement chain are active.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SensorSwitches {
    pub noise: bool,
    pub quantisation: bool,
    pub offset_drift: bool,
    pub delay: bool,
}

fn quantise(x: f64, q: f64) -> f64 {
    if q > 0.0 {
        (x / q).round() * q
    } else {
        x
    }
}

/// Running state of the measurement chain (random generator, delay line, drift).
pub(crate) struct SensorChain {
    p: Sensor,
    sw: SensorSwitches,
    rng: ChaCha8Rng,
    line: VecDeque<f64>,
    walk_um: f64,
    dt: f64,
}

impl SensorChain {
    pub fn new(p: Sensor, sw: SensorSwitches, seed: u64, dt: f64) -> Self {
        SensorChain { p, sw, rng: ChaCha8Rng::seed_from_u64(seed), line: VecDeque::new(), walk_um: 0.0, dt }
    }

    fn gauss(&mut self) -> f64 {
        StandardNormal.sample(&mut self.rng)
    }

    /// Measure one sample at time `t` of the true displacement (µm), current (A) and
    /// temperature [°C]. Every call draws the same number of random numbers, whatever the
    /// switches, so that switching one effect off leaves the others' noise unchanged.
    pub fn measure(&mut self, t: f64, x_um: f64, i_a: f64, temp_c: f64) -> (f64, f64, f64) {
        let (nx, ni, nt, nw) = (self.gauss(), self.gauss(), self.gauss(), self.gauss());
        let p = self.p;
        // Delay line: the value measured now is the true value d samples ago (the first
        // sample is repeated at the start).
        let d = if self.sw.delay { p.delay_samples } else { 0 };
        if self.line.is_empty() {
            for _ in 0..d {
                self.line.push_back(x_um);
            }
        }
        self.line.push_back(x_um);
        while self.line.len() > d + 1 {
            self.line.pop_front();
        }
        let mut x = self.line[0];
        let mut i = i_a;
        let mut temp = temp_c;
        if self.sw.offset_drift {
            self.walk_um += p.drift_walk_um_per_sqrt_s * self.dt.sqrt() * nw;
            x += p.displacement_offset_um + p.drift_rate_um_per_s * t + self.walk_um;
            i += p.current_offset_a;
        }
        if self.sw.noise {
            x += p.displacement_noise_um * nx;
            i += p.current_noise_a * ni;
            temp += p.temperature_noise_c * nt;
        }
        if self.sw.quantisation {
            x = quantise(x, p.displacement_quantum_um);
            i = quantise(i, p.current_quantum_a);
        }
        (x, i, temp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delay_and_quantisation_act_as_configured() {
        let p = Sensor {
            displacement_noise_um: 0.0,
            displacement_quantum_um: 0.5,
            displacement_offset_um: 0.0,
            drift_rate_um_per_s: 0.0,
            drift_walk_um_per_sqrt_s: 0.0,
            delay_samples: 2,
            current_noise_a: 0.0,
            current_quantum_a: 0.0,
            current_offset_a: 0.0,
            temperature_noise_c: 0.0,
        };
        let sw = SensorSwitches { noise: true, quantisation: true, offset_drift: true, delay: true };
        let mut s = SensorChain::new(p, sw, 1, 1e-4);
        let out: Vec<f64> =
            [0.0, 1.0, 2.0, 3.1, 4.0].iter().map(|&x| s.measure(0.0, x, 0.0, 0.0).0).collect();
        assert_eq!(out, vec![0.0, 0.0, 0.0, 1.0, 2.0]);
    }
}
