// The model-core workload of the QEMU smoke test. This one file is compiled twice: by build.rs on
// the host (to produce the expected values) and into the smoke binary on the Cortex-M4F, so the
// test checks that the cross-compiled models reproduce the host's numbers.

/// How many samples (10 kHz) the smoke workload runs; a checkpoint is recorded every `SMOKE_STRIDE`.
pub const SMOKE_SAMPLES: usize = 2000;
/// Samples between recorded checkpoints.
pub const SMOKE_STRIDE: usize = 50;
/// Number of checkpoints.
pub const SMOKE_CHECKPOINTS: usize = SMOKE_SAMPLES / SMOKE_STRIDE;

/// What the workload records.
#[derive(Clone, Copy)]
pub struct SmokeResult {
    /// Two ZOH mechanics (000 Table 1, and a lightly damped one) under a square force [µm].
    pub mechanics_um: [f32; SMOKE_CHECKPOINTS],
    /// Displacement of the ja+eddy+amp+mech plant driven by the J–A compensator [µm].
    pub chain_um: [f32; SMOKE_CHECKPOINTS],
    /// The compensator's command voltage [V].
    pub command_v: [f32; SMOKE_CHECKPOINTS],
    /// RMS tracking error of the compensated chain over the last 1000 samples [% of amplitude].
    pub tracking_rms_percent: f32,
    /// Displacement of the preisach+eddy+amp plant driven by the Preisach compensator [µm].
    pub preisach_um: [f32; SMOKE_CHECKPOINTS],
    /// Its RMS tracking error over the last 1000 samples [% of amplitude].
    pub preisach_tracking_rms_percent: f32,
}

/// Runs the workload.
pub fn smoke_workload() -> Result<SmokeResult, model_core::ParamError> {
    use model_core::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};
    use model_core::{Actuator, ActuatorParams, Compensator, ModelSpec};

    let mut r = SmokeResult {
        mechanics_um: [0.0; SMOKE_CHECKPOINTS],
        chain_um: [0.0; SMOKE_CHECKPOINTS],
        command_v: [0.0; SMOKE_CHECKPOINTS],
        tracking_rms_percent: 0.0,
        preisach_um: [0.0; SMOKE_CHECKPOINTS],
        preisach_tracking_rms_percent: 0.0,
    };
    let heavy = SecondOrderZoh::new(
        MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 },
        1e-4,
    )?;
    let light = SecondOrderZoh::new(
        MassSpringDamper { mass_kg: 0.5, damping_n_s_per_m: 150.0, stiffness_n_per_m: 2.0e6 },
        1e-4,
    )?;
    let (mut a, mut b) = (MechState::default(), MechState::default());
    for n in 0..SMOKE_SAMPLES {
        // A 50 Hz square force with a DC bias.
        let force = if (n / 100) % 2 == 0 { 120.0 } else { -30.0 };
        let y_mech = heavy.step(&mut a, force) + light.step(&mut b, force);
        if n % SMOKE_STRIDE == SMOKE_STRIDE - 1 {
            r.mechanics_um[n / SMOKE_STRIDE] = y_mech * 1e6;
        }
    }

    let p = ActuatorParams::TERFENOL_DEMO;
    let spec = |s| ModelSpec::parse(s).unwrap_or(ModelSpec::LINEAR);
    let plant = Actuator::new(spec("ja+eddy+amp+mech"), &p)?;
    let comp = Compensator::new(Actuator::new(spec("ja+eddy+amp"), &p)?);
    r.tracking_rms_percent = compensated_sine(&plant, &comp, |k, y_um, u| {
        r.chain_um[k] = y_um;
        r.command_v[k] = u;
    });
    r.preisach_tracking_rms_percent = preisach_chain(&p, &mut r.preisach_um)?;
    Ok(r)
}

/// The Preisach law's compensated chain (static: no mechanics) on the same sine.
#[inline(never)] // its two 4 KB tables live only while it runs
fn preisach_chain(
    p: &model_core::ActuatorParams,
    displacement_um: &mut [f32; SMOKE_CHECKPOINTS],
) -> Result<f32, model_core::ParamError> {
    use model_core::{Actuator, Compensator, ModelSpec};
    let spec = ModelSpec::parse("preisach+eddy+amp").unwrap_or(ModelSpec::LINEAR);
    let plant = Actuator::new(spec, p)?;
    let comp = Compensator::new(Actuator::new(spec, p)?);
    Ok(compensated_sine(&plant, &comp, |k, y_um, _| displacement_um[k] = y_um))
}

/// `plant` driven by `comp` along a 20 µm peak-to-peak, 50 Hz sine above the rest position:
/// `checkpoint(k, displacement from rest [µm], drive input)` every `SMOKE_STRIDE` samples;
/// returns the RMS tracking error over the last 1000 samples [% of amplitude].
fn compensated_sine(
    plant: &model_core::Actuator,
    comp: &model_core::Compensator,
    mut checkpoint: impl FnMut(usize, f32, f32),
) -> f32 {
    let (mut ps, mut cs) = (plant.rest_state(), comp.rest_state());
    let y0 = ps.mech.displacement_m;
    let amplitude = 10e-6;
    let mut err2 = 0.0f32;
    for n in 0..SMOKE_SAMPLES {
        let phase = 2.0 * core::f32::consts::PI * 50.0 * n as f32 * 1e-4;
        let y_ref = y0 + amplitude * (1.0 + model_core::math::sin_cos(phase).0);
        let u = comp.step(&mut cs, y_ref);
        let y = plant.step(&mut ps, u).map(|o| o.displacement_m).unwrap_or(f32::NAN);
        if n >= SMOKE_SAMPLES - 1000 {
            err2 += (y - y_ref) * (y - y_ref);
        }
        if n % SMOKE_STRIDE == SMOKE_STRIDE - 1 {
            checkpoint(n / SMOKE_STRIDE, (y - y0) * 1e6, u);
        }
    }
    model_core::math::sqrt(err2 / 1000.0) / amplitude * 100.0
}
