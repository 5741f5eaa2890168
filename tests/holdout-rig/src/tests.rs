//! Physics sanity of the rig: each test has a contrast that fails when the effect is missing.

use super::*;

fn quiet(law: Law, effects: Effects) -> Rig {
    Rig { law, effects: Effects { sensor_noise: false, ..effects }, ..Rig::default() }
}

/// ∮ H dM over the last `period` samples.
fn loop_area(rec: &Recording, period: usize) -> f64 {
    let n = rec.time_s.len();
    let (h, m) = (&rec.rod_field_a_per_m, &rec.magnetization_a_per_m);
    (n - period..n).map(|k| 0.5 * (h[k] + h[k - 1]) * (m[k] - m[k - 1])).sum()
}

#[test]
fn hysteresis_dissipates_energy_and_the_anhysteretic_law_does_not() {
    for law in [Law::ColemanHodgdon, Law::LorentzPreisach] {
        let drive = Drive::sine(1.5, 5.0, 0.6);
        let static_rig = Effects { eddy_current: false, ..Effects::NONE };
        let hyst = quiet(law, Effects { saturation: true, hysteresis: true, ..static_rig }).simulate(&drive);
        let anh = quiet(law, Effects { saturation: true, ..static_rig }).simulate(&drive);
        let ms = Rig::default().ms_a_per_m;
        let (a_h, a_a) = (loop_area(&hyst, 2000), loop_area(&anh, 2000));
        // Loss per cycle > 0 (second law), and well above the anhysteretic law's (≈ 0).
        assert!(a_h > 1e-3 * ms * 1000.0, "{law:?}: loop area {a_h}");
        assert!(a_a.abs() < 0.01 * a_h, "{law:?}: anhysteretic area {a_a} vs {a_h}");
    }
}

#[test]
fn periodic_drive_gives_a_closed_loop() {
    for law in [Law::ColemanHodgdon, Law::LorentzPreisach] {
        let rig = quiet(law, Effects { saturation: true, hysteresis: true, ..Effects::NONE });
        let rec = rig.simulate(&Drive::sine(1.5, 10.0, 0.5));
        let m = &rec.magnetization_a_per_m;
        let n = m.len();
        // One period = 1000 samples: the last two cycles coincide.
        let drift = (n - 1000..n).map(|k| (m[k] - m[k - 1000]).abs()).fold(0.0, f64::max);
        assert!(drift < 1e-3 * rig.ms_a_per_m, "{law:?}: loop does not close, drift {drift}");
    }
}

#[test]
fn everett_function_matches_a_direct_quadrature_of_the_density() {
    let p = LorentzPreisach::new(5000.0, 9000.0, 150_000.0);
    let g = |x: f64, c: f64| (9000.0 / PI) / ((x - c).powi(2) + 9000.0f64.powi(2));
    for (alpha, beta) in [(20_000.0, -10_000.0), (3000.0, 1000.0), (100_000.0, -100_000.0)] {
        // Midpoint rule over the triangle β ≤ b ≤ a ≤ α of g(a) g(−b).
        let n = 1500;
        let d = (alpha - beta) / n as f64;
        let mut sum = 0.0;
        for ia in 0..n {
            let a = beta + (ia as f64 + 0.5) * d;
            for ib in 0..n {
                let b = beta + (ib as f64 + 0.5) * d;
                if b < a {
                    sum += g(a, 5000.0) * g(b, -5000.0) * d * d;
                }
            }
        }
        let e = p.everett(alpha, beta);
        assert!((e - sum).abs() < 2e-3 * sum.max(1e-3), "E({alpha}, {beta}) = {e}, quadrature {sum}");
    }
}

#[test]
fn preisach_minor_loops_return_to_their_reversal_points() {
    let mut p = LorentzPreisach::new(5000.0, 9000.0, 150_000.0);
    let high = p.apply(40_000.0);
    let at_reversal = p.apply(-8_000.0);
    p.apply(2_000.0);
    p.apply(-3_000.0);
    p.apply(1_000.0);
    // Back down to the reversal point: the inner loops are wiped out, the output returns exactly.
    let back = p.apply(-8_000.0);
    assert!((back - at_reversal).abs() < 1e-9, "{back} vs {at_reversal}");
    assert!(at_reversal < high);
    assert!((p.apply(150_000.0) - 1.0).abs() < 1e-9 && (p.apply(-150_000.0) + 1.0).abs() < 1e-9);
}

#[test]
fn two_rod_modes_carry_the_static_compliance() {
    let rig = Rig::default();
    let modes = rod_modes(&rig, 60);
    let total: f64 = modes.iter().map(|m| m.1).sum();
    assert!((total - 1.0).abs() < 2e-3, "Σ shares = {total}");
    assert!(modes[0].1 + modes[1].1 > 0.98);
    // Rayleigh: a spring E A/L with the load plus a third of the rod's mass.
    let area = PI * rig.rod_radius_m.powi(2);
    let k = rig.rod_young_pa * area / rig.rod_length_m;
    let m = rig.load_mass_kg + rig.rod_density_kg_per_m3 * area * rig.rod_length_m / 3.0;
    let rayleigh = (k / m).sqrt();
    assert!((modes[0].0 / rayleigh - 1.0).abs() < 0.01, "{} vs {rayleigh}", modes[0].0);
}

#[test]
fn coil_heating_grows_with_current_squared_and_the_limit_holds() {
    let fx = Effects { amplifier_dynamics: true, thermal_drift: true, ..Effects::NONE };
    let rise = |amp: f64| {
        let rec =
            quiet(Law::ColemanHodgdon, fx).simulate(&Drive { offset_v: amp, ..Drive::sine(0.0, 1.0, 0.3) });
        rec.temperature_c.last().unwrap() - rec.temperature_c[0]
    };
    let ratio = rise(0.4) / rise(0.2);
    assert!((ratio - 4.0).abs() < 0.2, "ΔT ratio {ratio}");
    let cold = quiet(Law::ColemanHodgdon, Effects { thermal_drift: false, ..fx })
        .simulate(&Drive { offset_v: 0.4, ..Drive::sine(0.0, 1.0, 0.3) });
    assert_eq!(cold.temperature_c.last(), Some(&22.0));
    let hard = quiet(Law::ColemanHodgdon, fx).simulate(&Drive::sine(3.0, 50.0, 0.1));
    let peak = hard.true_current_a.iter().fold(0.0f64, |a, &i| a.max(i.abs()));
    assert!(peak <= 2.5 + 1e-9 && peak > 2.4, "peak current {peak}");
}

#[test]
fn eddy_ladder_lags_at_high_frequency_only() {
    let fx = Effects { eddy_current: true, ..Effects::NONE };
    // Peak amplitude of the fundamental over the second half (whole cycles).
    let swing = |f: f64, on: bool| {
        let rig = quiet(Law::ColemanHodgdon, Effects { eddy_current: on, ..fx });
        let rec = rig.simulate(&Drive::sine(1.0, f, 20.0 / f));
        let n = rec.time_s.len();
        let (mut s, mut c) = (0.0, 0.0);
        for k in n / 2..n {
            let phase = 2.0 * PI * f * rec.time_s[k];
            s += rec.rod_field_a_per_m[k] * phase.sin();
            c += rec.rod_field_a_per_m[k] * phase.cos();
        }
        2.0 * 2.0 * (s * s + c * c).sqrt() / (n - n / 2) as f64
    };
    let full = 2.0 * 1.2 * 10_000.0;
    assert!((swing(10.0, true) / full - 1.0).abs() < 0.01);
    assert!(swing(2000.0, true) / full < 0.85, "{}", swing(2000.0, true) / full);
    assert!((swing(2000.0, false) / full - 1.0).abs() < 0.02);
}

#[test]
fn aftereffect_creeps_logarithmically() {
    let fx = Effects { saturation: true, magnetic_aftereffect: true, ..Effects::NONE };
    // A current step 0 → 1 V at t = 2 s (the rig starts steady at 0 V).
    let step = Drive { waveform: Waveform::Square, offset_v: 0.5, ..Drive::sine(-0.5, 0.25, 3.1) };
    let rec = quiet(Law::ColemanHodgdon, fx).simulate(&step);
    let x = &rec.true_displacement_um;
    let (d1, d2) = (x[21_000] - x[20_100], x[30_000] - x[21_000]);
    assert!(d1 > 0.0 && d2 > 0.0);
    // Equal creep per decade of time, within the six-term approximation.
    assert!((d2 / d1 - 1.0).abs() < 0.35, "creep per decade {d1} then {d2}");
    let none = quiet(Law::ColemanHodgdon, Effects { magnetic_aftereffect: false, ..fx }).simulate(&step);
    let y = &none.true_displacement_um;
    assert!((y[30_000] - y[20_100]).abs() < 1e-6);
}

#[test]
fn every_output_is_finite_and_a_seed_fixes_the_noise() {
    for law in [Law::ColemanHodgdon, Law::LorentzPreisach] {
        for waveform in [
            Waveform::Sine,
            Waveform::Triangle,
            Waveform::Square,
            Waveform::Chirp,
            Waveform::Multisine,
            Waveform::Sweep,
        ] {
            let drive = Drive { waveform, f_end_hz: 800.0, ..Drive::sine(1.0, 40.0, 0.05) };
            let rig = Rig { law, ..Rig::default() };
            let a = rig.simulate(&drive);
            assert_eq!(a.time_s.len(), 500);
            assert!(a.displacement_um.iter().chain(&a.current_a).all(|v| v.is_finite()));
            let mut csv_a = Vec::new();
            a.write_csv(&mut csv_a).unwrap();
            let mut csv_b = Vec::new();
            rig.simulate(&drive).write_csv(&mut csv_b).unwrap();
            assert_eq!(csv_a, csv_b);
            let mut csv_c = Vec::new();
            Rig { seed: 2, ..rig }.simulate(&drive).write_csv(&mut csv_c).unwrap();
            assert_ne!(csv_a, csv_c);
        }
    }
}

#[test]
fn the_rig_starts_magnetised() {
    for law in [Law::ColemanHodgdon, Law::LorentzPreisach] {
        let fx = Effects { saturation: true, hysteresis: true, ..Effects::NONE };
        let drive = Drive::sine(0.0, 1.0, 0.01);
        let pre = quiet(law, Effects { premagnetised: true, ..fx }).simulate(&drive);
        let virgin = quiet(law, fx).simulate(&drive);
        let gap = pre.magnetization_a_per_m[0] - virgin.magnetization_a_per_m[0];
        assert!(gap.abs() > 0.01 * Rig::default().ms_a_per_m, "{law:?}: {gap}");
    }
}

#[test]
fn stroke_is_tens_of_micrometres() {
    for law in [Law::ColemanHodgdon, Law::LorentzPreisach] {
        let rec = Rig { law, ..Rig::default() }.simulate(&Drive::sine(1.0, 20.0, 0.2));
        let x = &rec.true_displacement_um[1000..];
        let span = x.iter().fold(f64::MIN, |a, &v| a.max(v)) - x.iter().fold(f64::MAX, |a, &v| a.min(v));
        println!("{law:?}: stroke {span} µm");
        assert!((5.0..100.0).contains(&span), "{law:?}: stroke {span} µm");
    }
}
