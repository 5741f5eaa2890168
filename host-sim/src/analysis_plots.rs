//! The residual analysis drawn: correlations with their band, spectra, Bode plots.

use crate::analysis::FileAnalysis;
use crate::plots::{Chart, Series};
use crate::spectral::{self, Correlation, FrequencyResponse};

impl FileAnalysis {
    fn correlation_panel(&self, c: &Correlation, title: &str, label: &str) -> Chart {
        let lag_ms = |k: usize| k as f64 * self.dt_s * 1e3;
        let end = lag_ms(c.r.len() - 1);
        Chart {
            title: format!("{} — {title}", self.name),
            x_label: "lag [ms]".into(),
            y_label: "correlation [1]".into(),
            y_range: None,
            series: vec![
                Series {
                    label: label.into(),
                    points: c.r.iter().enumerate().map(|(k, r)| (lag_ms(k), *r)).collect(),
                    color: 2,
                },
                Series {
                    label: format!("±1.96/√N (N = {})", c.samples),
                    points: vec![(0.0, c.bound), (end, c.bound)],
                    color: 1,
                },
                Series { label: String::new(), points: vec![(0.0, -c.bound), (end, -c.bound)], color: 1 },
            ],
        }
    }

    /// The correlation plot: residual autocorrelation above, input cross-correlation below.
    pub fn correlation_charts(&self) -> Vec<Chart> {
        let input = self.summary.frequency_response.input;
        vec![
            self.correlation_panel(&self.acf, "residual autocorrelation", "r_ee(τ)"),
            self.correlation_panel(&self.ccf, &format!("{input} to residual cross-correlation"), "r_ue(τ)"),
        ]
    }

    /// The residual spectrum, with the measured displacement's for scale [dB re 1 µm²/Hz].
    pub fn spectrum_chart(&self) -> Chart {
        let db = |p: f64| 10.0 * p.max(1e-30).log10();
        let f = &self.measured.spectra.freq_hz;
        let line = |psd: &[f64]| f.iter().zip(psd).skip(1).map(|(f, p)| (*f, db(*p))).collect::<Vec<_>>();
        Chart {
            title: format!("{} — residual spectrum (Welch, Hann, 50 % overlap)", self.name),
            x_label: "frequency [Hz]".into(),
            y_label: "PSD [dB re 1 µm²/Hz]".into(),
            y_range: None,
            series: vec![
                Series {
                    label: "measured displacement".into(),
                    points: line(&self.measured.spectra.syy),
                    color: 0,
                },
                Series { label: "residual".into(), points: line(&self.residual_psd), color: 2 },
            ],
        }
    }

    /// The Bode plot over the excited band: gain, phase (unwrapped) and measured coherence.
    pub fn bode_charts(&self, model_label: &str) -> Vec<Chart> {
        let fr = &self.summary.frequency_response;
        let f = &self.measured.spectra.freq_hz;
        // Without an excited band the panels are empty: the title says why, short enough to show.
        let title = if self.band.is_empty() {
            format!(
                "{} — H1 {}: no excited band in {:.0} Hz bins",
                self.name, fr.input, self.summary.residual_spectrum.resolution_hz
            )
        } else {
            format!("{} — frequency response {} to displacement (H1)", self.name, fr.input)
        };
        let gain = |h: &FrequencyResponse| {
            self.band.iter().filter_map(|&k| Some((f[k], spectral::gain_db(h.h[k])?))).collect::<Vec<_>>()
        };
        let phase = |h: &FrequencyResponse| {
            let p: Vec<f64> = self.band.iter().map(|&k| spectral::phase_deg(h.h[k])).collect();
            self.band.iter().map(|&k| f[k]).zip(spectral::unwrap_deg(&p)).collect::<Vec<_>>()
        };
        let unit = fr.gain_unit.replace("um", "µm").replace("_per_", "/");
        vec![
            Chart {
                title,
                x_label: "frequency [Hz]".into(),
                y_label: format!("gain [dB re 1 {unit}]"),
                y_range: None,
                series: vec![
                    Series { label: "measured".into(), points: gain(&self.measured), color: 0 },
                    Series { label: format!("model {model_label}"), points: gain(&self.model), color: 1 },
                ],
            },
            Chart {
                title: String::new(),
                x_label: "frequency [Hz]".into(),
                y_label: "phase [deg]".into(),
                y_range: None,
                series: vec![
                    Series { label: "measured".into(), points: phase(&self.measured), color: 0 },
                    Series { label: format!("model {model_label}"), points: phase(&self.model), color: 1 },
                ],
            },
            Chart {
                title: String::new(),
                x_label: "frequency [Hz]".into(),
                y_label: "coherence γ² [1]".into(),
                y_range: Some((0.0, 1.0)),
                series: vec![Series {
                    label: "measured".into(),
                    points: self.band.iter().map(|&k| (f[k], self.measured.coherence[k])).collect(),
                    color: 2,
                }],
            },
        ]
    }
}
