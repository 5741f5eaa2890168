//! The plant simulator: SIMULATED actuator recordings for tests and demos. A model-core chain
//! with any set of effects, integrated at `oversample` × the recording rate under the
//! continuous-time excitation (the identified models run at the recording rate with a held
//! input), then sampled like a rig does: current and displacement at the same instants, sensor
//! noise, quantisation and an arbitrary displacement offset.

use anyhow::{bail, Context, Result};
use model_core::{Actuator, ActuatorParams, ModelSpec};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::excitation::Excitation;
use crate::recording::Recording;

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
}

impl Plant {
    /// A rig with the given effects, the demo parameters and realistic sensors: 0.02 µm noise,
    /// 0.01 µm quantisation, 20 kHz integration.
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
            log_command: spec.has(model_core::Effect::AmplifierDynamics),
        }
    }

    /// Records `duration_s` of the response to `exc` (the drive is the command [V] when the
    /// plant has an amplifier, else the coil current [A]). `seed` fixes the noise.
    pub fn record(&self, name: &str, exc: &Excitation, duration_s: f64, seed: u64) -> Result<Recording> {
        exc.validate()?;
        if !(duration_s.is_finite() && duration_s > 0.0) {
            bail!("duration must be > 0 s, got {duration_s}");
        }
        if self.oversample == 0 {
            bail!("oversample must be ≥ 1");
        }
        let dt = self.params.dt_s as f64;
        let fine_dt = dt / self.oversample as f64;
        let mut fine = self.params;
        fine.dt_s = fine_dt as f32;
        let delay = self.params.delay_samples as u32 * self.oversample;
        fine.delay_samples = u16::try_from(delay).context("delay too long")?;
        let model = Actuator::new(self.spec, &fine).context("plant parameters")?;
        let n = (duration_s / dt).round() as usize;
        let mut rec = Recording::with_time(name, n, dt);
        let voltage = model.input_is_voltage();
        let mut command = Vec::with_capacity(n);
        let mut current = Vec::with_capacity(n);
        let mut disp = Vec::with_capacity(n);
        let mut s = model.rest_state();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let y_noise = Normal::new(0.0, self.noise_um.max(0.0)).context("noise")?;
        let i_noise = Normal::new(0.0, self.current_noise_a.max(0.0)).context("noise")?;
        let mut y_m = s.mech.displacement_m as f64;
        let mut i_now = if voltage { 0.0 } else { exc.value(0.0, duration_s) };
        for k in 0..n {
            // Sample at t_k: the drive, the coil current and the displacement at that instant.
            let t = k as f64 * dt;
            let u = exc.value(t, duration_s);
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
            // Integrate to t_{k+1} under the continuous drive.
            for j in 0..self.oversample {
                let tf = t + j as f64 * fine_dt;
                let drive = if j == 0 { u } else { exc.value(tf, duration_s) };
                let out =
                    model.step(&mut s, drive as f32).with_context(|| format!("plant input at t = {tf} s"))?;
                y_m = out.displacement_m as f64;
                i_now = out.current_a as f64;
            }
        }
        if self.log_command || voltage {
            rec.command_v = Some(command);
        }
        if self.log_current {
            rec.current_a = Some(current);
        }
        rec.displacement_um = Some(disp);
        Ok(rec)
    }
}
