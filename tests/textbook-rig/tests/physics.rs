//! The rig against closed forms, its own tolerance, rate independence, noise and loop shape.

use std::f64::consts::PI;
use textrig::*;

fn exp(structure: &str, drive: Drive, duration_s: f64) -> Experiment {
    Experiment {
        structure: structure.into(),
        params: Params::terfenol(),
        drive,
        duration_s,
        rate_hz: 10_000.0,
        start: Start::Demagnetised,
        noise: Noise::none(),
        seed: 7,
        log_flux: false,
        log_temperature: false,
    }
}

fn sine(f: f64, amp: f64, off: f64) -> Drive {
    Drive { waveform: Waveform::Sine { freq_hz: f }, amplitude: amp, offset: off }
}

fn range(x: &[f64]) -> f64 {
    let lo = x.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = x.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    hi - lo
}

/// Complex helpers for the mass–spring–damper G(jω) = ω_n²/(ω_n² − ω² + 2jζω_nω).
fn msd(wn: f64, z: f64, w: f64) -> (f64, f64) {
    let (re, im) = (wn * wn - w * w, 2.0 * z * wn * w);
    let d = re * re + im * im;
    (wn * wn * re / d, -wn * wn * im / d)
}

#[test]
fn linear_mech_matches_analytic_steady_state() {
    let f = 300.0;
    let (amp, off) = (0.9, 0.2);
    let mut e = exp("linear+mech", sine(f, amp, off), 0.1);
    e.params.rig.current_loop_tau_s = 0.0;
    let r = simulate(&e).unwrap();
    let p = &e.params;
    let n = p.coil.turns_per_m;
    let m0 = p.linear.offset_a_per_m + p.linear.susceptibility * (n * off + p.coil.bias_a_per_m);
    let m1 = p.linear.susceptibility * n * amp;
    let ms = &p.magnetostriction;
    let k = 1.5 * ms.lambda_s / (ms.ms_a_per_m * ms.ms_a_per_m) * p.rod_length_m * 1e6;
    let wn = 2.0 * PI * p.mech.natural_frequency_hz;
    let w = 2.0 * PI * f;
    let (g1r, g1i) = msd(wn, p.mech.damping_ratio, w);
    let (g2r, g2i) = msd(wn, p.mech.damping_ratio, 2.0 * w);
    let dc = k * (m0 * m0 + 0.5 * m1 * m1 - ms.bias_m_a_per_m * ms.bias_m_a_per_m);
    let mut worst: f64 = 0.0;
    let span = range(&r.truth.displacement_um);
    for (t, y) in r.time_s.iter().zip(&r.truth.displacement_um) {
        if *t < 0.05 {
            continue;
        }
        let th = w * t;
        // Im(G e^{jθ}) for the sine term, Re(G₂ e^{j2θ}) for the cosine term.
        let s1 = g1r * th.sin() + g1i * th.cos();
        let c2 = g2r * (2.0 * th).cos() - g2i * (2.0 * th).sin();
        let ya = dc + 2.0 * k * m0 * m1 * s1 - 0.5 * k * m1 * m1 * c2;
        worst = worst.max((y - ya).abs());
    }
    assert!(span > 1.0, "span {span}");
    eprintln!("linear+mech vs analytic: {:e} of the span", worst / span);
    assert!(worst / span <= 1e-6, "relative error {:e}", worst / span);
}

#[test]
fn amplifier_first_order_step() {
    let drive = Drive {
        waveform: Waveform::Steps { levels: vec![0.2, 1.0], hold_s: 0.01 },
        amplitude: 1.0,
        offset: 0.0,
    };
    let e = exp("amp", drive, 0.02);
    let r = simulate(&e).unwrap();
    let g = e.params.amp.gain_a_per_v;
    let tau = e.params.amp.tau_s;
    let mut worst: f64 = 0.0;
    for (t, i) in r.time_s.iter().zip(&r.truth.current_a) {
        let ia = if *t < 0.01 { 0.2 * g } else { 0.2 * g + 0.8 * g * (1.0 - (-(t - 0.01) / tau).exp()) };
        worst = worst.max((i - ia).abs());
    }
    eprintln!("amp step: worst {:e} of the step", worst / (0.8 * g));
    assert!(worst <= 1e-7 * g, "worst {worst:e}");
    assert_eq!(r.command_v.as_ref().unwrap()[150], 1.0);
}

#[test]
fn eddy_lag_step_behind_the_current_loop() {
    let drive = Drive {
        waveform: Waveform::Steps { levels: vec![0.0, 1.0], hold_s: 0.01 },
        amplitude: 1.0,
        offset: 0.0,
    };
    let e = exp("eddy", drive, 0.02);
    let r = simulate(&e).unwrap();
    let p = &e.params;
    let (te, tc) = (p.eddy_tau_s, p.rig.current_loop_tau_s);
    let dh = p.coil.turns_per_m;
    let mut worst: f64 = 0.0;
    for (t, h) in r.time_s.iter().zip(&r.truth.field_a_per_m) {
        let s = t - 0.01;
        let ha = p.coil.bias_a_per_m
            + if s < 0.0 {
                0.0
            } else {
                dh * (1.0 - (te * (-s / te).exp() - tc * (-s / tc).exp()) / (te - tc))
            };
        worst = worst.max((h - ha).abs());
    }
    eprintln!("eddy step: worst {:e} of the step", worst / dh);
    assert!(worst <= 1e-7 * dh, "worst {worst:e}");
}

#[test]
fn delay_shifts_by_exactly_a_fractional_d() {
    let mut e = exp("linear+delay", sine(170.0, 0.7, 0.1), 0.05);
    e.params.delay_samples = 1.3;
    let r = simulate(&e).unwrap();
    let mut u = exp("linear", sine(170.0, 0.7, 0.1), 0.05);
    u.rate_hz = 100_000.0;
    let ru = simulate(&u).unwrap();
    let span = range(&ru.truth.displacement_um);
    let mut worst: f64 = 0.0;
    for k in 2..r.time_s.len() {
        let j = 10 * k - 13;
        assert!((ru.time_s[j] - (r.time_s[k] - 1.3e-4)).abs() < 1e-12);
        worst = worst.max((r.truth.displacement_um[k] - ru.truth.displacement_um[j]).abs());
    }
    eprintln!("delay: worst {:e} of the span", worst / span);
    assert!(worst / span <= 1e-9, "relative {:e}", worst / span);
    // Before the delay has passed, the sensor reads the rest value.
    assert_eq!(r.truth.displacement_um[0], ru.truth.displacement_um[0]);
    // And it is not a whole-sample shift: 1 or 2 samples would be far off.
    let off1 = (r.truth.displacement_um[100] - r.truth.undelayed_displacement_um[99]).abs();
    assert!(off1 / span > 1e-3);
}

#[test]
fn langevin_static_curve_exact() {
    let e = exp("anhysteretic", sine(5.0, 2.0, 0.0), 0.2);
    let r = simulate(&e).unwrap();
    let p = &e.params.anhysteretic;
    for k in 0..r.time_s.len() {
        let h = r.truth.field_a_per_m[k];
        let hc = e.params.coil.turns_per_m * r.truth.current_a[k] + e.params.coil.bias_a_per_m;
        assert!((h - hc).abs() <= 1e-9 * hc.abs().max(1.0));
        let ma = p.ms_a_per_m * langevin(h / p.a_a_per_m);
        assert!((r.truth.magnetization_a_per_m[k] - ma).abs() <= 1e-12 * p.ms_a_per_m);
    }
    let x: f64 = 1e-3;
    assert!((langevin(x) - (x / 3.0 - x.powi(3) / 45.0 + 2.0 * x.powi(5) / 945.0)).abs() < 1e-19);
    // The series and the closed form agree where they meet.
    for x in [0.049_999_999_9_f64, 0.05] {
        let direct = 1.0 / x.tanh() - 1.0 / x;
        assert!((langevin(x) - direct).abs() < 1e-12 * direct, "{x}");
        let s = x.sinh();
        let d = 1.0 / (x * x) - 1.0 / (s * s);
        assert!((dlangevin(x) - d).abs() < 1e-12, "{x}");
    }
    assert!((langevin(2.0) - (1.0 / 2f64.tanh() - 0.5)).abs() < 1e-15);
}

#[test]
fn halving_the_tolerance_changes_ja_displacement_below_1e6() {
    let e = exp("ja+mech", sine(3.0, 1.2, 0.0), 0.5);
    let a = simulate_with(&e, &SolverOptions::default()).unwrap();
    let b = simulate_with(&e, &SolverOptions { rtol: 0.5e-9, atol_factor: 1.0 }).unwrap();
    let span = range(&a.truth.displacement_um);
    let worst = a
        .truth
        .displacement_um
        .iter()
        .zip(&b.truth.displacement_um)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    eprintln!("tolerance halving: {:e} of the span", worst / span);
    assert!(worst / span < 1e-6, "relative change {:e}", worst / span);
}

#[test]
fn ja_alone_is_rate_independent() {
    let run = |f: f64| {
        let mut e = exp("ja", sine(f, 1.5, 0.0), 2.0 / f);
        e.params.rig.current_loop_tau_s = 0.0;
        simulate(&e).unwrap()
    };
    let slow = run(1.0);
    let fast = run(500.0);
    let span = range(&slow.truth.magnetization_a_per_m);
    let mut worst: f64 = 0.0;
    for k in 0..fast.time_s.len() {
        let j = 500 * k;
        assert!((slow.truth.field_a_per_m[j] - fast.truth.field_a_per_m[k]).abs() < 1e-6);
        worst = worst.max((slow.truth.magnetization_a_per_m[j] - fast.truth.magnetization_a_per_m[k]).abs());
    }
    eprintln!("rate independence 1 Hz vs 500 Hz: {:e} of the span", worst / span);
    assert!(worst / span <= 1e-4, "relative {:e}", worst / span);
}

#[test]
fn current_noise_rms_grid_and_seed() {
    let base = exp("ja", sine(20.0, 1.0, 0.0), 0.5);
    for n in [1.0, 3.0] {
        let mut e = base.clone();
        e.noise = Noise::typical(n);
        let r = simulate(&e).unwrap();
        let dev: Vec<f64> = r.current_a.iter().zip(&r.truth.current_a).map(|(a, b)| a - b).collect();
        let rms = (dev.iter().map(|d| d * d).sum::<f64>() / dev.len() as f64).sqrt() / CURRENT_LSB_A;
        eprintln!("current noise N = {n}: rms {rms:.4} LSB");
        assert!((rms / n - 1.0).abs() <= 0.1, "N = {n}: rms {rms} LSB");
        for c in &r.current_a {
            let code = c / CURRENT_LSB_A;
            assert_eq!(code, code.round(), "{c} off the LSB grid");
        }
        let again = simulate(&e).unwrap();
        assert_eq!(r.current_a, again.current_a);
        assert_eq!(r.displacement_um, again.displacement_um);
        let mut other = e.clone();
        other.seed += 1;
        assert_ne!(simulate(&other).unwrap().current_a, r.current_a);
    }
    let r = simulate(&base).unwrap();
    assert_eq!(r.current_a, r.truth.current_a);
    assert_eq!(r.displacement_um, r.truth.displacement_um);
}

fn check_loop(structure: &str, params: Params, ms: f64) {
    let f = 2.0;
    let mut e = exp(structure, sine(f, 2.0, 0.0), 3.0 / f);
    e.params = params;
    e.rate_hz = 4000.0;
    let r = simulate(&e).unwrap();
    let n = r.time_s.len();
    let per = (e.rate_hz / f) as usize;
    let (h, m) = (&r.truth.field_a_per_m, &r.truth.magnetization_a_per_m);
    let start = n - per - 1;
    let span = range(&m[start..]);
    let close = (m[n - 1] - m[n - 1 - per]).abs();
    assert!(close <= 2e-3 * span, "{structure}: loop not closed ({close} of {span})");
    let mut area = 0.0;
    for k in start..n - 1 {
        area += 0.5 * (m[k] + m[k + 1]) * (h[k + 1] - h[k]);
    }
    let box_ = range(&h[start..]) * span;
    eprintln!(
        "{structure} {:?}: closure {:e}, area/box {:.4}",
        e.params.ja.variant,
        close / span,
        area / box_
    );
    assert!(area < -0.01 * box_, "{structure}: ∮M dH = {area:e} (box {box_:e}): not counter-clockwise");
    assert!(m.iter().all(|x| x.abs() <= ms), "{structure}: |M| > M_s");
}

#[test]
fn every_ja_form_and_preisach_give_closed_counterclockwise_loops() {
    for v in JaVariant::ALL {
        let mut p = Params::terfenol();
        p.ja.variant = v;
        let ms = p.ja.ms_a_per_m;
        check_loop("ja", p, ms);
    }
    let p = Params::terfenol();
    let ms = p.preisach.ms_a_per_m;
    check_loop("preisach", p.clone(), ms);
    let mut q = p;
    q.preisach.interaction_spread_a_per_m = None;
    check_loop("preisach", q, ms);
}

#[test]
fn structure_errors_name_the_effect_and_params_round_trip() {
    let mut e = exp("ja+mhec", sine(1.0, 1.0, 0.0), 0.1);
    match simulate(&e) {
        Err(RigError::UnknownEffect(s)) => assert_eq!(s, "mhec"),
        other => panic!("{other:?}"),
    }
    e.structure = "preisach+ja".into();
    assert!(matches!(simulate(&e), Err(RigError::BadStructure(_))));
    e.structure = "ja".into();
    e.params.ja.c = 1.5;
    let msg = simulate(&e).unwrap_err().to_string();
    assert!(msg.contains("ja.c"), "{msg}");
    let mut p = Params::terfenol();
    p.ja.variant = JaVariant::Szewczyk;
    p.amp_second_order = Some(AmpSecondOrder { k_u: 1.0, a_s: 4.8e-4, b_s2: 2.5e-8, c_s: 6.4e-4 });
    let mut back = Params::terfenol();
    back.apply_gma_toml(&p.to_gma_toml()).unwrap();
    assert_eq!(back, p);
}

#[test]
fn csv_has_the_documented_header_and_time_digits() {
    let mut e = exp("amp+ja+thermal", sine(5.0, 0.5, 0.2), 0.01);
    e.log_flux = true;
    e.log_temperature = true;
    let r = simulate(&e).unwrap();
    let mut buf = Vec::new();
    r.write_csv(&mut buf).unwrap();
    let text = String::from_utf8(buf).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_s,command_V,current_A,displacement_um,temperature_C,flux_density_T"
    );
    assert!(lines.next().unwrap().starts_with("0.0000000,"));
    assert_eq!(text.lines().count(), r.time_s.len() + 1);
}

#[test]
fn second_order_amplifier_matches_its_frequency_response() {
    let mut e = exp("amp", sine(500.0, 1.0, 0.0), 0.05);
    let (k, a, b, c) = (1.0, 4.8e-4, 2.5e-8, 6.4e-4);
    e.params.amp_second_order = Some(AmpSecondOrder { k_u: k, a_s: a, b_s2: b, c_s: c });
    let r = simulate(&e).unwrap();
    let w = 2.0 * PI * 500.0;
    // G(jω) = k (1 + jωA)/(1 − Bω² + jCω).
    let (nr, ni) = (k, k * w * a);
    let (dr, di) = (1.0 - b * w * w, c * w);
    let d2 = dr * dr + di * di;
    let (gr, gi) = ((nr * dr + ni * di) / d2, (ni * dr - nr * di) / d2);
    let mag = (gr * gr + gi * gi).sqrt();
    assert!((mag - 0.84).abs() < 0.01, "|G(500 Hz)| = {mag}");
    let mut worst: f64 = 0.0;
    for (t, i) in r.time_s.iter().zip(&r.truth.current_a) {
        if *t < 0.02 {
            continue;
        }
        let ia = gr * (w * t).sin() + gi * (w * t).cos();
        worst = worst.max((i - ia).abs());
    }
    eprintln!("second-order amp: |G| = {mag:.4}, worst {worst:e} A");
    assert!(worst <= 1e-7, "worst {worst:e}");
}

#[test]
fn aftereffect_step_is_the_documented_creep() {
    let drive = Drive {
        waveform: Waveform::Steps { levels: vec![0.0, 1.0], hold_s: 0.1 },
        amplitude: 0.5,
        offset: 0.0,
    };
    let mut e = exp("linear+aftereffect", drive, 0.2);
    e.params.rig.current_loop_tau_s = 0.0;
    let r = simulate(&e).unwrap();
    let p = &e.params;
    let m0 = p.linear.offset_a_per_m + p.linear.susceptibility * p.coil.bias_a_per_m;
    let dm = p.linear.susceptibility * p.coil.turns_per_m * 0.5;
    let (wf, tau) = (p.aftereffect.fraction, p.aftereffect.tau_s);
    let mut worst: f64 = 0.0;
    for (t, m) in r.time_s.iter().zip(&r.truth.magnetization_a_per_m) {
        let s = t - 0.1;
        let ma = if s < 0.0 { m0 } else { m0 + dm * ((1.0 - wf) + wf * (1.0 - (-s / tau).exp())) };
        worst = worst.max((m - ma).abs());
    }
    eprintln!("aftereffect step: worst {:e} of the step", worst / dm);
    assert!(worst <= 1e-8 * dm, "worst {worst:e}");
}

#[test]
fn thermal_heating_and_rod_lag_closed_form() {
    let drive =
        Drive { waveform: Waveform::Steps { levels: vec![1.0], hold_s: 100.0 }, amplitude: 1.5, offset: 0.0 };
    let mut e = exp("linear+thermal", drive.clone(), 20.0);
    e.rate_hz = 100.0;
    e.params.rig.current_loop_tau_s = 0.0;
    let r = simulate(&e).unwrap();
    let mut cold = exp("linear", drive, 20.0);
    cold.rate_hz = 100.0;
    cold.params.rig.current_loop_tau_s = 0.0;
    let rc = simulate(&cold).unwrap();
    let th = &e.params.thermal;
    let rise = th.thermal_resistance_c_per_w * th.coil_resistance_ohm * 1.5 * 1.5;
    let (tc, tr) = (th.tau_s, th.rod_tau_s);
    let mut worst_t: f64 = 0.0;
    let mut worst_y: f64 = 0.0;
    for k in 0..r.time_s.len() {
        let t = r.time_s[k];
        let coil = rise * (1.0 - (-t / tc).exp());
        let rod = rise * (1.0 - (tc * (-t / tc).exp() - tr * (-t / tr).exp()) / (tc - tr));
        worst_t = worst_t.max((r.truth.temperature_c[k] - e.params.rig.ambient_c - coil).abs());
        let dy = 1e6 * th.expansion_per_c * th.rod_length_m * rod;
        worst_y = worst_y.max((r.truth.displacement_um[k] - rc.truth.displacement_um[k] - dy).abs());
    }
    eprintln!("thermal: worst {:e} °C, {:e} µm (rise {rise} °C)", worst_t, worst_y);
    assert!(worst_t <= 1e-8 * rise);
    assert!(worst_y <= 1e-8 * 1e6 * th.expansion_per_c * th.rod_length_m * rise);
}

#[test]
fn a_history_start_continues_the_pre_drive() {
    let d = sine(5.0, 1.2, 0.1);
    let long = simulate(&exp("ja+mech+delay", d.clone(), 0.6)).unwrap();
    let mut e = exp("ja+mech+delay", d.clone(), 0.2);
    e.start = Start::History { drive: d, duration_s: 0.4 };
    let r = simulate(&e).unwrap();
    let span = range(&long.truth.displacement_um);
    let mut worst: f64 = 0.0;
    for k in 0..r.time_s.len() {
        worst = worst.max((r.truth.displacement_um[k] - long.truth.displacement_um[4000 + k]).abs());
        worst = worst.max(
            (r.truth.magnetization_a_per_m[k] - long.truth.magnetization_a_per_m[4000 + k]).abs() / 7.65e5
                * span,
        );
    }
    eprintln!("history start vs one long run: {:e} of the span", worst / span);
    assert!(worst / span <= 1e-6, "relative {:e}", worst / span);
}

/// Brute-force 2-D Gauss–Legendre (composite) measure of {b ≤ β ≤ α ≤ a} for the interaction
/// density, in (α, β) directly: an independent check of the closed-form/adaptive Everett.
fn brute_everett(p: &PreisachParams, a: f64, b: f64) -> f64 {
    let gl = [
        (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
        (-0.538_469_310_105_683, 0.478_628_670_499_366_5),
        (0.0, 0.568_888_888_888_888_9),
        (0.538_469_310_105_683, 0.478_628_670_499_366_5),
        (0.906_179_845_938_664, 0.236_926_885_056_189_1),
    ];
    let lor = |x: f64| 1.0 / (1.0 + x * x);
    let su = p.interaction_spread_a_per_m.unwrap();
    let dens = |al: f64, be: f64| {
        let (h, u) = (0.5 * (al - be), 0.5 * (al + be));
        lor((h - p.coercive_a_per_m) / p.spread_a_per_m) * lor(u / su)
    };
    let n = 400;
    let da = (a - b) / n as f64;
    let mut total = 0.0;
    for i in 0..n {
        for (xa, wa) in gl {
            let al = b + da * (i as f64 + 0.5 + 0.5 * xa);
            // β from b to α.
            let m = 80;
            let db = (al - b) / m as f64;
            for j in 0..m {
                for (xb, wb) in gl {
                    let be = b + db * (j as f64 + 0.5 + 0.5 * xb);
                    total += 0.25 * wa * wb * da * db * dens(al, be);
                }
            }
        }
    }
    total
}

#[test]
fn everett_function_matches_brute_force_and_memory_wipes_out() {
    let p = Params::terfenol().preisach;
    let ev = preisach::Everett::new(&p);
    let hm = p.h_max_a_per_m;
    assert!((ev.e(hm, -hm) - 1.0).abs() < 1e-14);
    let tot = brute_everett(&p, hm, -hm);
    for (a, b) in [(hm, -hm), (2.0e4, -5.0e3), (1.0e4, 2.0e3), (-3.0e3, -4.0e4)] {
        let want = brute_everett(&p, a, b) / tot;
        let got = ev.e(a, b);
        eprintln!("E({a}, {b}) = {got:.12} (brute force {want:.12})");
        assert!((got - want).abs() < 1e-9, "E({a}, {b}) = {got} vs {want}");
    }
    // Return-point memory: up to 2e4, down to −1e4, up to 2e4 again gives the first state back,
    // and the minor loop is wiped out (an excursion beyond 2e4 ignores it).
    let mut m = preisach::Memory::negative(&ev);
    m.commit(&ev, 2.0e4, 1.0);
    let first = m.up(&ev, 2.0e4, 1.0);
    m.commit(&ev, -1.0e4, -1.0);
    let low = m.up(&ev, -1.0e4, -1.0);
    m.commit(&ev, 2.0e4, 1.0);
    assert!((m.up(&ev, 2.0e4, 1.0) - first).abs() < 1e-15);
    assert!(low < first);
    let mut fresh = preisach::Memory::negative(&ev);
    fresh.commit(&ev, 3.0e4, 1.0);
    assert!((m.up(&ev, 3.0e4, 1.0) - fresh.up(&ev, 3.0e4, 1.0)).abs() < 1e-15);
    // Saturation: all relays up at +H_max, all down at −H_max.
    assert!((fresh.up(&ev, hm, 1.0) - 1.0).abs() < 1e-14);
    assert!(fresh.up(&ev, -hm, -1.0).abs() < 1e-14);
}
