//! The residual and frequency analysis against answers known without it: the H1 estimate of a
//! second-order stage (a difference equation written here, its response evaluated in closed
//! form) and the correlations of white noise and of an AR(1) sequence.

use host_sim::spectral::{self, cross_correlation, h1};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use realfft::num_complex::Complex;

const FS_HZ: f64 = 10_000.0;

/// A mass–spring–damper stage (f0 = 300 Hz, ζ = 0.1, static gain 20 µm/A) as a digital filter:
/// its continuous poles mapped exactly (z = e^{sT}), unit delay, numerator set for the static
/// gain. y_k = −a1·y_{k−1} − a2·y_{k−2} + b1·u_{k−1}.
struct Stage {
    a1: f64,
    a2: f64,
    b1: f64,
}

impl Stage {
    fn new() -> Self {
        let (f0, zeta, gain, t) = (300.0, 0.1, 20.0, 1.0 / FS_HZ);
        let w0 = 2.0 * std::f64::consts::PI * f0;
        let r = (-zeta * w0 * t).exp();
        let theta = w0 * t * (1.0 - zeta * zeta).sqrt();
        let (a1, a2) = (-2.0 * r * theta.cos(), r * r);
        Self { a1, a2, b1: gain * (1.0 + a1 + a2) }
    }

    fn run(&self, u: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; u.len()];
        for k in 2..u.len() {
            y[k] = -self.a1 * y[k - 1] - self.a2 * y[k - 2] + self.b1 * u[k - 1];
        }
        y
    }

    /// H(e^{jωT}) = b1·z⁻¹ / (1 + a1·z⁻¹ + a2·z⁻²).
    fn response(&self, f_hz: f64) -> Complex<f64> {
        let zi = Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * f_hz / FS_HZ);
        self.b1 * zi / (1.0 + self.a1 * zi + self.a2 * zi * zi)
    }
}

/// Linear chirp 20 Hz → 2 kHz over 4 s, 1 A amplitude, around a 1 A bias.
fn chirp() -> Vec<f64> {
    let (f_lo, f_hi, dur) = (20.0, 2000.0, 4.0);
    let n = (dur * FS_HZ) as usize;
    (0..n)
        .map(|k| {
            let t = k as f64 / FS_HZ;
            1.0 + (2.0 * std::f64::consts::PI * (f_lo * t + 0.5 * (f_hi - f_lo) / dur * t * t)).sin()
        })
        .collect()
}

/// Worst gain [dB] and phase [deg] error of H1 over its excited band, the band's edges [Hz],
/// and its coherence floor.
fn worst_error(u: &[f64], y: &[f64], stage: &Stage) -> (f64, f64, f64, f64) {
    let est = h1(u, y, FS_HZ, 4096).unwrap();
    let band = est.excited_bins();
    let f = &est.spectra.freq_hz;
    let (mut gain, mut phase) = (0.0f64, 0.0f64);
    for &k in &band {
        let exact = stage.response(f[k]);
        gain = gain.max((spectral::gain_db(est.h[k]).unwrap() - spectral::gain_db(exact).unwrap()).abs());
        phase = phase.max(
            spectral::phase_difference_deg(spectral::phase_deg(est.h[k]), spectral::phase_deg(exact)).abs(),
        );
    }
    (gain, phase, f[band[0]], f[*band.last().unwrap()])
}

#[test]
fn h1_of_a_second_order_stage_matches_its_analytic_response_over_the_excited_band() {
    let stage = Stage::new();
    let u = chirp();
    let noise = Normal::new(0.0, 0.05).unwrap(); // µm: sensor noise, 1/400 of the static response
    let mut rng = StdRng::seed_from_u64(7);
    let y: Vec<f64> = stage.run(&u).iter().map(|v| v + noise.sample(&mut rng)).collect();
    let (gain, phase, lo, hi) = worst_error(&u, &y, &stage);
    eprintln!("H1 vs analytic over {lo:.1}–{hi:.1} Hz: worst gain error {gain:.3} dB, phase {phase:.2}°");
    // The band must be the chirp's, resonance included, not a few convenient bins.
    assert!(lo < 50.0 && hi > 1950.0, "excited band {lo}–{hi} Hz");
    assert!(gain < 1.0, "worst gain error {gain:.3} dB over {lo}–{hi} Hz");
    assert!(phase < 5.0, "worst phase error {phase:.2}° over {lo}–{hi} Hz");

    // The same check fails for an output three samples late (0.3 ms: 108° at 1 kHz), so it
    // does test the phase.
    let late: Vec<f64> = std::iter::repeat_n(y[0], 3).chain(y[..y.len() - 3].iter().copied()).collect();
    let (_, phase_late, _, _) = worst_error(&u, &late, &stage);
    eprintln!("3 samples late: worst phase error {phase_late:.1}°");
    assert!(phase_late > 5.0, "a 3-sample delay went unnoticed: worst phase error {phase_late:.2}°");
    // And for a stage with a 10 % lower gain (0.9 dB): the gain check is as tight as stated.
    let low: Vec<f64> = y.iter().map(|v| 0.89 * v).collect();
    let (gain_low, _, _, _) = worst_error(&u, &low, &stage);
    eprintln!("gain × 0.89: worst gain error {gain_low:.3} dB");
    assert!(gain_low > 1.0, "an 11 % gain drop went unnoticed: {gain_low:.3} dB");
}

fn white(seed: u64, n: usize) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    (0..n).map(|_| normal.sample(&mut rng)).collect()
}

#[test]
fn white_noise_stays_within_the_bounds_and_ar1_does_not() {
    // 20 white sequences of 10 000 samples, lags 1..100: about 5 % outside ±1.96/√N.
    let shares: Vec<f64> = (0..20)
        .map(|s| cross_correlation(&white(s, 10_000), &white(s, 10_000), 100).unwrap().outside_share(1))
        .collect();
    let mean = shares.iter().sum::<f64>() / shares.len() as f64;
    assert!((0.03..=0.07).contains(&mean), "white noise: mean share outside {mean:.3} ({shares:?})");
    let acf = cross_correlation(&white(1, 10_000), &white(1, 10_000), 100).unwrap();
    assert!((acf.bound - 0.0196).abs() < 1e-12 && acf.r[0] == 1.0);

    // AR(1), e_k = 0.9·e_{k−1} + w_k: r(τ) = 0.9^τ, above the band up to τ ≈ 37.
    let w = white(99, 10_000);
    let mut e = vec![0.0; w.len()];
    for k in 1..w.len() {
        e[k] = 0.9 * e[k - 1] + w[k];
    }
    let ar = cross_correlation(&e, &e, 100).unwrap();
    assert!((ar.r[1] - 0.9).abs() < 0.03, "AR(1) r(1) = {}", ar.r[1]);
    assert!(ar.outside_share(1) > 0.3, "AR(1): only {:.2} of lags outside", ar.outside_share(1));
}

#[test]
fn an_input_left_in_the_residual_shows_at_its_lag() {
    // e_k = 0.5·u_{k−2} + noise: the cross-correlation peaks at lag 2, white u and e otherwise
    // unrelated stay inside the band.
    let u = white(3, 10_000);
    let noise = white(4, 10_000);
    let e: Vec<f64> = (0..u.len()).map(|k| if k >= 2 { 0.5 * u[k - 2] } else { 0.0 } + noise[k]).collect();
    let c = cross_correlation(&u, &e, 50).unwrap();
    let (lag, r) = c.largest(0).unwrap();
    assert_eq!(lag, 2);
    assert!((r - 0.5 / 1.25f64.sqrt()).abs() < 0.03, "r_ue(2) = {r}");
    let unrelated = cross_correlation(&u, &noise, 50).unwrap();
    assert!(unrelated.outside_share(0) < 0.15, "{}", unrelated.outside_share(0));
}
