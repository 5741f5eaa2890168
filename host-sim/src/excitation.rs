//! Excitation signals for the plant simulator: the drive (coil current [A], or amplifier
//! command [V] when the plant has an amplifier) as a function of time.

use std::f64::consts::PI;

use anyhow::{bail, Result};

/// A drive waveform; `bias` is the DC level added to every shape.
#[derive(Debug, Clone, PartialEq)]
pub enum Excitation {
    /// bias + amplitude · sin(2π f t).
    Sine {
        /// Frequency [Hz].
        freq_hz: f64,
        /// Amplitude.
        amplitude: f64,
        /// DC level.
        bias: f64,
    },
    /// Linear chirp from `f0_hz` to `f1_hz` over the duration.
    Chirp {
        /// Start frequency [Hz].
        f0_hz: f64,
        /// End frequency [Hz].
        f1_hz: f64,
        /// Amplitude.
        amplitude: f64,
        /// DC level.
        bias: f64,
    },
    /// Sum of sines with Schroeder phases (low crest factor), total peak ≈ amplitude.
    Multisine {
        /// Frequencies [Hz].
        freqs_hz: Vec<f64>,
        /// Peak amplitude.
        amplitude: f64,
        /// DC level.
        bias: f64,
    },
    /// bias ± amplitude, period 1/f (steps).
    Square {
        /// Frequency [Hz].
        freq_hz: f64,
        /// Amplitude.
        amplitude: f64,
        /// DC level.
        bias: f64,
    },
    /// Sine whose amplitude ramps linearly from `from` to `to` over the duration.
    AmplitudeSweep {
        /// Frequency [Hz].
        freq_hz: f64,
        /// Amplitude at the start.
        from: f64,
        /// Amplitude at the end.
        to: f64,
        /// DC level.
        bias: f64,
    },
}

impl Excitation {
    /// Checks frequencies and amplitudes are finite and positive where they must be.
    pub fn validate(&self) -> Result<()> {
        let finite = |name: &str, v: f64| -> Result<()> {
            if !v.is_finite() {
                bail!("excitation {name} must be a finite number, got {v}");
            }
            Ok(())
        };
        let positive = |name: &str, v: f64| -> Result<()> {
            if !(v.is_finite() && v > 0.0) {
                bail!("excitation {name} must be > 0, got {v}");
            }
            Ok(())
        };
        match self {
            Excitation::Sine { freq_hz, amplitude, bias }
            | Excitation::Square { freq_hz, amplitude, bias } => {
                positive("frequency [Hz]", *freq_hz)?;
                finite("amplitude", *amplitude)?;
                finite("bias", *bias)
            }
            Excitation::Chirp { f0_hz, f1_hz, amplitude, bias } => {
                positive("start frequency [Hz]", *f0_hz)?;
                positive("end frequency [Hz]", *f1_hz)?;
                finite("amplitude", *amplitude)?;
                finite("bias", *bias)
            }
            Excitation::Multisine { freqs_hz, amplitude, bias } => {
                if freqs_hz.is_empty() {
                    bail!("a multisine needs at least one frequency");
                }
                for f in freqs_hz {
                    positive("frequency [Hz]", *f)?;
                }
                finite("amplitude", *amplitude)?;
                finite("bias", *bias)
            }
            Excitation::AmplitudeSweep { freq_hz, from, to, bias } => {
                positive("frequency [Hz]", *freq_hz)?;
                finite("start amplitude", *from)?;
                finite("end amplitude", *to)?;
                finite("bias", *bias)
            }
        }
    }

    /// The drive at time `t` of a record lasting `duration_s`.
    pub fn value(&self, t: f64, duration_s: f64) -> f64 {
        match self {
            Excitation::Sine { freq_hz, amplitude, bias } => {
                bias + amplitude * (2.0 * PI * freq_hz * t).sin()
            }
            Excitation::Chirp { f0_hz, f1_hz, amplitude, bias } => {
                let k = (f1_hz - f0_hz) / duration_s.max(1e-12);
                bias + amplitude * (2.0 * PI * (f0_hz * t + 0.5 * k * t * t)).sin()
            }
            Excitation::Multisine { freqs_hz, amplitude, bias } => {
                let n = freqs_hz.len() as f64;
                let sum: f64 = freqs_hz
                    .iter()
                    .enumerate()
                    .map(|(k, f)| {
                        let phase = -PI * (k as f64) * (k as f64 + 1.0) / n; // Schroeder
                        (2.0 * PI * f * t + phase).sin()
                    })
                    .sum();
                bias + amplitude * sum / n.sqrt() / 1.6
            }
            Excitation::Square { freq_hz, amplitude, bias } => {
                let s = if (freq_hz * t).fract() < 0.5 { 1.0 } else { -1.0 };
                bias + amplitude * s
            }
            Excitation::AmplitudeSweep { freq_hz, from, to, bias } => {
                let a = from + (to - from) * (t / duration_s.max(1e-12)).clamp(0.0, 1.0);
                bias + a * (2.0 * PI * freq_hz * t).sin()
            }
        }
    }

    /// A short description for reports, the drive's levels in `unit` ("sine 50 Hz, 1 ± 0.5 A").
    pub fn describe(&self, unit: &str) -> String {
        match self {
            Excitation::Sine { freq_hz, amplitude, bias } => {
                format!("sine {freq_hz} Hz, {bias} ± {amplitude} {unit}")
            }
            Excitation::Chirp { f0_hz, f1_hz, amplitude, bias } => {
                format!("chirp {f0_hz}–{f1_hz} Hz, {bias} ± {amplitude} {unit}")
            }
            Excitation::Multisine { freqs_hz, amplitude, bias } => {
                format!(
                    "multisine {} tones {:.0}–{:.0} Hz, {bias} ± {amplitude} {unit}",
                    freqs_hz.len(),
                    freqs_hz[0],
                    freqs_hz[freqs_hz.len() - 1]
                )
            }
            Excitation::Square { freq_hz, amplitude, bias } => {
                format!("square {freq_hz} Hz, {bias} ± {amplitude} {unit}")
            }
            Excitation::AmplitudeSweep { freq_hz, from, to, bias } => {
                format!("sine {freq_hz} Hz, amplitude {from} → {to} {unit}, bias {bias} {unit}")
            }
        }
    }
}
