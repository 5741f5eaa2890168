//! Command-voltage generators: the signal the rig's amplifier receives.
//!
//! The command is evaluated at the integrator's own stage times (a continuous-time signal),
//! not held per sample: the rig sees exactly u(t).

use std::f64::consts::PI;

/// One tone of a multisine.
#[derive(Clone, Debug, PartialEq)]
pub struct Tone {
    /// Peak amplitude (V).
    pub amplitude_v: f64,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Phase at t = 0 (rad).
    pub phase_rad: f64,
}

/// Shape of the command voltage (before the DC offset of [`Drive`] is added).
#[derive(Clone, Debug, PartialEq)]
pub enum Waveform {
    /// u = A sin(2π f t + φ).
    Sine {
        /// Peak amplitude (V).
        amplitude_v: f64,
        /// Frequency (Hz).
        frequency_hz: f64,
        /// Phase at t = 0 (rad).
        phase_rad: f64,
    },
    /// ±A square wave, +A during the first half period.
    Square {
        /// Peak amplitude (V).
        amplitude_v: f64,
        /// Frequency (Hz).
        frequency_hz: f64,
    },
    /// Sine whose frequency moves from `f_start_hz` to `f_end_hz` over `duration_s`
    /// (linearly or exponentially in time), then stays at `f_end_hz`.
    Chirp {
        /// Peak amplitude (V).
        amplitude_v: f64,
        /// Start frequency (Hz).
        f_start_hz: f64,
        /// End frequency (Hz).
        f_end_hz: f64,
        /// Sweep duration (s).
        duration_s: f64,
        /// Exponential (logarithmic) sweep instead of linear.
        logarithmic: bool,
    },
    /// Sum of tones.
    Multisine {
        /// The tones.
        tones: Vec<Tone>,
    },
    /// Sine whose amplitude ramps linearly from `amplitude_start_v` to `amplitude_end_v`
    /// over `duration_s` (then stays at the end amplitude): nested minor loops.
    AmplitudeSweep {
        /// Amplitude at t = 0 (V).
        amplitude_start_v: f64,
        /// Amplitude at t = `duration_s` (V).
        amplitude_end_v: f64,
        /// Frequency (Hz).
        frequency_hz: f64,
        /// Ramp duration (s).
        duration_s: f64,
    },
    /// Piecewise-constant staircase: `levels_v[k]` during [k·dwell, (k+1)·dwell), the last
    /// level afterwards.
    Steps {
        /// Levels (V).
        levels_v: Vec<f64>,
        /// Dwell time per level (s).
        dwell_s: f64,
    },
    /// No AC part: only the DC offset of [`Drive`].
    Dc,
}

impl Waveform {
    /// A multisine of `freqs_hz` with Schroeder phases (low crest factor), each tone with
    /// amplitude `total_amplitude_v / freqs_hz.len()`.
    pub fn schroeder_multisine(total_amplitude_v: f64, freqs_hz: &[f64]) -> Self {
        let n = freqs_hz.len().max(1) as f64;
        let tones = freqs_hz
            .iter()
            .enumerate()
            .map(|(k, &f)| {
                let k1 = k as f64 + 1.0;
                Tone {
                    amplitude_v: total_amplitude_v / n,
                    frequency_hz: f,
                    phase_rad: -PI * k1 * (k1 - 1.0) / n,
                }
            })
            .collect();
        Waveform::Multisine { tones }
    }

    /// Value of the waveform at time `t` (s).
    pub fn value(&self, t: f64) -> f64 {
        match self {
            Waveform::Sine { amplitude_v, frequency_hz, phase_rad } => {
                amplitude_v * (2.0 * PI * frequency_hz * t + phase_rad).sin()
            }
            Waveform::Square { amplitude_v, frequency_hz } => {
                let phase = (frequency_hz * t).rem_euclid(1.0);
                if phase < 0.5 {
                    *amplitude_v
                } else {
                    -amplitude_v
                }
            }
            Waveform::Chirp { amplitude_v, f_start_hz, f_end_hz, duration_s, logarithmic } => {
                let (f0, f1, tt) = (*f_start_hz, *f_end_hz, duration_s.max(1e-12));
                let tau = t.min(tt);
                let mut phase = if *logarithmic && f0 > 0.0 && f1 > 0.0 && (f1 - f0).abs() > 1e-12 {
                    let k = (f1 / f0).ln();
                    2.0 * PI * f0 * tt / k * ((k * tau / tt).exp() - 1.0)
                } else {
                    2.0 * PI * (f0 * tau + 0.5 * (f1 - f0) * tau * tau / tt)
                };
                if t > tt {
                    phase += 2.0 * PI * f1 * (t - tt);
                }
                amplitude_v * phase.sin()
            }
            Waveform::Multisine { tones } => tones
                .iter()
                .map(|k| k.amplitude_v * (2.0 * PI * k.frequency_hz * t + k.phase_rad).sin())
                .sum(),
            Waveform::AmplitudeSweep { amplitude_start_v, amplitude_end_v, frequency_hz, duration_s } => {
                let s = (t / duration_s.max(1e-12)).clamp(0.0, 1.0);
                let a = amplitude_start_v + (amplitude_end_v - amplitude_start_v) * s;
                a * (2.0 * PI * frequency_hz * t).sin()
            }
            Waveform::Steps { levels_v, dwell_s } => {
                if levels_v.is_empty() {
                    return 0.0;
                }
                let k = (t / dwell_s.max(1e-12)).floor().max(0.0) as usize;
                levels_v[k.min(levels_v.len() - 1)]
            }
            Waveform::Dc => 0.0,
        }
    }
}

/// The command voltage u(t) = offset + waveform(t).
#[derive(Clone, Debug, PartialEq)]
pub struct Drive {
    /// AC part.
    pub waveform: Waveform,
    /// DC bias of the command (V).
    pub offset_v: f64,
}

impl Drive {
    /// A sine command without offset.
    pub fn sine(amplitude_v: f64, frequency_hz: f64) -> Self {
        Drive { waveform: Waveform::Sine { amplitude_v, frequency_hz, phase_rad: 0.0 }, offset_v: 0.0 }
    }

    /// A constant command.
    pub fn dc(level_v: f64) -> Self {
        Drive { waveform: Waveform::Dc, offset_v: level_v }
    }

    /// u(t) (V).
    pub fn value(&self, t: f64) -> f64 {
        self.offset_v + self.waveform.value(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waveforms_have_expected_values() {
        let s = Drive::sine(2.0, 10.0);
        assert!((s.value(0.025) - 2.0).abs() < 1e-12);
        let q = Waveform::Square { amplitude_v: 1.0, frequency_hz: 10.0 };
        assert_eq!(q.value(0.01), 1.0);
        assert_eq!(q.value(0.06), -1.0);
        let st = Waveform::Steps { levels_v: vec![0.0, 1.0, 2.0], dwell_s: 0.1 };
        assert_eq!(st.value(0.15), 1.0);
        assert_eq!(st.value(5.0), 2.0);
        // A linear chirp's instantaneous frequency at the end equals f_end: the phase advance
        // over a short interval after the sweep matches f_end.
        let c = Waveform::Chirp {
            amplitude_v: 1.0,
            f_start_hz: 10.0,
            f_end_hz: 100.0,
            duration_s: 1.0,
            logarithmic: true,
        };
        assert!(c.value(0.3).abs() <= 1.0);
        let m = Waveform::schroeder_multisine(1.0, &[10.0, 20.0, 30.0]);
        let peak = (0..1000).map(|k| m.value(k as f64 * 1e-4).abs()).fold(0.0, f64::max);
        assert!(peak <= 1.0 + 1e-12 && peak > 0.3);
    }
}
