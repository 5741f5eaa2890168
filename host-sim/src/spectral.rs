//! Residual and frequency analysis (the numerics; `analysis.rs` applies them to a recording):
//! sample auto- and cross-correlation with their whiteness bounds, Welch power spectra (Hann
//! window, 50 % overlap, mean removed per segment) and the H1 frequency-response estimate
//! H1 = S_uy / S_uu with its coherence γ² = |S_uy|² / (S_uu S_yy). FFTs by `realfft` (rustfft).

use anyhow::{bail, Result};
use realfft::num_complex::Complex;
use realfft::RealFftPlanner;

/// z of the two-sided 95 % band of a sample correlation of white noise: ±1.96/√N.
pub const Z95: f64 = 1.96;

/// Input PSD floor of the excited band: bins more than 20 dB below the input's largest
/// (non-DC) bin carry only window leakage from the excited ones, not excitation.
pub const EXCITED_INPUT_DB: f64 = 20.0;

/// Coherence floor of the excited band: below it, noise or nonlinearity dominates the
/// estimate. The random error of one bin is about √((1 − γ²)/(2 n_d γ²)) (n_d segments): at
/// γ² = 0.9 and 8 segments 0.08, i.e. 0.7 dB and 4.8° (1σ); far less where γ² is near 1.
pub const EXCITED_COHERENCE: f64 = 0.9;

/// A sample correlation r(τ) for τ = 0..=L and the white-noise band ±1.96/√N.
#[derive(Debug, Clone, PartialEq)]
pub struct Correlation {
    /// r(τ), τ = 0..=max_lag samples (dimensionless, |r| ≤ 1).
    pub r: Vec<f64>,
    /// N: the samples the estimate used (the band's N).
    pub samples: usize,
    /// 1.96/√N.
    pub bound: f64,
}

impl Correlation {
    /// Share of the lags in `from..=max_lag` where |r| exceeds the bound (≈ 5 % for white noise).
    pub fn outside_share(&self, from: usize) -> f64 {
        let lags = self.r.get(from..).unwrap_or_default();
        if lags.is_empty() {
            return 0.0;
        }
        lags.iter().filter(|r| r.abs() > self.bound).count() as f64 / lags.len() as f64
    }

    /// The lag in `from..` with the largest |r|, and r there.
    pub fn largest(&self, from: usize) -> Option<(usize, f64)> {
        self.r
            .iter()
            .enumerate()
            .skip(from)
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map(|(k, r)| (k, *r))
    }
}

fn check_finite(name: &str, x: &[f64]) -> Result<()> {
    if let Some(k) = x.iter().position(|v| !v.is_finite()) {
        bail!("{name}: sample {k} is not a finite number");
    }
    Ok(())
}

/// Mean and Σ(x − mean)².
fn mean_and_energy(x: &[f64]) -> (f64, f64) {
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    (mean, x.iter().map(|v| (v - mean) * (v - mean)).sum())
}

/// Normalised sample cross-correlation r_xy(τ) = Σ_t x̃_t ỹ_{t+τ} / √(Σx̃² Σỹ²) for τ = 0..=max_lag
/// (x leads y; x̃, ỹ mean removed; the biased estimator, as the ±1.96/√N band assumes). With
/// `x = y` it is the autocorrelation, r(0) = 1. Refuses constant or non-finite signals, or fewer
/// than 2·max_lag samples.
pub fn cross_correlation(x: &[f64], y: &[f64], max_lag: usize) -> Result<Correlation> {
    let n = x.len();
    if y.len() != n {
        bail!("correlation: the signals have {n} and {} samples", y.len());
    }
    if max_lag == 0 || n < 2 * max_lag {
        bail!(
            "correlation: {n} samples are too few for lags up to {max_lag} (need at least {})",
            2 * max_lag.max(1)
        );
    }
    check_finite("correlation input", x)?;
    check_finite("correlation input", y)?;
    let (mx, ex) = mean_and_energy(x);
    let (my, ey) = mean_and_energy(y);
    if ex <= 0.0 || ey <= 0.0 {
        bail!("correlation: a signal is constant (no variance to correlate)");
    }
    // Linear (not circular) correlation: zero-pad past 2N, then IFFT(conj(X)·Y). One padded
    // buffer and two spectra at a time (2 million samples: about 100 MB).
    let len = (2 * n).next_power_of_two();
    let mut planner = RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(len);
    let inv = planner.plan_fft_inverse(len);
    let mut buf = fwd.make_input_vec();
    let spectrum = |v: &[f64], mean: f64, buf: &mut [f64]| -> Result<Vec<Complex<f64>>> {
        buf.fill(0.0); // the transform uses its input as scratch
        for (b, x) in buf.iter_mut().zip(v) {
            *b = x - mean;
        }
        let mut out = fwd.make_output_vec();
        fwd.process(buf, &mut out).map_err(|e| anyhow::anyhow!("FFT: {e}"))?;
        Ok(out)
    };
    let sx = spectrum(x, mx, &mut buf)?;
    let mut prod = spectrum(y, my, &mut buf)?;
    for (p, a) in prod.iter_mut().zip(&sx) {
        *p *= a.conj();
    }
    drop(sx);
    // DC and Nyquist bins of a real signal's product are real up to rounding.
    let last = prod.len() - 1;
    prod[0].im = 0.0;
    prod[last].im = 0.0;
    inv.process(&mut prod, &mut buf).map_err(|e| anyhow::anyhow!("FFT: {e}"))?;
    let scale = 1.0 / (len as f64 * (ex * ey).sqrt());
    let r = buf[..=max_lag].iter().map(|v| (v * scale).clamp(-1.0, 1.0)).collect();
    Ok(Correlation { r, samples: n, bound: Z95 / (n as f64).sqrt() })
}

/// Effective number of independent samples of a series, N/τ, with τ the larger of two readings
/// of its autocorrelation, each blind where the other sees:
/// - the integrated autocorrelation time 1 + 2 Σ_k ρ(k), its sum cut by Geyer's initial monotone
///   sequence (Geyer 1992: the pairs Γ_m = ρ(2m) + ρ(2m+1) summed while positive, each held at
///   most the one before, τ = −1 + 2 Σ Γ_m). It sees slow model error under white noise, whose
///   lag-1 correlation is small (the noise) but which stays correlated for a fraction of its
///   period (the lag-1 reading alone overstated N_eff a hundredfold there);
/// - the AR(1) reading (1 + ρ(1))/(1 − ρ(1)). It sees a residual that oscillates in a band
///   (a missed resonance), whose correlations cancel in the sum although a statistic along a
///   regressor in the same band (a least-squares gain, a parameter's interval) is inflated.
///
/// Negative correlation counts every sample once: the result lies in [1, N]. A series without
/// variance about its mean counts once (one offset), an all-zero one N times; a non-finite one
/// once.
pub fn effective_samples(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 4 {
        return n as f64;
    }
    if x.iter().any(|v| !v.is_finite()) {
        return 1.0;
    }
    // Variance at the rounding level of the values is none: a constant.
    let (_, energy) = mean_and_energy(x);
    let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if peak == 0.0 {
        return n as f64;
    }
    if energy <= n as f64 * (1e-12 * peak).powi(2) {
        return 1.0;
    }
    let Ok(correlation) = cross_correlation(x, x, n / 2) else { return 1.0 };
    let r = correlation.r;
    let mut tau = -1.0;
    let mut previous = f64::INFINITY;
    for pair in r.chunks_exact(2) {
        let gamma = (pair[0] + pair[1]).min(previous);
        if gamma <= 0.0 {
            break;
        }
        tau += 2.0 * gamma;
        previous = gamma;
    }
    let rho1 = r.get(1).copied().unwrap_or(0.0).clamp(0.0, 0.999);
    let tau = tau.max((1.0 + rho1) / (1.0 - rho1));
    (n as f64 / tau).clamp(1.0, n as f64)
}

/// One-sided Welch spectra of an input u and an output y on the same frequency grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Spectra {
    /// Bin frequencies [Hz], 0 to fs/2 in steps of fs/segment.
    pub freq_hz: Vec<f64>,
    /// Input PSD S_uu [u²/Hz].
    pub suu: Vec<f64>,
    /// Output PSD S_yy [y²/Hz].
    pub syy: Vec<f64>,
    /// Cross spectrum S_uy [u·y/Hz] (conj(U)·Y).
    pub suy: Vec<Complex<f64>>,
    /// Segments averaged.
    pub segments: usize,
}

/// Segment length for Welch: the largest power of two ≤ N/4 (at least about 7 averages with
/// 50 % overlap), between 64 and 8192 samples; None when N < 128.
pub fn default_segment(n: usize) -> Option<usize> {
    if n < 128 {
        return None;
    }
    let quarter = n / 4;
    let p = 1usize << (usize::BITS - 1 - quarter.leading_zeros());
    Some(p.clamp(64, 8192))
}

/// Welch estimate of S_uu, S_yy and S_uy: Hann-windowed segments of `segment` samples, at
/// least 50 % overlap (spread to cover every sample), each segment's mean removed, density scaling (one-sided: interior bins doubled).
pub fn welch(u: &[f64], y: &[f64], fs_hz: f64, segment: usize) -> Result<Spectra> {
    let n = u.len();
    if y.len() != n {
        bail!("spectrum: the signals have {n} and {} samples", y.len());
    }
    if segment < 8 || segment > n {
        bail!("spectrum: segment of {segment} samples for {n} samples (need 8 ≤ segment ≤ samples)");
    }
    if !(fs_hz.is_finite() && fs_hz > 0.0) {
        bail!("spectrum: sample rate {fs_hz} Hz is not a positive number");
    }
    check_finite("spectrum input", u)?;
    check_finite("spectrum input", y)?;
    let window: Vec<f64> = (0..segment)
        .map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / segment as f64).cos())
        .collect();
    let w2: f64 = window.iter().map(|w| w * w).sum();
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(segment);
    let bins = segment / 2 + 1;
    let (mut suu, mut syy, mut suy) = (vec![0.0; bins], vec![0.0; bins], vec![Complex::new(0.0, 0.0); bins]);
    // At least 50 % overlap, segments spread evenly from the first sample to the last (no tail
    // dropped: a chirp's last frequencies are at its end).
    let segments = if n == segment { 1 } else { (n - segment).div_ceil(segment / 2) + 1 };
    let mut buf = fft.make_input_vec();
    let (mut fu, mut fy) = (fft.make_output_vec(), fft.make_output_vec());
    for i in 0..segments {
        let start = if segments == 1 { 0 } else { i * (n - segment) / (segments - 1) };
        for (x, out) in [(&u[start..start + segment], &mut fu), (&y[start..start + segment], &mut fy)] {
            let mean = x.iter().sum::<f64>() / segment as f64;
            for ((b, v), w) in buf.iter_mut().zip(x).zip(&window) {
                *b = (v - mean) * w;
            }
            fft.process(&mut buf, out).map_err(|e| anyhow::anyhow!("FFT: {e}"))?;
        }
        for k in 0..bins {
            suu[k] += fu[k].norm_sqr();
            syy[k] += fy[k].norm_sqr();
            suy[k] += fu[k].conj() * fy[k];
        }
    }
    for k in 0..bins {
        let one_sided = if k == 0 || (segment % 2 == 0 && k == bins - 1) { 1.0 } else { 2.0 };
        let s = one_sided / (fs_hz * w2 * segments as f64);
        suu[k] *= s;
        syy[k] *= s;
        suy[k] *= s;
    }
    let freq_hz = (0..bins).map(|k| k as f64 * fs_hz / segment as f64).collect();
    Ok(Spectra { freq_hz, suu, syy, suy, segments })
}

/// An H1 frequency-response estimate from u to y.
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// The spectra it came from.
    pub spectra: Spectra,
    /// H1 = S_uy / S_uu per bin [y/u]; zero where the input has no power.
    pub h: Vec<Complex<f64>>,
    /// γ² = |S_uy|² / (S_uu S_yy) per bin, in [0, 1]; zero where undefined.
    pub coherence: Vec<f64>,
}

/// H1 estimate (unbiased under output noise) and coherence from Welch spectra.
pub fn h1(u: &[f64], y: &[f64], fs_hz: f64, segment: usize) -> Result<FrequencyResponse> {
    let spectra = welch(u, y, fs_hz, segment)?;
    let floor = f64::MIN_POSITIVE * 1e6;
    let h = spectra
        .suu
        .iter()
        .zip(&spectra.suy)
        .map(|(uu, uy)| if *uu > floor { uy / uu } else { Complex::new(0.0, 0.0) })
        .collect();
    let coherence = spectra
        .suu
        .iter()
        .zip(&spectra.syy)
        .zip(&spectra.suy)
        .map(|((uu, yy), uy)| {
            let d = uu * yy;
            if d > floor {
                (uy.norm_sqr() / d).clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect();
    Ok(FrequencyResponse { spectra, h, coherence })
}

impl FrequencyResponse {
    /// The excited band: bins above DC whose input PSD is within [`EXCITED_INPUT_DB`] of the
    /// input's largest non-DC bin and whose coherence is at least [`EXCITED_COHERENCE`].
    pub fn excited_bins(&self) -> Vec<usize> {
        let peak = self.spectra.suu.iter().skip(1).fold(0.0f64, |m, v| m.max(*v));
        if peak <= 0.0 {
            return Vec::new();
        }
        let floor = peak * 10f64.powf(-EXCITED_INPUT_DB / 10.0);
        (1..self.h.len())
            .filter(|&k| self.spectra.suu[k] >= floor && self.coherence[k] >= EXCITED_COHERENCE)
            .collect()
    }
}

/// Gain in dB (20·log10|h|); None for a zero gain.
pub fn gain_db(h: Complex<f64>) -> Option<f64> {
    let a = h.norm();
    (a > 0.0 && a.is_finite()).then(|| 20.0 * a.log10())
}

/// Phase of h in degrees, (−180, 180].
pub fn phase_deg(h: Complex<f64>) -> f64 {
    h.arg().to_degrees()
}

/// Difference of two phases [deg], wrapped into (−180, 180].
pub fn phase_difference_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// Phases [deg] unwrapped along the sequence (jumps over 180° taken as wraps), for plots.
pub fn unwrap_deg(phases: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(phases.len());
    let mut prev: Option<f64> = None;
    for &p in phases {
        let v = match prev {
            Some(q) => q + phase_difference_deg(p, q),
            None => p,
        };
        out.push(v);
        prev = Some(v);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng as _, SeedableRng as _};

    fn uniform_noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    #[test]
    fn effective_samples_of_white_noise_and_of_an_ar1_series() {
        let n = 20_000;
        let white = effective_samples(&uniform_noise(n, 1));
        assert!(white > 0.9 * n as f64 && white <= n as f64, "white noise: N_eff {white}");
        // AR(1) with ρ = 0.9: τ = (1 + ρ)/(1 − ρ) = 19.
        let mut x = 0.0;
        let ar1: Vec<f64> = uniform_noise(n, 2)
            .into_iter()
            .map(|e| {
                x = 0.9 * x + e;
                x
            })
            .collect();
        let red = effective_samples(&ar1);
        let expected = n as f64 / 19.0;
        assert!((red / expected - 1.0).abs() < 0.25, "ρ = 0.9: N_eff {red}, expected {expected}");
    }

    /// Slow model error under white noise of the same power (the residual of a model that
    /// misses a slow effect): ρ(1) is only ≈ 0.5, an AR(1) reading of it says N/3, while the
    /// error stays correlated over a third of its period, τ ≈ 1 + P/(2π) (≈ 320 at P = 2000).
    #[test]
    fn slow_error_under_noise_counts_once_per_stretch_of_its_period_not_per_sample() {
        let (n, period) = (30_000, 2000.0);
        let noise = uniform_noise(n, 3);
        // Uniform noise on [−1, 1] has variance 1/3; the sine's amplitude √(2/3) matches it.
        let amp = (2.0f64 / 3.0).sqrt();
        let x: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, e)| e + amp * (2.0 * std::f64::consts::PI * k as f64 / period).sin())
            .collect();
        let got = effective_samples(&x);
        let expected = n as f64 / (1.0 + period / (2.0 * std::f64::consts::PI));
        assert!(got > expected / 1.5 && got < expected * 1.5, "N_eff {got}, expected ≈ {expected}");
        assert!(got < n as f64 / 30.0, "N_eff {got}: the lag-1 reading's N/3 would pass this check");
    }

    /// A residual oscillating in a band (a missed resonance, 10 samples a period): its
    /// correlations cancel in Geyer's sum (τ ≈ 2.6), the AR(1) reading keeps it (ρ(1) = cos 36°,
    /// τ = 9.5), and the larger counts.
    #[test]
    fn a_band_limited_residual_counts_by_its_lag_one_correlation() {
        let n = 20_000;
        let noise = uniform_noise(n, 4);
        let x: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, e)| 0.05 * e + (2.0 * std::f64::consts::PI * k as f64 / 10.0).sin())
            .collect();
        let rho1 = (2.0 * std::f64::consts::PI / 10.0).cos();
        let expected = n as f64 * (1.0 - rho1) / (1.0 + rho1);
        let got = effective_samples(&x);
        assert!((got / expected - 1.0).abs() < 0.1, "N_eff {got}, expected ≈ {expected}");
    }

    #[test]
    fn effective_samples_stay_between_one_and_n() {
        let n = 1000;
        let alternating: Vec<f64> = (0..n).map(|k| if k % 2 == 0 { 1.0 } else { -1.0 }).collect();
        assert_eq!(effective_samples(&alternating), n as f64, "negative correlation counts each sample once");
        assert_eq!(effective_samples(&vec![0.3; n]), 1.0, "a constant offset is one sample");
        assert_eq!(effective_samples(&vec![0.0; n]), n as f64);
        assert_eq!(effective_samples(&[f64::NAN; 10]), 1.0);
        assert_eq!(effective_samples(&[1.0, 2.0]), 2.0);
        let ramp: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let r = effective_samples(&ramp);
        assert!((1.0..10.0).contains(&r), "a ramp is one slow trend: N_eff {r}");
    }

    #[test]
    fn welch_psd_of_a_sine_integrates_to_its_power() {
        // A 1 V amplitude sine carries 0.5 V²; the density summed over bins × Δf recovers it.
        let fs = 1000.0;
        let x: Vec<f64> =
            (0..8192).map(|k| (2.0 * std::f64::consts::PI * 62.5 * k as f64 / fs).sin()).collect();
        let s = welch(&x, &x, fs, 512).unwrap();
        let df = fs / 512.0;
        let power: f64 = s.suu.iter().sum::<f64>() * df;
        // Hann's equivalent noise bandwidth is 1.5 bins: the density sums exactly.
        assert!((power - 0.5).abs() < 0.01, "power {power}");
        assert_eq!(s.segments, 31);
    }

    #[test]
    fn correlation_at_lag_equals_the_direct_sum() {
        let x: Vec<f64> = (0..300).map(|k| ((k * 37 % 101) as f64).sin()).collect();
        let y: Vec<f64> = (0..300).map(|k| ((k * 53 % 97) as f64).cos() + 0.3 * x[k]).collect();
        let c = cross_correlation(&x, &y, 10).unwrap();
        let mx = x.iter().sum::<f64>() / 300.0;
        let my = y.iter().sum::<f64>() / 300.0;
        let sx = x.iter().map(|v| (v - mx).powi(2)).sum::<f64>();
        let sy = y.iter().map(|v| (v - my).powi(2)).sum::<f64>();
        for tau in 0..=10 {
            let direct =
                (0..300 - tau).map(|t| (x[t] - mx) * (y[t + tau] - my)).sum::<f64>() / (sx * sy).sqrt();
            assert!((c.r[tau] - direct).abs() < 1e-12, "lag {tau}: {} vs {direct}", c.r[tau]);
        }
    }

    #[test]
    fn constant_and_short_signals_are_refused() {
        assert!(cross_correlation(&[1.0; 100], &[2.0; 100], 5).unwrap_err().to_string().contains("constant"));
        assert!(cross_correlation(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0], 5).is_err());
        assert!(welch(&[1.0; 4], &[1.0; 4], 1.0, 8).is_err());
    }

    #[test]
    fn phases_wrap_and_unwrap() {
        assert_eq!(phase_difference_deg(170.0, -170.0), -20.0);
        assert_eq!(unwrap_deg(&[170.0, -170.0, -150.0]), vec![170.0, 190.0, 210.0]);
        assert_eq!(default_segment(10_000), Some(2048));
        assert_eq!(default_segment(100), None);
    }
}
