//! The scored channels: each file after its burn-in, on the measured channel nearest where an
//! effect acts (current, flux density or displacement), and whether an effect shows there.

use super::signatures::derivative;
use super::signatures::r2;
use crate::recording::Recording;
use crate::signal::reversal_positions;
use crate::simulation::simulate;
use anyhow::Result;
use model_core::effects::Stage;
use model_core::{Effect, ModelSpec};
use rayon::prelude::*;

/// Samples left out of every score at the start of a file: the rig's initial magnetic state is
/// unknown (a real rod is not demagnetised), so the first full cycle of the drive (up to its
/// second reversal) is a burn-in, at most half the file.
pub fn burn_in(rec: &Recording) -> usize {
    let drive = rec.current_a.as_deref().or(rec.command_v.as_deref()).unwrap_or_default();
    reversal_positions(drive).get(1).copied().unwrap_or(0).min(rec.len() / 2)
}

/// A residual after the burn-in (offset removed) and its NRMSE.
#[derive(Debug, Clone)]
pub(crate) struct Scored {
    pub(crate) residual: Vec<f64>,
    pub(crate) nrmse: f64,
}

pub(crate) fn scored(measured: &[f64], model: &[f64], skip: usize) -> Scored {
    let (m, y) = (&measured[skip..], &model[skip..]);
    let n = m.len().max(1) as f64;
    let offset = m.iter().zip(y).map(|(a, b)| a - b).sum::<f64>() / n;
    let residual: Vec<f64> = m.iter().zip(y).map(|(a, b)| a - b - offset).collect();
    let (lo, hi) = m.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let rms = (residual.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    Scored { residual, nrmse: rms / (hi - lo).max(1e-12) }
}

/// The channel a candidate is scored on.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Channel {
    Displacement,
    Current,
    /// A search coil's flux density: what the field and magnetization stages act on, before the
    /// mechanics, the thermal elongation and the displacement probe.
    FluxDensity,
    /// A logged `temperature_C`: what coil heating acts on before the rod expands.
    Temperature,
}

impl Channel {
    /// The contract's name.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Channel::Displacement => "displacement",
            Channel::Current => "current",
            Channel::FluxDensity => "flux_density",
            Channel::Temperature => "temperature",
        }
    }

    /// The measured channel nearest where `e` acts: the amplifier's on the current, the rod's
    /// field, magnetization and creep on the flux density, coil heating on the temperature, the
    /// rest on the displacement — when every file measured that channel.
    pub(crate) fn judging(e: Effect, measured: Measured) -> Channel {
        match e.info().stage {
            Stage::Amplifier if measured.current => Channel::Current,
            Stage::Thermal if measured.temperature => Channel::Temperature,
            Stage::RodField | Stage::Magnetization | Stage::MagnetizationCreep if measured.flux => {
                Channel::FluxDensity
            }
            _ => Channel::Displacement,
        }
    }
}

/// The channels besides the displacement that every file measured.
#[derive(Clone, Copy)]
pub(crate) struct Measured {
    /// `current_A` and `command_V`: the amplifier is judged command → current.
    pub(crate) current: bool,
    /// `flux_density_T` (a search coil).
    pub(crate) flux: bool,
    /// `temperature_C` (the coil's).
    pub(crate) temperature: bool,
}

/// The channels besides the displacement: their columns, whether a file logs them, and what they
/// judge.
pub(crate) const CHANNELS: [(&str, Logs, &str); 3] = [
    ("current_A and command_V", |r| r.current_a.is_some() && r.command_v.is_some(), "amplifier dynamics"),
    (
        "flux_density_T",
        |r| r.flux_density_t.is_some(),
        "the rod's field, magnetization and creep effects (and the laws and J–A forms compared)",
    ),
    ("temperature_C", |r| r.temperature_c.is_some(), "coil heating"),
];

impl Measured {
    /// Findings for channels some files log and others do not: each judges its effects only
    /// when every file has it, and falls back to the displacement silently otherwise.
    pub(crate) fn partly(fit_files: &[Recording], score_files: &[Recording]) -> Vec<String> {
        let files: Vec<&Recording> = fit_files.iter().chain(score_files).collect();
        CHANNELS
            .iter()
            .filter_map(|(name, logs, what)| {
                let lacking: Vec<&str> = files.iter().filter(|r| !logs(r)).map(|r| r.name.as_str()).collect();
                (!lacking.is_empty() && lacking.len() < files.len()).then(|| {
                    format!(
                        "{name}: logged in some files but not in {}: {what} judged on the displacement (that channel \
                         is used only when every fit and scored file has it)",
                        lacking.join(", ")
                    )
                })
            })
            .collect()
    }

    /// What every fit and scored file logs.
    pub(crate) fn in_every(fit_files: &[Recording], score_files: &[Recording]) -> Self {
        let [current, flux, temperature] =
            CHANNELS.map(|(_, logs, _)| fit_files.iter().chain(score_files).all(logs));
        Measured { current, flux, temperature }
    }
}

/// Per file, the scored residual on `channel` after the file's burn-in `skip`.
pub(crate) fn channel_scores(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    files: &[Recording],
    skip: &[usize],
    channel: Channel,
) -> Result<Vec<Scored>> {
    files
        .par_iter()
        .zip(skip)
        .map(|(rec, &k)| {
            let sim = simulate(spec, params, rec)?;
            Ok(match channel {
                Channel::Displacement => {
                    scored(rec.displacement_um.as_deref().unwrap_or_default(), &sim.displacement_um, k)
                }
                Channel::Current => scored(rec.current_a.as_deref().unwrap_or_default(), &sim.current_a, k),
                Channel::FluxDensity => {
                    // Scale and zero fitted on the scored part, as the offset is.
                    let b = &rec.flux_density_t.as_deref().unwrap_or_default()[k..];
                    let (_, model) =
                        crate::score::flux_fit(b, &sim.field_a_per_m[k..], &sim.magnetization_a_per_m[k..]);
                    scored(b, &model, 0)
                }
                Channel::Temperature => {
                    // The ambient fitted on the scored part, as the offset is.
                    let t = &rec.temperature_c.as_deref().unwrap_or_default()[k..];
                    let rise = sim.temperature_rise_c.get(k..).unwrap_or_default();
                    scored(t, &crate::score::temperature_fit(t, rise).1, 0)
                }
            })
        })
        .collect()
}

pub(crate) fn displacement_scores(
    spec: ModelSpec,
    params: &model_core::ActuatorParams,
    files: &[Recording],
    skip: &[usize],
) -> Result<Vec<Scored>> {
    channel_scores(spec, params, files, skip, Channel::Displacement)
}

/// Whether an effect shows in a file: the refit's prediction with the effect switched off
/// (residual `off`) differs from the refit's (residual `on`; both measured − model, offsets
/// removed) by more, in rms, than the file's measurement noise. The noise is estimated from the
/// refit's residual by its successive differences (von Neumann; Rice 1984): σ² ≈ Σ (r_k −
/// r_{k−1})² / 2(N − 1), which white noise passes whole and a slow model error hardly at all (a
/// fast one raises the estimate: the test then errs towards not counting the file).
pub(crate) fn effect_shows(off: &[f64], on: &[f64]) -> bool {
    let n = on.len().max(1) as f64;
    let d: Vec<f64> = off.iter().zip(on).map(|(a, b)| a - b).collect();
    let mean_d = d.iter().sum::<f64>() / n;
    let change = d.iter().map(|v| (v - mean_d) * (v - mean_d)).sum::<f64>() / n;
    let noise =
        on.windows(2).map(|w| (w[1] - w[0]) * (w[1] - w[0])).sum::<f64>() / (2.0 * (n - 1.0).max(1.0));
    change > noise
}

/// Σ_f N_eff,f ln(MSE_before,f / MSE_after,f): the Gaussian log-likelihood gain of a refit with
/// each file's effective sample size (the baseline's).
/// `n_eff` holds each file's effective samples of the baseline's residual (computed once by the
/// caller, who also needs their sum for the penalty).
pub(crate) fn information_gain(before: &[Scored], after: &[Scored], n_eff: &[f64]) -> f64 {
    before
        .iter()
        .zip(after)
        .zip(n_eff)
        .map(|((b, a), n)| {
            let mse =
                |s: &Scored| s.residual.iter().map(|v| v * v).sum::<f64>() / s.residual.len().max(1) as f64;
            n * (mse(b).max(1e-300) / mse(a).max(1e-300)).ln()
        })
        .sum()
}

/// The baseline of the current channel: i = g·u + b (least squares over the fit files).
pub(crate) struct StaticGain {
    pub(crate) gain: f64,
    pub(crate) offset: f64,
}

impl StaticGain {
    pub(crate) fn fit(files: &[Recording], skip: &[usize]) -> Self {
        let (mut n, mut su, mut si, mut suu, mut sui) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for (rec, &k) in files.iter().zip(skip) {
            let (Some(u), Some(i)) = (rec.command_v.as_deref(), rec.current_a.as_deref()) else { continue };
            for (u, i) in u[k..].iter().zip(&i[k..]) {
                n += 1.0;
                su += u;
                si += i;
                suu += u * u;
                sui += u * i;
            }
        }
        let var = suu - su * su / n.max(1.0);
        let gain = if var > 0.0 { (sui - su * si / n) / var } else { 0.0 };
        StaticGain { gain, offset: (si - gain * su) / n.max(1.0) }
    }

    pub(crate) fn model(&self, rec: &Recording) -> Vec<f64> {
        rec.command_v.as_deref().unwrap_or_default().iter().map(|u| self.gain * u + self.offset).collect()
    }

    pub(crate) fn scores(&self, files: &[Recording], skip: &[usize]) -> Vec<Scored> {
        files
            .iter()
            .zip(skip)
            .map(|(rec, &k)| scored(rec.current_a.as_deref().unwrap_or_default(), &self.model(rec), k))
            .collect()
    }

    /// Pooled R² of the static residual by the lag signature −d(g·u)/dt.
    pub(crate) fn lag_evidence(&self, files: &[Recording], skip: &[usize]) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (rec, &k) in files.iter().zip(skip) {
            let model = self.model(rec);
            let s = scored(rec.current_a.as_deref().unwrap_or_default(), &model, k);
            let rate = derivative(&model, rec.dt_s());
            let var: f64 = s.residual.iter().map(|v| v * v).sum();
            num += r2(&s.residual, &rate[k..]) * var;
            den += var;
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }
}

/// Whether a file logs a channel's columns.
pub(crate) type Logs = fn(&Recording) -> bool;
