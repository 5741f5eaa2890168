//! Drive waveforms, evaluated in continuous time (value and time derivative).

use crate::{Drive, RigError, Waveform};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha20Rng;
use std::f64::consts::PI;

/// A waveform made ready to evaluate over a run of `duration_s`.
#[derive(Clone, Debug)]
pub struct Signal {
    kind: Kind,
    amplitude: f64,
    offset: f64,
}

#[derive(Clone, Debug)]
enum Kind {
    Sine(f64),
    Square { f: f64, rise: f64 },
    Steps { levels: Vec<f64>, hold: f64 },
    Multi { freqs: Vec<f64>, phases: Vec<f64>, scale: f64 },
    Chirp { f0: f64, f1: f64, log: bool, dur: f64 },
}

fn multisine(freqs: &[f64], ph: &[f64], t: f64) -> (f64, f64) {
    let mut v = 0.0;
    let mut d = 0.0;
    for (f, p) in freqs.iter().zip(ph) {
        let w = 2.0 * PI * f;
        v += (w * t + p).sin();
        d += w * (w * t + p).cos();
    }
    (v, d)
}

impl Signal {
    /// Prepare `drive` for a run of `duration_s`; `seed` draws the multisine phases.
    pub fn new(drive: &Drive, duration_s: f64, seed: u64) -> Result<Signal, RigError> {
        let bad = |s: &str| Err(RigError::BadParameter(format!("waveform: {s}")));
        if !drive.amplitude.is_finite() || !drive.offset.is_finite() {
            return bad("amplitude and offset must be finite");
        }
        let kind = match &drive.waveform {
            Waveform::Sine { freq_hz } => {
                if !(*freq_hz > 0.0 && freq_hz.is_finite()) {
                    return bad("sine frequency must be > 0");
                }
                Kind::Sine(*freq_hz)
            }
            Waveform::Square { freq_hz, rise_s } => {
                if !(*freq_hz > 0.0) || !(*rise_s >= 0.0) || *rise_s >= 0.5 / freq_hz {
                    return bad("square: frequency > 0 and 0 <= rise < half period");
                }
                Kind::Square { f: *freq_hz, rise: *rise_s }
            }
            Waveform::Steps { levels, hold_s } => {
                if levels.is_empty() || !(*hold_s > 0.0) {
                    return bad("steps: at least one level and hold_s > 0");
                }
                Kind::Steps { levels: levels.clone(), hold: *hold_s }
            }
            Waveform::Multisine { f_lo_hz, f_hi_hz, tones } => {
                if *tones == 0 || !(*f_lo_hz > 0.0) || f_hi_hz < f_lo_hz {
                    return bad("multisine: tones >= 1 and 0 < f_lo <= f_hi");
                }
                let n = *tones;
                let freqs: Vec<f64> = (0..n)
                    .map(|k| {
                        if n == 1 {
                            *f_lo_hz
                        } else {
                            f_lo_hz + (f_hi_hz - f_lo_hz) * k as f64 / (n - 1) as f64
                        }
                    })
                    .collect();
                // Crest-factor control: 32 random phase sets from the seed, the one of lowest
                // peak kept, then scaled to a peak of 1 over the evaluation window.
                let mut rng = ChaCha20Rng::seed_from_u64(seed ^ 0x6d75_6c74_6973_696e);
                let window = (2.0 / f_lo_hz).min(duration_s.max(1.0 / f_lo_hz));
                let grid = 20_000;
                let mut best: Option<(f64, Vec<f64>)> = None;
                for _ in 0..32 {
                    let ph: Vec<f64> = (0..n).map(|_| rng.random::<f64>() * 2.0 * PI).collect();
                    let peak = (0..=grid)
                        .map(|i| multisine(&freqs, &ph, window * i as f64 / grid as f64).0.abs())
                        .fold(0.0, f64::max);
                    if best.as_ref().is_none_or(|(p, _)| peak < *p) {
                        best = Some((peak, ph));
                    }
                }
                let (peak, phases) = best.expect("32 candidates");
                Kind::Multi { freqs, phases, scale: 1.0 / peak }
            }
            Waveform::Chirp { f0_hz, f1_hz, log } => {
                if !(*f0_hz > 0.0) || !(*f1_hz > 0.0) {
                    return bad("chirp: frequencies > 0");
                }
                Kind::Chirp { f0: *f0_hz, f1: *f1_hz, log: *log, dur: duration_s.max(1e-12) }
            }
        };
        Ok(Signal { kind, amplitude: drive.amplitude, offset: drive.offset })
    }

    /// Normalised shape s(t) in about [−1, 1] and its derivative.
    fn shape(&self, t: f64) -> (f64, f64) {
        match &self.kind {
            Kind::Sine(f) => {
                let w = 2.0 * PI * f;
                ((w * t).sin(), w * (w * t).cos())
            }
            Kind::Square { f, rise } => {
                let period = 1.0 / f;
                let ph = t.rem_euclid(period);
                let half = 0.5 * period;
                if ph < *rise {
                    let x = PI * ph / rise;
                    (-x.cos(), PI / rise * x.sin())
                } else if ph < half {
                    (1.0, 0.0)
                } else if ph < half + rise {
                    let x = PI * (ph - half) / rise;
                    (x.cos(), -PI / rise * x.sin())
                } else {
                    (-1.0, 0.0)
                }
            }
            Kind::Steps { levels, hold } => {
                let k = (t / hold).floor().max(0.0) as usize;
                (levels[k % levels.len()], 0.0)
            }
            Kind::Multi { freqs, phases, scale } => {
                let (v, d) = multisine(freqs, phases, t);
                (v * scale, d * scale)
            }
            Kind::Chirp { f0, f1, log, dur } => {
                let (phase, freq) = if *log && (f1 - f0).abs() > 1e-12 * f0 {
                    let r = (f1 / f0).ln();
                    let k = (r * t / dur).exp();
                    (2.0 * PI * f0 * dur / r * (k - 1.0), f0 * k)
                } else {
                    let c = (f1 - f0) / dur;
                    (2.0 * PI * (f0 * t + 0.5 * c * t * t), f0 + c * t)
                };
                (phase.sin(), 2.0 * PI * freq * phase.cos())
            }
        }
    }

    /// The drive's value (V or A) at `t`.
    pub fn value(&self, t: f64) -> f64 {
        self.offset + self.amplitude * self.shape(t).0
    }

    /// Value and time derivative at `t`.
    pub fn value_rate(&self, t: f64) -> (f64, f64) {
        let (s, d) = self.shape(t);
        (self.offset + self.amplitude * s, self.amplitude * d)
    }

    /// Times in (t0, t1) where the waveform or its derivative jumps (the solver stops there).
    pub fn breaks(&self, t0: f64, t1: f64) -> Vec<f64> {
        let mut v = Vec::new();
        let mut push_grid = |base: f64, period: f64| {
            let mut k = ((t0 - base) / period).floor() - 1.0;
            loop {
                let t = base + k * period;
                if t >= t1 {
                    break;
                }
                if t > t0 {
                    v.push(t);
                }
                k += 1.0;
            }
        };
        match &self.kind {
            Kind::Square { f, rise } => {
                let p = 1.0 / f;
                push_grid(0.0, p);
                push_grid(0.5 * p, p);
                if *rise > 0.0 {
                    push_grid(*rise, p);
                    push_grid(0.5 * p + rise, p);
                }
            }
            Kind::Steps { hold, .. } => push_grid(0.0, *hold),
            _ => {}
        }
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    }
}
