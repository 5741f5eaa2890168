//! Each candidate effect's first-order signature in the baseline's residual (−dy/dt for lags,
//! −ÿ for resonance, sign(dH/dt) for hysteresis, …) and the share of the residual it explains.

use crate::recording::Recording;
use crate::signal::correlation;
use crate::signal::mean;
use crate::simulated::Simulation;
use model_core::effects::Signature;
use model_core::Effect;

/// Signals of one file under the baseline model, for the signatures.
pub(crate) struct Signals {
    pub(crate) residual: Vec<f64>,
    pub(crate) rate: Vec<f64>,
    pub(crate) accel: Vec<f64>,
    pub(crate) branch: Vec<f64>,
    pub(crate) cubic: Vec<f64>,
    pub(crate) creep: Vec<f64>,
    pub(crate) heat: Vec<f64>,
}

impl Signals {
    /// The signals without their first `n` samples (the burn-in).
    pub(crate) fn skip(mut self, n: usize) -> Self {
        for v in [
            &mut self.residual,
            &mut self.rate,
            &mut self.accel,
            &mut self.branch,
            &mut self.cubic,
            &mut self.creep,
            &mut self.heat,
        ] {
            v.drain(..n.min(v.len()));
        }
        self
    }
}

pub(crate) fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a).max(1) as f64 * dt)
        })
        .collect()
}

pub(crate) fn lowpass(x: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let p = (-dt / tau).exp();
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            y = p * y + (1.0 - p) * v;
            y
        })
        .collect()
}

/// The signatures on the displacement (`flux: false`: the baseline's residual with its offset) or
/// on the search coil's flux density (the model's flux fitted to it, [`crate::score::flux_fit`]).
pub(crate) fn signals(rec: &Recording, sim: &Simulation, offset: f64, flux: bool) -> Signals {
    let dt = rec.dt_s();
    // The model's output on the channel, and the measured one.
    let (y, measured): (Vec<f64>, &[f64]) = if flux {
        let b = rec.flux_density_t.as_deref().unwrap_or_default();
        (crate::score::flux_fit(b, &sim.field_a_per_m, &sim.magnetization_a_per_m).1, b)
    } else {
        let y = sim.displacement_um.iter().map(|y| y + offset).collect();
        (y, rec.displacement_um.as_deref().unwrap_or_default())
    };
    let residual: Vec<f64> = measured.iter().zip(&y).map(|(m, y)| m - y).collect();
    let y = y.as_slice();
    let rate = derivative(y, dt);
    let accel = derivative(&rate, dt);
    let h = &sim.field_a_per_m;
    let dh = derivative(h, dt);
    let hscale = dh.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    // Smooth sign of dH/dt: the branch the rod is on.
    let branch: Vec<f64> = dh.iter().map(|v| (v / (0.05 * hscale)).tanh()).collect();
    let hmean = h.iter().sum::<f64>() / h.len() as f64;
    let cubic: Vec<f64> = h.iter().map(|v| (v - hmean).powi(3)).collect();
    let creep = lowpass(y, dt, 0.05).iter().zip(y).map(|(l, v)| l - v).collect();
    let heat = joule_heat(&sim.current_a, dt);
    Signals { residual, rate, accel, branch, cubic, creep, heat }
}

/// The accumulated coil heating ∫i² dt [A² s] of a current sampled every `dt` s: the
/// coil-heating signature (its resistance aside).
pub(crate) fn joule_heat(current: &[f64], dt: f64) -> Vec<f64> {
    let mut acc = 0.0;
    current
        .iter()
        .map(|i| {
            acc += i * i * dt;
            acc
        })
        .collect()
}

/// R² of the least-squares fit of `r` by `a·f + b` (one regressor and a constant).
pub(crate) fn r2(r: &[f64], f: &[f64]) -> f64 {
    correlation(r, f).powi(2)
}

/// Pooled evidence R² of `effect`'s signature over the files (variance-weighted mean).
pub(crate) fn evidence(effect: Effect, sigs: &[Signals]) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for s in sigs {
        let var = s.residual.iter().map(|v| v * v).sum::<f64>();
        let score = match effect.info().signature {
            Signature::Lag => r2(&s.residual, &s.rate),
            Signature::Resonance => r2(&s.residual, &s.accel).max(r2(&s.residual, &s.rate)),
            Signature::Branch => r2(&s.residual, &s.branch),
            Signature::Cubic => r2(&s.residual, &s.cubic),
            Signature::Creep => r2(&s.residual, &s.creep),
            Signature::Heating => r2(&s.residual, &s.heat),
            Signature::None => 0.0,
        };
        num += score * var;
        den += var;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Pooled R² of the coil-heating signature on the logged temperature: the baseline has no
/// heating, so its temperature is a constant and the residual is the temperature's own
/// variation, regressed on the accumulated Joule heat ∫i² dt of the baseline's current.
pub(crate) fn heating_evidence(files: &[Recording], sims: &[Simulation], skip: &[usize]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for ((rec, sim), &k) in files.iter().zip(sims).zip(skip) {
        let t = &rec.temperature_c.as_deref().unwrap_or_default()[k..];
        let heat = joule_heat(&sim.current_a[k..], rec.dt_s());
        let m = mean(t.iter().copied());
        let var = t.iter().map(|v| (v - m) * (v - m)).sum::<f64>();
        num += r2(t, &heat) * var;
        den += var;
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// [`signature_words`] for signatures taken on the flux density.
pub(crate) fn flux_signature_words(signature: Signature) -> &'static str {
    match signature {
        Signature::Lag => "the lag signature −dB/dt of the flux density (shared by the rod's lags)",
        Signature::Creep => "the creep signature lowpass(B) − B of the flux density",
        _ => signature_words(signature),
    }
}

pub(crate) fn signature_words(signature: Signature) -> &'static str {
    match signature {
        Signature::Lag => "the lag signature −dy/dt (shared by every lag: rod, amplifier, sensor)",
        Signature::Resonance => "the resonance signature −ÿ (and −dy/dt)",
        Signature::Branch => "the branch sign(dH/dt) (loop opening)",
        Signature::Cubic => "the cubic field excursion (H − H̄)³",
        Signature::Creep => "the creep signature lowpass(y) − y",
        Signature::Heating => "the accumulated coil heating ∫i² dt",
        Signature::None => "—",
    }
}

/// The recording in which an effect shows (what an engineer adds to the fit files to pin it).
pub(crate) fn where_it_shows(e: Effect) -> &'static str {
    match e {
        Effect::Saturation => "slow loops that reach the knee of the magnetization curve",
        Effect::Hysteresis | Effect::Preisach => "slow loops of several amplitudes, major and minor",
        Effect::EddyCurrent => "broadband drive to kHz (a chirp or multisine), with `current_A` recorded",
        Effect::MechanicalDynamics => "a chirp or multisine across the first resonance",
        Effect::AmplifierDynamics => "`current_A` recorded with a broadband command",
        Effect::MagneticAftereffect => "held steps, each several creep time constants long",
        Effect::ThermalDrift => "minutes at high current, as long as the coil takes to warm",
        Effect::SensorDelay => "broadband drive to kHz, where a delay's phase grows with frequency",
    }
}

/// Residual whiteness: share of autocorrelation lags 1–20 outside the 95 % band, pooled.
pub(crate) fn whiteness(residuals: &[&[f64]]) -> f64 {
    let mut outside = 0usize;
    let mut total = 0usize;
    for r in residuals {
        let n = r.len();
        if n < 2 {
            continue;
        }
        let m = r.iter().sum::<f64>() / n as f64;
        let c0: f64 = r.iter().map(|v| (v - m).powi(2)).sum();
        if c0 <= 0.0 {
            continue;
        }
        let band = 1.96 / (n as f64).sqrt();
        for lag in 1..=20.min(n - 1) {
            let c: f64 = (lag..n).map(|k| (r[k] - m) * (r[k - lag] - m)).sum();
            total += 1;
            if (c / c0).abs() > band {
                outside += 1;
            }
        }
    }
    outside as f64 / total.max(1) as f64
}

/// Whether a share of lags outside the 95 % band is more than white noise gives (5 % plus two
/// binomial standard deviations over the lags tested), and that limit.
pub(crate) fn structured_residual(share: f64, files: usize) -> (bool, f64) {
    let lags = (20 * files).max(1) as f64;
    let limit = 0.05 + 2.0 * (0.05 * 0.95 / lags).sqrt();
    (share > limit, limit)
}
