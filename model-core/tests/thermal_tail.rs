//! `Actuator::thermal_tail_step`: the coil-heating share of the displacement, which the
//! workbench subtracts to solve λ_s in closed form with one run of the chain. Mechanics and
//! delay are linear, so the displacement at λ_s is λ_s·g + t with t the tail's output: checked
//! against the two-run split (2·y(λ) − y(2λ) = t) on a drive that heats the coil.

use model_core::{Actuator, ActuatorParams, ModelSpec};

fn run(spec: ModelSpec, p: &ActuatorParams, n: usize) -> (Vec<f32>, Vec<f32>) {
    let m = Actuator::new(spec, p).unwrap();
    let mut s = m.rest_state();
    let (mut y, mut i) = (Vec::new(), Vec::new());
    for k in 0..n {
        let t = k as f32 * p.dt_s;
        let o = m.step(&mut s, 0.5 + 2.0 * libm::sinf(2.0 * core::f32::consts::PI * 50.0 * t)).unwrap();
        y.push(o.displacement_m);
        i.push(o.current_a);
    }
    (y, i)
}

#[test]
fn the_displacement_is_the_magnetostrictive_part_plus_the_thermal_tail() {
    for spec in ["amp+eddy+ja+aftereffect+mech+thermal+delay", "ja+thermal", "preisach+mech+thermal"] {
        let spec = ModelSpec::parse(spec).unwrap();
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.thermal.thermal_resistance_c_per_w = 40.0; // a visible drift within the record
        p.thermal.tau_s = 0.05;
        p.delay_samples = 3.0;
        let n = 4000;
        let (y1, currents) = run(spec, &p, n);
        let mut p2 = p;
        p2.magnetostriction.lambda_s *= 2.0;
        let (y2, _) = run(spec, &p2, n);
        let m = Actuator::new(spec, &p).unwrap();
        let mut s = m.thermal_tail_rest();
        let tail: Vec<f32> = currents.iter().map(|&i| m.thermal_tail_step(&mut s, i)).collect();
        let span = y1.iter().fold(0.0f32, |a, v| a.max(v.abs()));
        let drift = tail.iter().fold(0.0f32, |a, v| a.max(v.abs()));
        assert!(drift > 0.01 * span, "{spec}: the coil must heat visibly ({drift:e} m of {span:e} m)");
        for k in 0..n {
            let two_run = 2.0 * y1[k] - y2[k];
            assert!(
                (two_run - tail[k]).abs() <= 1e-5 * span,
                "{spec}: sample {k}: two-run split {two_run:e} m, tail {:e} m",
                tail[k]
            );
        }
    }
}

#[test]
fn without_thermal_drift_the_tail_is_zero() {
    let m =
        Actuator::new(ModelSpec::parse("ja+mech+delay").unwrap(), &ActuatorParams::TERFENOL_DEMO).unwrap();
    let mut s = m.thermal_tail_rest();
    assert!((0..100).all(|_| m.thermal_tail_step(&mut s, 3.0) == 0.0));
}
