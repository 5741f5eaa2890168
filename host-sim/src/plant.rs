//! The plant simulator: SIMULATED actuator recordings for tests and demos. A model-core chain
//! with any set of effects, integrated at `oversample` × the recording rate under the
//! continuous-time excitation (the identified models run at the recording rate with a held
//! input), then sampled like a rig does: current and displacement at the same instants, sensor
//! noise, quantisation and an arbitrary displacement offset. Eddy currents are distributed by
//! default (field diffusion into the rod, [`crate::rod_diffusion`]), richer than the lumped lag
//! the models identify.

use anyhow::{bail, Context, Result};
use model_core::{
    Actuator, ActuatorOutput, ActuatorParams, ActuatorState, Effect, FirstOrderHold, MagneticOutput,
    ModelSpec, PreviousSample,
};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::excitation::Excitation;
use crate::recording::Recording;
use crate::rod_diffusion::{RodDiffusion, RodDiffusionState};

/// How the simulated rod's eddy currents are modelled (when the plant has `eddy_current`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EddyModel {
    /// Field diffusion into a solid rod (Bessel modes); `eddy_tau_s` is its low-frequency lag.
    Distributed,
    /// The models' own first-order lag of time constant `eddy_tau_s`.
    Lumped,
}

/// Everything that defines a simulated rig.
#[derive(Debug, Clone)]
pub struct Plant {
    /// Effects present in the simulated actuator.
    pub spec: ModelSpec,
    /// Its parameters; `dt_s` is the recording's sample period.
    pub params: ActuatorParams,
    /// Integration steps per recorded sample (≥ 1).
    pub oversample: u32,
    /// Displacement sensor noise, standard deviation [µm].
    pub noise_um: f64,
    /// Displacement quantisation step [µm] (0: none).
    pub quantum_um: f64,
    /// Displacement sensor offset [µm].
    pub offset_um: f64,
    /// Current sensor noise, standard deviation [A].
    pub current_noise_a: f64,
    /// Whether the recording has a `current_A` column.
    pub log_current: bool,
    /// Whether the recording has a `command_V` column (always when the plant has an amplifier).
    pub log_command: bool,
    /// Eddy-current model of the simulated rod.
    pub eddy: EddyModel,
    /// A search coil on the rod: `Some(σ)` adds a `flux_density_T` column, the rod's mean flux
    /// density B = μ0 (H + M) with white noise of standard deviation σ [T]; `None`: no column.
    pub flux_noise_t: Option<f64>,
}

impl Plant {
    /// A rig with the given effects and parameters, realistic sensors (0.02 µm noise, 0.01 µm
    /// quantisation), 20 kHz integration and distributed eddy currents.
    pub fn new(spec: ModelSpec, params: ActuatorParams) -> Self {
        Self {
            spec,
            params,
            oversample: 2,
            noise_um: 0.02,
            quantum_um: 0.01,
            offset_um: 0.0,
            current_noise_a: 0.0,
            log_current: true,
            log_command: spec.has(Effect::AmplifierDynamics),
            eddy: EddyModel::Distributed,
            flux_noise_t: None,
        }
    }

    /// The simulated actuator in words: its effects, and how its eddy currents are modelled.
    pub fn describe(&self) -> String {
        match (self.spec.has(Effect::EddyCurrent), self.eddy) {
            (false, _) => format!("`{}`", self.spec),
            (true, EddyModel::Distributed) => format!("`{}` (distributed eddy currents)", self.spec),
            (true, EddyModel::Lumped) => format!("`{}` (lumped eddy currents)", self.spec),
        }
    }

    /// The actuator at the integration step (delay scaled to keep its time).
    fn fine_model(&self) -> Result<(FineModel, f64)> {
        if self.oversample == 0 {
            bail!("oversample must be ≥ 1");
        }
        let fine_dt = self.params.dt_s as f64 / self.oversample as f64;
        let mut fine = self.params;
        fine.dt_s = fine_dt as f32;
        fine.delay_samples = self.params.delay_samples * self.oversample as f32;
        if self.spec.has(Effect::SensorDelay)
            && fine.delay_samples >= model_core::chain::MAX_DELAY_SAMPLES as f32
        {
            bail!(
                "delay_samples = {} at {}× oversampling is {} integration steps; the delay line holds \
                 fewer than {}: lower the oversampling or the delay",
                self.params.delay_samples,
                self.oversample,
                fine.delay_samples,
                model_core::chain::MAX_DELAY_SAMPLES
            );
        }
        // Distributed: the chain without its lumped lag, the rod's diffusion in its place.
        let distributed = self.spec.has(Effect::EddyCurrent) && self.eddy == EddyModel::Distributed;
        let chain_spec = if distributed { self.spec.without(Effect::EddyCurrent) } else { self.spec };
        let chain = crate::simulation::workbench_model(chain_spec, &fine).context("plant parameters")?;
        let rod = if distributed {
            Some(RodDiffusion::new(self.params.eddy_tau_s as f64, fine_dt).context("plant parameters")?)
        } else {
            None
        };
        Ok((FineModel { chain, rod }, fine_dt))
    }

    /// The plant stepped one recording period at a time under a drive the caller holds over the
    /// period (a controller's output), for closed-loop tests. No sensor noise.
    pub fn stepper(&self) -> Result<PlantStepper> {
        let (model, _) = self.fine_model()?;
        let state = model.rest_state();
        Ok(PlantStepper {
            displacement_m: state.chain.mech.displacement_m as f64,
            current_a: 0.0,
            model,
            state,
            oversample: self.oversample,
        })
    }

    /// Records `duration_s` of the response to `exc` (the drive is the command [V] when the
    /// plant has an amplifier, else the coil current [A]). `seed` fixes the noise.
    pub fn record(&self, name: &str, exc: &Excitation, duration_s: f64, seed: u64) -> Result<Recording> {
        exc.validate()?;
        if !(duration_s.is_finite() && duration_s > 0.0) {
            bail!("duration must be > 0 s, got {duration_s}");
        }
        let (model, fine_dt) = self.fine_model()?;
        let dt = self.params.dt_s as f64;
        let n = (duration_s / dt).round() as usize;
        let mut rec = Recording::with_time(name, n, dt);
        let voltage = model.chain.input_is_voltage();
        let mut command = Vec::with_capacity(n);
        let mut current = Vec::with_capacity(n);
        let mut disp = Vec::with_capacity(n);
        // At rest at the drive's first value, the rod demagnetised there (as a rig's record starts).
        let mut s = model.rest_state_at(exc.value(0.0, duration_s), fine_dt);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let y_noise = Normal::new(0.0, self.noise_um.max(0.0)).context("noise")?;
        let i_noise = Normal::new(0.0, self.current_noise_a.max(0.0)).context("noise")?;
        let mut y_m = s.chain.mech.displacement_m as f64;
        // The search coil's noise has its own stream: the other columns are the same with it or without.
        let mut flux_rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x5EA2_C011);
        let b_noise = Normal::new(0.0, self.flux_noise_t.unwrap_or(0.0).max(0.0)).context("noise")?;
        // The rod's field and magnetization after the last integration step (B is formed only
        // where a row logs it).
        let mut h_m_now = (s.chain.rod_field_a_per_m.value(), s.chain.m_slow_a_per_m.value());
        let mut flux = Vec::with_capacity(if self.flux_noise_t.is_some() { n } else { 0 });
        let mut i_now = if voltage { s.chain.amp.current_a as f64 } else { exc.value(0.0, duration_s) };
        // A sine drive is generated by rotating a unit phasor by ω·dt_fine per integration step
        // (renormalised every step) instead of calling sin twice per sample.
        let mut phasor = match exc {
            Excitation::Sine { freq_hz, .. } => {
                let w = 2.0 * std::f64::consts::PI * freq_hz * fine_dt;
                Some(((1.0f64, 0.0f64), (w.cos(), w.sin())))
            }
            _ => None,
        };
        let mut drive_at = |tf: f64| -> f64 {
            match (&mut phasor, exc) {
                (Some((z, r)), Excitation::Sine { amplitude, bias, .. }) => {
                    let v = bias + amplitude * z.1;
                    let (c, s) = (z.0 * r.0 - z.1 * r.1, z.0 * r.1 + z.1 * r.0);
                    let g = 1.5 - 0.5 * (c * c + s * s);
                    *z = (c * g, s * g);
                    v
                }
                _ => exc.value(tf, duration_s),
            }
        };
        // The drive at t_k (each call of `drive_at` moves a sine's phasor one step on).
        let mut u = drive_at(0.0);
        for k in 0..n {
            // Sample at t_k: the drive, the coil current and the displacement at that instant.
            let t = k as f64 * dt;
            command.push(u);
            let i_meas = if voltage { i_now } else { u };
            current.push(if self.current_noise_a > 0.0 { i_meas + i_noise.sample(&mut rng) } else { i_meas });
            let mut y = y_m * 1e6 + self.offset_um;
            if self.noise_um > 0.0 {
                y += y_noise.sample(&mut rng);
            }
            if self.quantum_um > 0.0 {
                y = (y / self.quantum_um).round() * self.quantum_um;
            }
            disp.push(y);
            let mut log_flux = |(h, m): (f32, f32)| {
                if let Some(sigma) = self.flux_noise_t {
                    let b = crate::channels::MU0 * (h as f64 + m as f64);
                    flux.push(if sigma > 0.0 { b + b_noise.sample(&mut flux_rng) } else { b });
                }
            };
            // Every column of the row at t_k: the last step ended there.
            log_flux(h_m_now);
            // Integrate to t_{k+1} under the continuous drive, the drive a straight line between
            // the integration steps' instants (the workbench's first-order hold).
            for j in 0..self.oversample {
                let tf = t + (j + 1) as f64 * fine_dt;
                u = drive_at(tf);
                let out = model.step_between(&mut s, u).with_context(|| {
                    format!("plant input at t = {tf:.6} s (is --amplitude or --bias in range?)")
                })?;
                y_m = out.displacement_m as f64;
                i_now = out.current_a as f64;
                h_m_now = (out.field_a_per_m, out.magnetization_a_per_m);
            }
        }
        if self.log_command || voltage {
            rec.command_v = Some(command);
        }
        if self.log_current {
            rec.current_a = Some(current);
        }
        rec.displacement_um = Some(disp);
        if self.flux_noise_t.is_some() {
            rec.flux_density_t = Some(flux);
        }
        Ok(rec)
    }
}

/// The plant's actuator at the integration step: a model-core chain, and the rod's field
/// diffusion in place of its lumped eddy lag when eddy currents are distributed.
struct FineModel {
    chain: Actuator,
    rod: Option<RodDiffusion>,
}

/// State of a [`FineModel`].
struct FineState {
    chain: ActuatorState,
    rod: Option<RodDiffusionState>,
    /// The first-order hold's coefficients and what it keeps of the last step (a recording's
    /// run); `None`: the drive is held over each step (a controller's output in closed loop).
    ramp: Option<(FirstOrderHold, PreviousSample, MagneticOutput)>,
}

impl FineModel {
    fn rest_state(&self) -> FineState {
        self.settled(self.chain.rest_state())
    }

    /// At rest at drive `drive`, the rod demagnetised at its field ([`Actuator::rest_state_at`]),
    /// stepped under the first-order hold at step `dt_s` (the lumped chain).
    fn rest_state_at(&self, drive: f64, dt_s: f64) -> FineState {
        let mut s = self.settled(self.chain.rest_state_at(drive as f32, 0.0));
        s.ramp = Some((
            FirstOrderHold::new(&self.chain, dt_s as f32),
            self.chain.previous_at_rest(&s.chain, drive as f32),
            self.chain.magnetic_at_rest(&s.chain),
        ));
        s
    }

    /// `chain` with the rod's diffusion settled at its field.
    fn settled(&self, chain: ActuatorState) -> FineState {
        // The diffusion starts in equilibrium at the rest state's rod field.
        let rod = self.rod.as_ref().map(|r| r.rest_state(chain.rod_field_a_per_m.value() as f64));
        FineState { chain, rod, ramp: None }
    }

    /// One integration step of a recording's run, the drive a straight line to `to` (the
    /// first-order hold; the distributed rod's diffusion, which has no ramp form, holds the
    /// midpoint of its field's line, exact to second order).
    #[inline]
    fn step_between(&self, s: &mut FineState, to: f64) -> Result<ActuatorOutput, model_core::StepError> {
        let Some((hold, prev, before)) = &mut s.ramp else { return self.step(s, to) };
        let rod = (&self.rod, &mut s.rod);
        self.chain.step_ramp_with_field_stage(&mut s.chain, hold, (prev, before), to as f32, |h0, h1| {
            match rod {
                (Some(rod), Some(rs)) => rod.step(rs, 0.5 * (h0 as f64 + h1 as f64)) as f32,
                _ => h1,
            }
        })
    }

    /// One integration step with `drive` held over it (a controller's output).
    #[inline]
    fn step(&self, s: &mut FineState, drive: f64) -> Result<ActuatorOutput, model_core::StepError> {
        // One instantiation of the chain for both eddy models keeps its stages inlined together.
        let rod = (&self.rod, &mut s.rod);
        self.chain.step_with_field_stage(&mut s.chain, drive as f32, |h| match rod {
            (Some(rod), Some(rs)) => rod.step(rs, h as f64) as f32,
            _ => h,
        })
    }
}

/// A plant advanced period by period (see [`Plant::stepper`]).
pub struct PlantStepper {
    model: FineModel,
    state: FineState,
    oversample: u32,
    displacement_m: f64,
    current_a: f64,
}

impl PlantStepper {
    /// Coil current [A] now.
    pub fn current_a(&self) -> f64 {
        self.current_a
    }

    /// Displacement [µm] now (the plant's absolute value).
    pub fn displacement_um(&self) -> f64 {
        self.displacement_m * 1e6
    }

    /// Holds `drive` (command [V] with an amplifier, else current [A]) for one recording period.
    pub fn step(&mut self, drive: f64) -> Result<()> {
        for _ in 0..self.oversample {
            let o = self.model.step(&mut self.state, drive).context("plant input")?;
            self.displacement_m = o.displacement_m as f64;
            self.current_a = o.current_a as f64;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rod's distributed eddy currents are in the loop: they lag like the lumped model at
    /// low frequency and differ from it at high frequency; without `eddy` the choice is moot.
    #[test]
    fn distributed_eddy_currents_depart_from_the_lumped_lag_at_high_frequency() {
        let rms_gap = |spec: &str, freq_hz: f64| {
            let mut plant = Plant::new(ModelSpec::parse(spec).unwrap(), ActuatorParams::TERFENOL_DEMO);
            plant.params.eddy_tau_s = 5e-4;
            plant.noise_um = 0.0;
            plant.quantum_um = 0.0;
            let exc = Excitation::Sine { freq_hz, amplitude: 1.0, bias: 0.0 };
            let mut runs = [EddyModel::Distributed, EddyModel::Lumped].map(|eddy| {
                plant.eddy = eddy;
                plant.record("e", &exc, 0.1, 1).unwrap().displacement_um.unwrap()
            });
            let [d, l] = &mut runs;
            let range = l.iter().fold(f64::MIN, |a, &b| a.max(b)) - l.iter().fold(f64::MAX, |a, &b| a.min(b));
            let ms = d.iter().zip(l.iter()).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / d.len() as f64;
            ms.sqrt() / range
        };
        let low = rms_gap("eddy+ja", 5.0);
        let high = rms_gap("eddy+ja", 800.0);
        println!("distributed vs lumped eddy: NRMS gap {low:.4} at 5 Hz, {high:.4} at 800 Hz");
        assert!(low < 0.005, "5 Hz: distributed and lumped differ by {low}");
        assert!(high > 0.03 && high > 10.0 * low, "800 Hz: only {high} apart (5 Hz: {low})");
        assert_eq!(rms_gap("ja", 800.0), 0.0);
    }

    /// The sine recurrence matches the closed form over a long record.
    #[test]
    fn sine_drive_matches_the_closed_form() {
        let mut plant = Plant::new(ModelSpec::parse("amp+ja").unwrap(), ActuatorParams::TERFENOL_DEMO);
        plant.noise_um = 0.0;
        let exc = Excitation::Sine { freq_hz: 123.0, amplitude: 1.5, bias: 0.2 };
        let rec = plant.record("s", &exc, 3.0, 1).unwrap();
        let worst = rec
            .time_s
            .iter()
            .zip(rec.command_v.as_ref().unwrap())
            .map(|(t, u)| (u - exc.value(*t, 3.0)).abs())
            .fold(0.0f64, f64::max);
        assert!(worst < 1e-9, "max drive error {worst}");
    }
}
