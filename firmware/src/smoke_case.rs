// The model-core workload of the QEMU smoke test. This one file is compiled twice: by build.rs on
// the host (to produce the expected values) and into the smoke binary on the Cortex-M4F, so the
// test checks that the cross-compiled models reproduce the host's numbers.

/// How many samples the smoke workload runs; a checkpoint is recorded every `SMOKE_STRIDE`.
pub const SMOKE_SAMPLES: usize = 2000;
/// Samples between recorded checkpoints.
pub const SMOKE_STRIDE: usize = 100;
/// Number of checkpoints.
pub const SMOKE_CHECKPOINTS: usize = SMOKE_SAMPLES / SMOKE_STRIDE;

/// Runs the workload, returning the displacement [µm] at every checkpoint.
pub fn smoke_workload() -> Result<[f32; SMOKE_CHECKPOINTS], model_core::ParamError> {
    use model_core::mechanics::{MassSpringDamper, MechState, SecondOrderZoh};
    // 000 Table 1 mechanics (overdamped) and a lightly damped variant, at the 10 kHz loop rate.
    let heavy = SecondOrderZoh::new(
        MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 },
        1e-4,
    )?;
    let light = SecondOrderZoh::new(
        MassSpringDamper { mass_kg: 0.5, damping_n_s_per_m: 150.0, stiffness_n_per_m: 2.0e6 },
        1e-4,
    )?;
    let (mut a, mut b) = (MechState::default(), MechState::default());
    let mut out = [0.0; SMOKE_CHECKPOINTS];
    for n in 0..SMOKE_SAMPLES {
        // A 50 Hz square force with a DC bias.
        let force = if (n / 100) % 2 == 0 { 120.0 } else { -30.0 };
        let y = heavy.step(&mut a, force) + light.step(&mut b, force);
        if n % SMOKE_STRIDE == SMOKE_STRIDE - 1 {
            out[n / SMOKE_STRIDE] = y * 1e6;
        }
    }
    Ok(out)
}
