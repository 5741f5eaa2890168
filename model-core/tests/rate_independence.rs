//! A rate-independent law draws the same loop at any drive frequency: `ja` (each form) and
//! `preisach` driven by a current sine at 500 Hz (fs/20) and at 1 Hz, sampled at 10 kHz; the
//! 500 Hz loop against the 1 Hz one at the same phases, as a share of the loop's range.
//! Printed per law, amplitude and integration (`cargo test -p model-core --release --test
//! rate_independence -- --nocapture`); asserted at today's figures, so that a change that
//! loosens the integration fails. Issue 81's goal is 0.2 % everywhere: the board's explicit
//! sub-step misses it on every J–A form (0.5–6.4 %), the workbench's second-order one, its
//! sub-steps as many as its tolerance asks, on loops under about 1 A (0.06–1.03 %; its
//! refinement only moves its first try).

use model_core::magnetization::JaVariant;
use model_core::{Actuator, ActuatorParams, ModelSpec};

/// The 500 Hz loop's largest distance from the 1 Hz loop, in % of the latter's range.
fn loop_gap(law: &str, variant: JaVariant, amplitude_a: f64, refinement: u32, second_order: bool) -> f64 {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.dt_s = 1e-4;
    p.ja.variant = variant;
    let mut model =
        Actuator::new(ModelSpec::parse(law).unwrap(), &p).unwrap().with_finer_hysteresis(refinement);
    if second_order {
        model = model.with_second_order_hysteresis();
    }
    let run = |f_hz: f64, per_period: usize| -> Vec<f32> {
        let mut s = model.rest_state_at(0.0, 0.0);
        (0..4 * per_period)
            .map(|k| {
                let i = amplitude_a * (2.0 * core::f64::consts::PI * f_hz * k as f64 * 1e-4).sin();
                model.step(&mut s, i as f32).unwrap().magnetization_a_per_m
            })
            .skip(3 * per_period)
            .collect()
    };
    let (fast, slow) = (run(500.0, 20), run(1.0, 10_000));
    let range = slow.iter().copied().fold(f32::MIN, f32::max) - slow.iter().copied().fold(f32::MAX, f32::min);
    let gap = fast.iter().zip(slow.iter().step_by(500)).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    100.0 * (gap / range) as f64
}

#[test]
fn a_rate_independent_law_draws_one_loop_at_any_frequency() {
    let mut failures = Vec::new();
    for (law, variants) in [("ja", &JaVariant::ALL[..]), ("preisach", &[JaVariant::Bulk][..])] {
        for &variant in variants {
            for amplitude in [0.25, 1.0, 2.0] {
                // The board's stepping, the workbench's, and the workbench's at half the sub-step.
                for (refinement, second_order) in [(1, false), (1, true), (2, true)] {
                    let gap = loop_gap(law, variant, amplitude, refinement, second_order);
                    let order = if second_order { "second-order" } else { "explicit" };
                    println!(
                        "{law:<9} {variant:<15} {amplitude:>4} A  {order:<12} ×{refinement}: {gap:.3} % of the range"
                    );
                    // Today's figures with a margin (issue 81's goal: 0.2 %).
                    let bound = match (law, refinement, second_order) {
                        ("preisach", ..) => 0.01,
                        (_, 1, false) => 3.5 / amplitude.sqrt(),
                        _ => 0.35 / amplitude.powf(0.95),
                    };
                    if gap.is_nan() || gap > bound {
                        failures.push(format!(
                            "{law} {variant} {amplitude} A ×{refinement}: {gap:.3} % > {bound:.2} %"
                        ));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
