//! Host time per model step (ns/step): `cargo bench -p model-core --bench models`.
//! The same workloads run on the Cortex-M4F under QEMU for instruction counts
//! (`scripts/fw bench`); both tables are in the crate README.
#![allow(missing_docs)] // criterion's macros generate undocumented items

use criterion::{criterion_group, criterion_main, Criterion};
use model_core::arx::{Arx, ArxParams, ArxState};
use model_core::magnetization::{JaParams, JaState, JilesAtherton, Preisach, PreisachParams};
use model_core::mechanics::{ChainParams, ChainState, ChainZoh, MassSpringDamper, MechState, SecondOrderZoh};
use model_core::{Actuator, ActuatorParams, Compensator, ModelSpec};
use std::hint::black_box;

/// A 400 Hz full-scale sine at 10 kHz: 25 samples per period (looked up, so that the bench
/// times the model, not `sin`).
fn sine(n: usize, amplitude: f32, bias: f32) -> f32 {
    static UNIT: std::sync::OnceLock<[f32; 25]> = std::sync::OnceLock::new();
    let unit =
        UNIT.get_or_init(|| core::array::from_fn(|k| (2.0 * core::f32::consts::PI * k as f32 / 25.0).sin()));
    bias + amplitude * unit[n % 25]
}

fn bench(c: &mut Criterion) {
    let ja = JilesAtherton::new(JaParams::TSMA_ROD1_002).unwrap();
    c.bench_function("ja_substep", |b| {
        let mut s = JaState::default();
        let mut dir = 1.0;
        b.iter(|| {
            if s.h_a_per_m.abs() > 5e4 {
                dir = -dir;
            }
            ja.substep(&mut s, black_box(dir * 100.0));
        })
    });
    c.bench_function("ja_sample_400hz_fullscale", |b| {
        let mut s = JaState::default();
        let mut n = 0;
        b.iter(|| {
            n += 1;
            ja.step(&mut s, black_box(sine(n, 6e4, 0.0)))
        })
    });
    // Two rods stepped beside each other (the workbench runs two files on one core this way),
    // and the same two one after the other: per pair of samples.
    let ja_other = JilesAtherton::new(JaParams { k_a_per_m: 3000.0, ..JaParams::TSMA_ROD1_002 }).unwrap();
    c.bench_function("ja_sample_400hz_fullscale_two_rods_in_turn", |b| {
        let (mut s, mut s_other) = (JaState::default(), JaState::default());
        let mut n = 0;
        b.iter(|| {
            n += 1;
            (
                ja.step(&mut s, black_box(sine(n, 6e4, 0.0))),
                ja_other.step(&mut s_other, black_box(sine(n + 3, 5e4, 0.0))),
            )
        })
    });
    c.bench_function("ja_sample_400hz_fullscale_two_rods_beside", |b| {
        let (mut s, mut s_other) = (JaState::default(), JaState::default());
        let mut n = 0;
        b.iter(|| {
            n += 1;
            ja.step_beside(
                &mut s,
                black_box(sine(n, 6e4, 0.0)),
                &ja_other,
                &mut s_other,
                black_box(sine(n + 3, 5e4, 0.0)),
            )
        })
    });
    let zoh = SecondOrderZoh::new(
        MassSpringDamper { mass_kg: 0.1, damping_n_s_per_m: 3000.0, stiffness_n_per_m: 9.9e6 },
        1e-4,
    )
    .unwrap();
    c.bench_function("zoh_step", |b| {
        let mut s = MechState::default();
        let mut n = 0;
        b.iter(|| {
            n += 1;
            zoh.step(&mut s, black_box(sine(n, 100.0, 0.0)))
        })
    });
    let p = ActuatorParams::TERFENOL_DEMO;
    let full = Actuator::new(ModelSpec::parse("amp+eddy+ja+mech").unwrap(), &p).unwrap();
    let comp = Compensator::new(Actuator::new(ModelSpec::parse("amp+eddy+ja").unwrap(), &p).unwrap());
    let y0 = full.rest_state().mech.displacement_m;
    // 100 Hz (one J–A sub-step per sample) and 400 Hz (several), as in the QEMU cases.
    for (label, stride) in [("", 1), ("_400hz", 4)] {
        c.bench_function(&format!("chain_amp_eddy_ja_mech{label}"), |b| {
            let mut s = full.rest_state();
            let mut n = 0;
            b.iter(|| {
                n += 1;
                full.step(&mut s, black_box(sine(n * stride / 4, 1.0, 0.0)))
            })
        });
        c.bench_function(&format!("inverse_amp_eddy_ja{label}"), |b| {
            let mut s = comp.rest_state();
            let mut n = 0;
            b.iter(|| {
                n += 1;
                comp.step(&mut s, black_box(y0 + sine(n * stride / 4, 10e-6, 10e-6)))
            })
        });
    }
    let preisach = Preisach::new(PreisachParams {
        ms_a_per_m: 6e5,
        coercive_a_per_m: 3000.0,
        spread_a_per_m: 10_000.0,
        interaction_spread_a_per_m: Some(10_000.0),
        reversible_fraction: None,
        reversible_field_a_per_m: None,
        h_max_a_per_m: 80_000.0,
    })
    .unwrap();
    c.bench_function("preisach_step", |b| {
        let mut s = preisach.demagnetized();
        let mut n = 0;
        b.iter(|| {
            n += 1;
            preisach.step(&mut s, black_box(sine(n, 4e4, 1e4)))
        })
    });
    let chain = ChainZoh::new(ChainParams::TSMA_002, 1e-4).unwrap();
    c.bench_function("ndof_tsma6_step", |b| {
        let mut s = ChainState::default();
        let mut n = 0;
        b.iter(|| {
            n += 1;
            let f = sine(n, 100.0, 0.0);
            chain.step(&mut s, &ChainParams::tsma_forces(black_box([f, f, f])))
        })
    });
    let arx = Arx::new(ArxParams::DAVINO_003).unwrap();
    c.bench_function("arx_003_step", |b| {
        let mut s: ArxState<2, 2> = arx.steady_state(0.0).unwrap();
        let mut n = 0;
        b.iter(|| {
            n += 1;
            arx.step(&mut s, black_box(sine(n, 13.0, 13.0)))
        })
    });
}

criterion_group! {
    name = models;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(300))
        .measurement_time(std::time::Duration::from_secs(1));
    targets = bench
}
criterion_main!(models);
