//! model-core with arbitrary parameters and inputs: `Actuator::new` refuses the set, or every
//! step gives finite outputs (or refuses an out-of-range input), and the inverse compensator's
//! command is always finite and within ±MAX_INPUT. Every parameter is the demo value, the demo
//! value scaled by up to 2^±16, or an arbitrary f32 (NaN, ±inf, subnormal, huge).
#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use model_core::amplifier::SecondOrderAmpParams;
use model_core::chain::MAX_INPUT;
use model_core::{Actuator, ActuatorParams, Compensator, Effect, ModelSpec};

const FIELDS: usize = 34;

#[derive(Arbitrary, Debug)]
enum Value {
    Demo,
    Scaled(i8),
    Raw(f32),
}

#[derive(Arbitrary, Debug)]
struct Case {
    effects: u16,
    values: [Value; FIELDS],
    second_order_amp: bool,
    delay: u16,
    inputs: Vec<f32>,
    amplitude: f32,
}

fn set(v: &mut f32, how: &Value) {
    match how {
        Value::Demo => {}
        Value::Scaled(s) => *v *= (*s as f32 / 8.0).exp2(),
        Value::Raw(x) => *v = *x,
    }
}

fn params(c: &Case) -> ActuatorParams {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    let mut so = SecondOrderAmpParams { k_u: 2.0, a_s: 1e-8, b_s2: 2e-4, c_s: 1.0 };
    let fields: [&mut f32; FIELDS] = [
        &mut p.dt_s,
        &mut p.amp.gain_a_per_v,
        &mut p.amp.tau_s,
        &mut p.coil.turns_per_m,
        &mut p.coil.bias_a_per_m,
        &mut p.eddy_tau_s,
        &mut p.linear.offset_a_per_m,
        &mut p.linear.susceptibility,
        &mut p.anhysteretic.ms_a_per_m,
        &mut p.anhysteretic.a_a_per_m,
        &mut p.ja.ms_a_per_m,
        &mut p.ja.a_a_per_m,
        &mut p.ja.alpha,
        &mut p.ja.k_a_per_m,
        &mut p.ja.c,
        &mut p.preisach.ms_a_per_m,
        &mut p.preisach.coercive_a_per_m,
        &mut p.preisach.spread_a_per_m,
        &mut p.preisach.h_max_a_per_m,
        &mut p.magnetostriction.lambda_s,
        &mut p.magnetostriction.ms_a_per_m,
        &mut p.magnetostriction.bias_m_a_per_m,
        &mut p.rod_length_m,
        &mut p.mech.natural_frequency_hz,
        &mut p.mech.damping_ratio,
        &mut p.aftereffect.fraction,
        &mut p.aftereffect.tau_s,
        &mut p.thermal.coil_resistance_ohm,
        &mut p.thermal.thermal_resistance_c_per_w,
        &mut p.thermal.tau_s,
        &mut p.thermal.rod_tau_s,
        &mut so.k_u,
        &mut so.b_s2,
        &mut so.c_s,
    ];
    for (f, how) in fields.into_iter().zip(&c.values) {
        set(f, how);
    }
    p.amp_second_order = c.second_order_amp.then_some(so);
    // 0 to 80 samples in sixteenths: fractional delays, and some beyond the line (refused).
    p.delay_samples = (c.delay % 1280) as f32 / 16.0;
    p
}

fuzz_target!(|c: Case| {
    let mut spec = ModelSpec::LINEAR;
    for (k, e) in Effect::ALL.iter().enumerate() {
        if c.effects & (1 << k) != 0 {
            spec = spec.with(*e);
        }
    }
    if spec.has(Effect::Preisach) && spec.has(Effect::Hysteresis) {
        return; // a conflict the spec parser refuses
    }
    let p = params(&c);
    let Ok(model) = Actuator::new(spec, &p) else { return };
    let mut s = model.rest_state();
    for &u in c.inputs.iter().take(512) {
        match model.step(&mut s, u) {
            Ok(out) => {
                let all = [
                    out.current_a,
                    out.field_a_per_m,
                    out.magnetization_a_per_m,
                    out.strain,
                    out.displacement_m,
                ];
                assert!(
                    all.iter().all(|v| v.is_finite()),
                    "non-finite output {out:?} for input {u} with {p:?} ({spec})"
                );
            }
            Err(_) => assert!(!u.is_finite() || u.abs() > MAX_INPUT, "refused the valid input {u}"),
        }
    }
    let comp = Compensator::new(model);
    let mut cs = comp.rest_state();
    for (k, &u) in c.inputs.iter().take(256).enumerate() {
        let target = u * c.amplitude * 1e-6 + (k as f32 * 0.05).sin() * 2e-5;
        let cmd = comp.step(&mut cs, target);
        assert!(cmd.is_finite() && cmd.abs() <= MAX_INPUT, "compensator command {cmd} for {target} ({spec})");
    }
});
