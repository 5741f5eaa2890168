//! f32 models against an f64 reference, one row per math function the per-sample code uses,
//! with libm and with micromath behind that function. Prints the table in the crate README:
//!
//! `cargo test -p model-core --features math-audit --test f32_accuracy -- --nocapture`
//!
//! The f64 reference is an independent re-implementation of the `ja+eddy+mech` chain (same
//! equations and sub-step rule, all in f64), so the libm row also checks the f32 chain itself.

use model_core::math::{self, audit};
use model_core::{Actuator, ActuatorParams, Compensator, ModelSpec};
use std::f64::consts::PI;

const DT: f64 = 1e-4;
/// The sine set: (bias current [A], amplitude [A], frequency [Hz]).
const SINES: [(f64, f64, f64); 4] =
    [(0.0, 0.5, 10.0), (0.5, 1.5, 50.0), (0.0, 2.0, 200.0), (1.0, 1.0, 400.0)];

fn nrmse(a: &[f64], reference: &[f64]) -> f64 {
    let (lo, hi) = reference.iter().fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    let mse = a.iter().zip(reference).map(|(x, r)| (x - r) * (x - r)).sum::<f64>() / a.len() as f64;
    mse.sqrt() / (hi - lo)
}

fn current(n: usize, (bias, amp, f): (f64, f64, f64)) -> f64 {
    bias + amp * (2.0 * PI * f * n as f64 * DT).sin()
}

/// The `ja+eddy+mech` chain in f64.
struct Reference {
    p: ActuatorParams,
    h_lag: f64,
    h: f64,
    m: f64,
    m_irr: f64,
    /// L and L' at the present H_e (the J–A scheme evaluates them once per sub-step).
    l: f64,
    dl: f64,
    y: f64,
    v: f64,
    phi: [[f64; 2]; 2],
    gamma: [f64; 2],
}

fn langevin(x: f64) -> (f64, f64) {
    if x.abs() < 1e-3 {
        (x / 3.0 - x * x * x / 45.0, 1.0 / 3.0 - x * x / 15.0)
    } else {
        let s = x.sinh();
        (1.0 / x.tanh() - 1.0 / x, 1.0 / (x * x) - 1.0 / (s * s))
    }
}

impl Reference {
    fn new(p: ActuatorParams) -> Self {
        // Unit-gain mass-spring-damper, exact ZOH by a 40-term Taylor series of e^{AT} (‖AT‖ < 1).
        let w = 2.0 * PI * p.mech.natural_frequency_hz as f64;
        let z = p.mech.damping_ratio as f64;
        let a = [[0.0, 1.0], [-w * w, -2.0 * z * w]];
        let (mut phi, mut psi) = ([[1.0, 0.0], [0.0, 1.0]], [[DT, 0.0], [0.0, DT]]);
        let mut term = [[1.0, 0.0], [0.0, 1.0]];
        for k in 1..40 {
            let mut t = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    t[i][j] = (term[i][0] * a[0][j] + term[i][1] * a[1][j]) * DT / k as f64;
                }
            }
            term = t;
            for i in 0..2 {
                for j in 0..2 {
                    phi[i][j] += term[i][j];
                    psi[i][j] += term[i][j] * DT / (k + 1) as f64;
                }
            }
        }
        // B = [0, ω²] for the unit-gain form ÿ = ω²(y_free − y) − 2ζω ẏ.
        let gamma = [psi[0][1] * w * w, psi[1][1] * w * w];
        let mut r = Reference {
            p,
            h_lag: 0.0,
            h: 0.0,
            m: 0.0,
            m_irr: 0.0,
            l: 0.0,
            dl: 1.0 / 3.0,
            y: 0.0,
            v: 0.0,
            phi,
            gamma,
        };
        let h0 = p.coil.bias_a_per_m as f64;
        r.ja(h0);
        r.h_lag = h0;
        r.y = r.free_displacement();
        r
    }

    fn ja(&mut self, h: f64) {
        let j = &self.p.ja;
        let (ms, a, alpha, k, c) =
            (j.ms_a_per_m as f64, j.a_a_per_m as f64, j.alpha as f64, j.k_a_per_m as f64, j.c as f64);
        let dh_total = h - self.h;
        let n = ((dh_total.abs() / (0.25 * a.min(2.0 * k))) as u32 + 1).min(64); // model-core: min(a/4, k/2)
        let dh = dh_total / n as f64;
        let dir = if dh >= 0.0 { 1.0 } else { -1.0 };
        for _ in 0..n {
            let chi_irr = ((ms * self.l - self.m_irr) * dir).max(0.0) / k;
            let dm_dhe = c * ms / a * self.dl + (1.0 - c) * chi_irr;
            let dhe = dh / (1.0 - alpha * dm_dhe).max(0.05);
            self.m_irr = (self.m_irr + chi_irr * dhe).clamp(-ms, ms);
            self.h += dh;
            let m_predicted = self.m + dm_dhe * dhe;
            (self.l, self.dl) = langevin((self.h + alpha * m_predicted) / a);
            self.m = (c * ms * self.l + (1.0 - c) * self.m_irr).clamp(-ms, ms);
        }
    }

    fn free_displacement(&self) -> f64 {
        let q = &self.p.magnetostriction;
        let k_lambda = 1.5 * q.lambda_s as f64 / (q.ms_a_per_m as f64).powi(2);
        k_lambda * (self.m * self.m - (q.bias_m_a_per_m as f64).powi(2)) * self.p.rod_length_m as f64
    }

    fn step(&mut self, i: f64) -> f64 {
        let h_coil = self.p.coil.turns_per_m as f64 * i + self.p.coil.bias_a_per_m as f64;
        let pole = (-DT / self.p.eddy_tau_s as f64).exp();
        self.h_lag = pole * self.h_lag + (1.0 - pole) * h_coil;
        self.ja(self.h_lag);
        let u = self.free_displacement();
        let (y, v) = (self.y, self.v);
        self.y = self.phi[0][0] * y + self.phi[0][1] * v + self.gamma[0] * u;
        self.v = self.phi[1][0] * y + self.phi[1][1] * v + self.gamma[1] * u;
        self.y
    }
}

/// Displacement NRMSE of the f32 `ja+eddy+mech` chain against the f64 reference, worst over the set.
fn forward_chain_nrmse() -> f64 {
    let p = ActuatorParams::TERFENOL_DEMO;
    let model = Actuator::new(ModelSpec::parse("ja+eddy+mech").unwrap(), &p).unwrap();
    SINES
        .iter()
        .map(|&sine| {
            let mut s = model.rest_state();
            let mut r = Reference::new(p);
            let (mut y32, mut y64) = (Vec::new(), Vec::new());
            for n in 0..4000 {
                let i = current(n, sine);
                y32.push(model.step(&mut s, i as f32).unwrap().displacement_m as f64);
                y64.push(r.step(i));
            }
            nrmse(&y32, &y64)
        })
        .fold(0.0, f64::max)
}

/// Tracking NRMSE of the `ja` compensator (whose inverse magnetostriction takes a square root)
/// driving the f32 plant, against the f64 reference trajectory it is asked for (up to 30 µm
/// peak to peak, the stroke the inverse is specified for).
fn inverse_nrmse() -> f64 {
    let p = ActuatorParams::TERFENOL_DEMO;
    let model = Actuator::new(ModelSpec::parse("ja").unwrap(), &p).unwrap();
    let comp = Compensator::new(model);
    SINES
        .iter()
        .map(|&(_, amp, f)| {
            let (mut cs, mut ms) = (comp.rest_state(), model.rest_state());
            let y0 = ms.mech.displacement_m as f64;
            let (mut y, mut r) = (Vec::new(), Vec::new());
            for n in 0..4000 {
                let y_ref = y0 + 7.5e-6 * amp * (1.0 - (2.0 * PI * f * n as f64 * DT).cos());
                let u = comp.step(&mut cs, y_ref as f32);
                y.push(model.step(&mut ms, u).unwrap().displacement_m as f64);
                r.push(y_ref);
            }
            nrmse(&y, &r)
        })
        .fold(0.0, f64::max)
}

/// NRMSE of a reference sine generated with `math::sin_cos` (phase wrapped to ±π as the
/// firmware does) against the f64 sine.
fn waveform_nrmse() -> f64 {
    SINES
        .iter()
        .map(|&(_, _, f)| {
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for n in 0..4000 {
                let phase = (2.0 * PI * f * n as f64 * DT + PI).rem_euclid(2.0 * PI) - PI;
                a.push(math::sin_cos(phase as f32).0 as f64);
                b.push(phase.sin());
            }
            nrmse(&a, &b)
        })
        .fold(0.0, f64::max)
}

/// Worst relative error of `f32` against `f64` over `xs`.
fn max_rel(xs: impl Iterator<Item = f64>, f32_fn: impl Fn(f32) -> f32, f64_fn: impl Fn(f64) -> f64) -> f64 {
    xs.map(|x| {
        let x = x as f32; // the reference sees the same (rounded) argument
        let r = f64_fn(x as f64);
        ((f32_fn(x) as f64 - r) / r.abs().max(1e-30)).abs()
    })
    .fold(0.0, f64::max)
}

#[test]
fn f32_math_against_f64_reference() {
    let lin = |lo: f64, hi: f64| (0..2000).map(move |k| lo + (hi - lo) * k as f64 / 1999.0);
    type Measure = fn() -> f64;
    let functions: [(&str, u8, &str, &str, Measure); 3] = [
        (
            "exp",
            audit::EXP,
            "own f32 table + cubic",
            "Langevin L and L' in the mid range 0.5 ≤ x < 9 (J–A, anhysteretic)",
            forward_chain_nrmse,
        ),
        ("sqrt", audit::SQRT, "libm", "inverse magnetostriction (compensator)", inverse_nrmse),
        ("sin_cos", audit::SIN_COS, "libm", "reference waveform generator (firmware)", waveform_nrmse),
    ];
    // (function, implementation, chosen, max relative error, output NRMSE)
    let mut rows: Vec<(&str, &str, bool, f64, f64)> = Vec::new();
    println!(
        "| function | used for | implementation | max rel. error of the function | output NRMSE vs f64 |"
    );
    println!("|---|---|---|---|---|");
    for (name, bit, chosen, used, measure) in functions {
        let mut alternatives = vec![(chosen, None)];
        if name == "exp" {
            alternatives.push(("libm", Some(audit::LIBM)));
        }
        alternatives.push(("micromath", Some(audit::MICROMATH)));
        for (implementation, alt) in alternatives {
            match alt {
                Some(a) => audit::route(bit, a),
                None => audit::reset(),
            }
            let fn_err = match name {
                "exp" => max_rel(lin(-18.0, -1.0), math::exp, f64::exp),
                "sqrt" => max_rel(lin(1e-6, 4e11), math::sqrt, f64::sqrt),
                _ => max_rel(lin(0.05, 3.1), |x| math::sin_cos(x).0, f64::sin),
            };
            let out = measure();
            audit::reset();
            let mark = if alt.is_none() { " (chosen)" } else { "" };
            println!("| `{name}` | {used} | {implementation}{mark} | {fn_err:.1e} | {out:.1e} |");
            rows.push((name, implementation, alt.is_none(), fn_err, out));
        }
    }
    let get = |n: &str, i: &str| rows.iter().find(|r| r.0 == n && r.1 == i).map(|r| (r.3, r.4)).unwrap();
    // The chosen implementations keep the f32 chain on the f64 reference …
    let (exp_err, chain) = get("exp", "own f32 table + cubic");
    assert!(exp_err < 1.5e-7, "exp: relative error {exp_err:e}");
    assert!(chain < 1e-4, "f32 ja+eddy+mech vs f64: NRMSE {chain:e}");
    let (_, chain_libm) = get("exp", "libm");
    assert!(chain < 2.0 * chain_libm, "own exp {chain:e} should match libm {chain_libm:e}");
    let (_, inv) = get("sqrt", "libm");
    assert!(inv < 1e-3, "compensator tracking NRMSE {inv:e}");
    let (_, wave) = get("sin_cos", "libm");
    assert!(wave < 1e-6, "sine NRMSE {wave:e}");
    // … and each micromath substitute costs at least an order of magnitude in the output, which is
    // why it is not used (if micromath improved, this fails and the choice is revisited).
    for (n, chosen_out) in [("exp", chain), ("sqrt", inv), ("sin_cos", wave)] {
        let (_, mm) = get(n, "micromath");
        assert!(mm > 10.0 * chosen_out, "{n}: micromath {mm:e} vs chosen {chosen_out:e}");
    }
}
