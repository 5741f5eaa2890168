//! How well a run matches its recording: NRMSE per measured channel, the displacement offset in
//! closed form, the flux density's zero and magnetization scale, the coil temperature's fit.

use model_core::{Effect, ModelSpec};

use crate::channels::{FLUX_SCALE_RANGE, MU0};
use crate::recording::Recording;
use crate::simulated::Simulation;

/// How well a model matches one file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FileScore {
    /// NRMSE of the displacement (offset removed).
    pub nrmse: f64,
    /// NRMSE of the current channel, when the model predicts a measured current.
    pub nrmse_current: Option<f64>,
    /// The flux density's fit, when the file measured it.
    pub flux: Option<FluxFit>,
    /// The coil temperature's fit, when the model has coil heating and the file logged it.
    pub temperature: Option<TemperatureFit>,
    /// Fitted displacement offset [µm].
    pub offset_um: f64,
    /// The initial state's excursion [A/m] (`None`: a law without memory).
    pub initial_excursion_a_per_m: Option<f64>,
}

/// rms(a − b) / (max − min of a).
pub fn nrmse(measured: &[f64], model: &[f64]) -> f64 {
    let (lo, hi) = measured.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let mse = measured.iter().zip(model).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / measured.len() as f64;
    mse.sqrt() / (hi - lo).max(1e-12)
}

/// MATLAB's `compare` fit, 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) [%], of a model whose [`nrmse`] against
/// `measured` is `nrmse` (the same residual: ‖y − ŷ‖ = √n · nrmse · range): 100 for a perfect
/// model, 0 for one no better than the measured mean, negative for one worse. `None` for a
/// constant channel.
pub fn fit_percent(measured: &[f64], nrmse: f64) -> Option<f64> {
    let n = measured.len().max(1) as f64;
    let (lo, hi) = measured.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let mean = measured.iter().sum::<f64>() / n;
    let rms_about_mean = (measured.iter().map(|y| (y - mean) * (y - mean)).sum::<f64>() / n).sqrt();
    let fit = 100.0 * (1.0 - nrmse * (hi - lo).max(1e-12) / rms_about_mean);
    fit.is_finite().then_some(fit)
}

/// How the model's magnetization matches a measured flux density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FluxFit {
    /// NRMSE of the flux density.
    pub nrmse: f64,
    /// The magnetization scale g of B = μ0 (H + g M) + c: how much larger the rod's
    /// magnetization swing is than the model's (the M_s ratio where the law's normalised shape is
    /// right; also the coil's area against the rod's).
    pub scale: f64,
    /// The integrator's zero c [T].
    pub offset_t: f64,
}

/// The search coil's flux density as the model explains it: B = μ0 (H + g M) + c, the
/// magnetization scale g and the integrator's zero c by linear least squares (variable
/// projection, like the displacement's offset and λ_s). Displacement fits hold M_s as given
/// (λ_s carries the strain's scale, and the strain only sees M/M_s), so the flux's magnitude is
/// left to g and the channel judges the magnetization's shape and timing. Returns the fit and the
/// model's flux density [T] sample by sample.
pub fn flux_fit(measured: &[f64], field: &[f64], magnetization: &[f64]) -> (FluxFit, Vec<f64>) {
    let n = measured.len().max(1) as f64;
    // Regress y = B − μ0 H on x = μ0 M with an intercept.
    let y = |k: usize| measured[k] - MU0 * field[k];
    let x = |k: usize| MU0 * magnetization[k];
    let (my, mx) = ((0..measured.len()).map(y).sum::<f64>() / n, (0..measured.len()).map(x).sum::<f64>() / n);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for k in 0..measured.len() {
        sxy += (x(k) - mx) * (y(k) - my);
        sxx += (x(k) - mx) * (x(k) - mx);
    }
    let scale = if sxx > 0.0 && sxy.is_finite() {
        (sxy / sxx).clamp(FLUX_SCALE_RANGE.0, FLUX_SCALE_RANGE.1)
    } else {
        1.0
    };
    let offset_t = my - scale * mx;
    let model: Vec<f64> = (0..measured.len()).map(|k| MU0 * field[k] + scale * x(k) + offset_t).collect();
    (FluxFit { nrmse: nrmse(measured, &model), scale, offset_t }, model)
}

/// How the model's coil heating matches a logged temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemperatureFit {
    /// NRMSE of the temperature.
    pub nrmse: f64,
    /// The temperature the rise is counted from [°C]: the coil's when the file starts, taken
    /// to be in equilibrium with its surroundings (the model's rise starts at 0).
    pub ambient_c: f64,
}

/// The logged temperature as the model explains it: T = T_amb + θ, with θ the model's rise
/// (`rise` empty: none, a model without coil heating) and T_amb by least squares (the mean
/// difference, like the displacement's offset). Returns the fit and the model's temperature
/// [°C] sample by sample.
pub fn temperature_fit(measured: &[f64], rise: &[f64]) -> (TemperatureFit, Vec<f64>) {
    let at = |k: usize| rise.get(k).copied().unwrap_or(0.0);
    let n = measured.len().max(1) as f64;
    let ambient_c = measured.iter().enumerate().map(|(k, t)| t - at(k)).sum::<f64>() / n;
    let model: Vec<f64> = (0..measured.len()).map(|k| ambient_c + at(k)).collect();
    (TemperatureFit { nrmse: nrmse(measured, &model), ambient_c }, model)
}

/// Scores a simulation against its file.
pub fn score(spec: ModelSpec, rec: &Recording, sim: &Simulation) -> FileScore {
    score_with_models(spec, rec, sim).0
}

/// [`score`], and the model's flux density and temperature where the file measured them (what
/// their residual blocks need: fitted once).
pub(crate) fn score_with_models(
    spec: ModelSpec,
    rec: &Recording,
    sim: &Simulation,
) -> (FileScore, ChannelModels) {
    let meas = rec.displacement_um.as_deref().unwrap_or_default();
    let offset = meas.iter().zip(&sim.displacement_um).map(|(a, b)| a - b).sum::<f64>() / meas.len() as f64;
    let shifted: Vec<f64> = sim.displacement_um.iter().map(|y| y + offset).collect();
    let nrmse_current = match (&rec.current_a, spec.has(Effect::AmplifierDynamics)) {
        (Some(i), true) => Some(nrmse(i, &sim.current_a)),
        _ => None,
    };
    let (flux, flux_model) = match rec.flux_density_t.as_deref() {
        Some(b) => {
            let (f, model) = flux_fit(b, &sim.field_a_per_m, &sim.magnetization_a_per_m);
            (Some(f), Some(model))
        }
        None => (None, None),
    };
    let temperature = match rec.temperature_c.as_deref() {
        Some(t) if spec.has(Effect::ThermalDrift) => Some(temperature_fit(t, &sim.temperature_rise_c)),
        _ => None,
    };
    let memory = spec.has_magnetic_memory();
    let score = FileScore {
        nrmse: nrmse(meas, &shifted),
        nrmse_current,
        flux,
        temperature: temperature.as_ref().map(|t| t.0),
        offset_um: offset,
        initial_excursion_a_per_m: memory.then_some(sim.initial_excursion_a_per_m),
    };
    (score, ChannelModels { flux: flux_model, temperature: temperature.map(|t| t.1) })
}

/// The models of the channels fitted in closed form ([`score_with_models`]).
pub(crate) struct ChannelModels {
    /// The flux density B = μ0 (H + g M) + c, when the file measured it.
    pub flux: Option<Vec<f64>>,
    /// The coil temperature, when the file logged it and the model heats the coil.
    pub temperature: Option<Vec<f64>>,
}
