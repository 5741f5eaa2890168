//! Residual and frequency analysis of a model against one recording (`gma compare`, the report):
//! is the residual white (autocorrelation), does it still depend on the drive (cross-correlation
//! with the input), where is its power (spectrum), and does the model's frequency response match
//! the one the data show (H1 of measured and of model output from the same input, same estimator).
//! The numerics are in [`crate::spectral`].

use anyhow::{bail, Result};
use serde::Serialize;

use crate::recording::Recording;
use crate::simulated::Simulation;
use crate::spectral::{self, Correlation, FrequencyResponse};

/// Default largest lag of the correlations [samples].
pub const DEFAULT_MAX_LAG: usize = 100;

/// Largest allowed `--max-lag` [samples].
pub const MAX_LAG_LIMIT: usize = 100_000;

/// Whiteness of one correlation, as reported.
#[derive(Debug, Clone, Serialize)]
pub struct CorrelationSummary {
    /// Largest lag L [samples] (lags 0..=L were estimated).
    pub max_lag: usize,
    /// Lag of one sample [s].
    pub lag_s: f64,
    /// N, the samples behind the estimate.
    pub samples: usize,
    /// The white-noise band 1.96/√N.
    pub bound: f64,
    /// Share of the tested lags with |r| above the bound (≈ 0.05 for a white residual).
    pub outside_share: f64,
    /// Lag [samples] of the largest |r| among the tested lags.
    pub largest_lag: usize,
    /// r at that lag.
    pub largest: f64,
}

/// Where the residual's power lies.
#[derive(Debug, Clone, Serialize)]
pub struct SpectrumSummary {
    /// Frequency resolution (bin width) [Hz].
    pub resolution_hz: f64,
    /// Welch segments averaged.
    pub segments: usize,
    /// Frequency of the residual's largest PSD bin above DC [Hz].
    pub peak_hz: f64,
    /// Residual PSD there [µm²/Hz].
    pub peak_um2_per_hz: f64,
}

/// Measured against model frequency response over the excited band.
#[derive(Debug, Clone, Serialize)]
pub struct FrequencyResponseSummary {
    /// The input column (`current_A` or `command_V`).
    pub input: &'static str,
    /// Unit of the gain (`um_per_A` or `um_per_V`; dB are re 1 of it).
    pub gain_unit: &'static str,
    /// Lowest and highest frequency of the excited band [Hz]; null when nothing is excited.
    pub band_hz: Option<[f64; 2]>,
    /// Bins in the excited band.
    pub bins: usize,
    /// Mean measured coherence γ² over the band.
    pub mean_coherence: Option<f64>,
    /// rms over the band of the model's gain minus the measured gain [dB].
    pub gain_error_db_rms: Option<f64>,
    /// Largest |gain error| over the band [dB].
    pub gain_error_db_max: Option<f64>,
    /// rms over the band of the model's phase minus the measured phase [deg].
    pub phase_error_deg_rms: Option<f64>,
    /// Largest |phase error| over the band [deg].
    pub phase_error_deg_max: Option<f64>,
}

/// The JSON/text summary of one file's analysis.
#[derive(Debug, Clone, Serialize)]
pub struct AnalysisSummary {
    /// Residual autocorrelation r_ee(τ), lags 1..=L tested.
    pub residual_autocorrelation: CorrelationSummary,
    /// Input–residual cross-correlation r_ue(τ) (input leads), lags 0..=L tested.
    pub input_cross_correlation: CorrelationSummary,
    /// Residual PSD.
    pub residual_spectrum: SpectrumSummary,
    /// H1 of measured and of model displacement from the same input.
    pub frequency_response: FrequencyResponseSummary,
}

/// One file's analysis: the summary and what the plots draw.
#[derive(Debug, Clone)]
pub struct FileAnalysis {
    /// The file's name.
    pub name: String,
    /// What is reported.
    pub summary: AnalysisSummary,
    /// r_ee.
    pub acf: Correlation,
    /// r_ue.
    pub ccf: Correlation,
    /// Residual PSD per bin [µm²/Hz] (on `measured.spectra.freq_hz`).
    pub residual_psd: Vec<f64>,
    /// H1 from input to measured displacement.
    pub measured: FrequencyResponse,
    /// H1 from input to model displacement.
    pub model: FrequencyResponse,
    /// The excited band's bins.
    pub band: Vec<usize>,
    /// Sample period [s].
    pub dt_s: f64,
}

fn rms(v: impl Iterator<Item = f64> + Clone) -> Option<f64> {
    let n = v.clone().count();
    (n > 0).then(|| (v.map(|x| x * x).sum::<f64>() / n as f64).sqrt())
}

fn max_abs(v: impl Iterator<Item = f64>) -> Option<f64> {
    v.map(f64::abs).reduce(f64::max)
}

fn correlation_summary(c: &Correlation, from: usize, dt_s: f64) -> CorrelationSummary {
    let (largest_lag, largest) = c.largest(from).unwrap_or((from, 0.0));
    CorrelationSummary {
        max_lag: c.r.len() - 1,
        lag_s: dt_s,
        samples: c.samples,
        bound: c.bound,
        outside_share: c.outside_share(from),
        largest_lag,
        largest,
    }
}

/// Analyses `sim` (plus the fitted `offset_um`) against `rec` with lags up to `max_lag`.
/// Refuses (the caller says why and goes on) recordings too short for the spectra (128 samples)
/// or the lags (2·max_lag), a constant drive, or a residual without variance.
pub fn analyse(rec: &Recording, sim: &Simulation, offset_um: f64, max_lag: usize) -> Result<FileAnalysis> {
    let measured_um = rec.displacement_um.as_deref().unwrap_or_default();
    let (input, input_name, gain_unit) = match (&rec.current_a, &rec.command_v) {
        (Some(i), _) => (i.as_slice(), "current_A", "um_per_A"),
        (None, Some(u)) => (u.as_slice(), "command_V", "um_per_V"),
        _ => bail!("no drive column (current_A or command_V) to analyse against"),
    };
    let n = rec.len();
    let Some(segment) = spectral::default_segment(n) else {
        bail!("{n} samples are too few for the spectra (need at least 128)");
    };
    let dt_s = rec.dt_s();
    let fs_hz = 1.0 / dt_s;
    let model_um: Vec<f64> = sim.displacement_um.iter().map(|y| y + offset_um).collect();
    let residual_um: Vec<f64> = measured_um.iter().zip(&model_um).map(|(m, y)| m - y).collect();
    let acf = spectral::cross_correlation(&residual_um, &residual_um, max_lag)?;
    let ccf = spectral::cross_correlation(input, &residual_um, max_lag)?;
    let residual_psd = spectral::welch(&residual_um, &residual_um, fs_hz, segment)?;
    let measured = spectral::h1(input, measured_um, fs_hz, segment)?;
    let model = spectral::h1(input, &model_um, fs_hz, segment)?;
    let band = measured.excited_bins();

    let freq = &measured.spectra.freq_hz;
    let (peak_bin, peak) = residual_psd
        .suu
        .iter()
        .enumerate()
        .skip(1)
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(k, p)| (k, *p))
        .unwrap_or((0, 0.0));
    let gain_err =
        band.iter().filter_map(|&k| Some(spectral::gain_db(model.h[k])? - spectral::gain_db(measured.h[k])?));
    let phase_err = band.iter().map(|&k| {
        spectral::phase_difference_deg(spectral::phase_deg(model.h[k]), spectral::phase_deg(measured.h[k]))
    });
    let frequency_response = FrequencyResponseSummary {
        input: input_name,
        gain_unit,
        band_hz: band.first().zip(band.last()).map(|(a, b)| [freq[*a], freq[*b]]),
        bins: band.len(),
        mean_coherence: (!band.is_empty())
            .then(|| band.iter().map(|&k| measured.coherence[k]).sum::<f64>() / band.len() as f64),
        gain_error_db_rms: rms(gain_err.clone()),
        gain_error_db_max: max_abs(gain_err),
        phase_error_deg_rms: rms(phase_err.clone()),
        phase_error_deg_max: max_abs(phase_err),
    };
    let summary = AnalysisSummary {
        residual_autocorrelation: correlation_summary(&acf, 1, dt_s),
        input_cross_correlation: correlation_summary(&ccf, 0, dt_s),
        residual_spectrum: SpectrumSummary {
            resolution_hz: fs_hz / segment as f64,
            segments: residual_psd.segments,
            peak_hz: freq[peak_bin],
            peak_um2_per_hz: peak,
        },
        frequency_response,
    };
    Ok(FileAnalysis {
        name: rec.name.clone(),
        summary,
        acf,
        ccf,
        residual_psd: residual_psd.suu,
        measured,
        model,
        band,
        dt_s,
    })
}

impl std::fmt::Display for AnalysisSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (a, c) = (&self.residual_autocorrelation, &self.input_cross_correlation);
        writeln!(
            f,
            "  residual ACF: {:.0} % of lags 1..{} outside ±{:.4} (N = {}, 5 % if white); input CCF: {:.0} % of lags 0..{} outside",
            100.0 * a.outside_share,
            a.max_lag,
            a.bound,
            a.samples,
            100.0 * c.outside_share,
            c.max_lag
        )?;
        let r = &self.frequency_response;
        match (r.band_hz, r.gain_error_db_rms, r.phase_error_deg_rms) {
            (Some([lo, hi]), Some(g), Some(p)) => write!(
                f,
                "  frequency response {} → displacement, excited band {lo:.1}–{hi:.1} Hz ({} bins): model − measured gain {g:.2} dB rms, phase {p:.1}° rms",
                r.input, r.bins
            ),
            _ => write!(
                f,
                "  frequency response {}: no excited band (input PSD or coherence too low in {:.1} Hz bins: a drive \
                 below about twice that needs a longer file)",
                r.input, self.residual_spectrum.resolution_hz
            ),
        }
    }
}
