//! The identified mechanics (f_n, ζ): damped at least by ζ = 1e-3, refused where its f32 step
//! would not decay, and finite however stiff and fast the mode and however hard it is driven.

use model_core::chain::ModalMechanics;
use model_core::mechanics::MechState;
use model_core::{Actuator, ActuatorParams, ModelSpec};

/// Undamped, the f32-rounded transition matrix set the amplitude (a free oscillation at 1584 Hz,
/// 10 kHz, grew 2.48× over 1e8 samples): ζ below 1e-3 is refused by name. At the floor, a mode
/// whose decay per sample (ζ 2π f_n dt = 1.3e-7) is near the rounding of the step still decays;
/// one ten times slower is refused by f_n.
#[test]
fn a_free_oscillation_decays_or_the_mode_is_refused_by_name() {
    let undamped = ModalMechanics { natural_frequency_hz: 1584.0, damping_ratio: 0.0 };
    assert_eq!(undamped.discretised(1e-4).err().map(|e| e.name()), Some("mech.damping_ratio"));
    let slow = ModalMechanics { natural_frequency_hz: 0.2, damping_ratio: ModalMechanics::MIN_DAMPING_RATIO };
    let zoh = slow.discretised(1e-4).unwrap();
    let mut s = MechState { displacement_m: 1.0, velocity_m_per_rad: 0.0 };
    let mut peak = 0.0f32;
    for n in 0..10_000_000 {
        let y = zoh.step(&mut s, 0.0);
        if n >= 10_000_000 - 60_000 {
            peak = peak.max(y.abs()); // the last period and more
        }
    }
    // Exact: e^{−ζ ω_n t} = e^{−1.26} = 0.28; the rounding takes about a tenth of the decay.
    assert!(peak < 0.4, "amplitude after 1e7 samples: {peak}");
    let slower = ModalMechanics { natural_frequency_hz: 0.01, ..slow };
    assert_eq!(slower.discretised(1e-4).err().map(|e| e.name()), Some("mech.natural_frequency_hz"));
}

/// The largest free displacement the other bounds allow (linear law: 1e7 A through 1e7 turns/m
/// and χ = 1e5, λ_s = 1 over M_s = 1e3 on a 10 m rod: about 1e33 m) into a 1 MHz or a 5 kHz mode
/// at 10 kHz, driven at the Nyquist rate: finite. The velocity in m/s was 1e40 at the first
/// sample (now the state carries ẏ/ω_n, as large as the displacement's swing).
#[test]
fn a_stiff_fast_mode_driven_hard_stays_finite() {
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.amp.gain_a_per_v = 1e3;
    p.coil.turns_per_m = 1e7;
    p.coil.bias_a_per_m = 0.0;
    p.linear.susceptibility = 1e5;
    p.magnetostriction.lambda_s = 1.0;
    p.magnetostriction.ms_a_per_m = 1e3;
    p.rod_length_m = 10.0;
    p.mech.damping_ratio = ModalMechanics::MIN_DAMPING_RATIO;
    for f_n in [1.0025e6, 5e3] {
        p.mech.natural_frequency_hz = f_n;
        let m = Actuator::new(ModelSpec::parse("amp+linear+mech").unwrap(), &p).unwrap();
        let mut s = m.rest_state();
        for n in 0..2000 {
            let o = m.step(&mut s, if n % 2 == 0 { 1e4 } else { -1e4 }).unwrap();
            assert!(o.displacement_m.is_finite(), "{f_n} Hz, sample {n}: {o:?} ({:?})", s.mech);
        }
    }
}

/// A natural frequency so high (or low) that 1/ω_n² leaves f32 was refused as `mech.mass_kg`, a
/// derived value the parameter file does not hold: the frequency itself is refused by name, with
/// its range, and the ends of that range still step.
#[test]
fn a_natural_frequency_beyond_f32_is_refused_by_its_own_name() {
    for f_n in [1e30, 2e9, 1e-21, 0.0, -5.0] {
        let m = ModalMechanics { natural_frequency_hz: f_n, damping_ratio: 0.3 };
        let e = m.unit_gain().err();
        assert_eq!(e.map(|e| e.name()), Some("mech.natural_frequency_hz"), "{f_n} Hz");
    }
    let mut p = ActuatorParams::TERFENOL_DEMO;
    p.mech.natural_frequency_hz = ModalMechanics::MAX_NATURAL_FREQUENCY_HZ;
    let m = Actuator::new(ModelSpec::parse("ja+mech").unwrap(), &p).unwrap();
    let mut s = m.rest_state();
    for n in 0..200 {
        let o = m.step(&mut s, (n as f32 * 0.1).sin()).unwrap();
        assert!(o.displacement_m.is_finite(), "sample {n}: {o:?}");
    }
    let low =
        ModalMechanics { natural_frequency_hz: ModalMechanics::MIN_NATURAL_FREQUENCY_HZ, damping_ratio: 0.3 };
    let msd = low.unit_gain().unwrap();
    assert!(msd.mass_kg.is_finite() && msd.damping_n_s_per_m.is_finite(), "{msd:?}");
}

/// At the largest damping ratio accepted the step still follows the first-order lag it tends to
/// (τ = 2ζ/ω_n); beyond it the mode is refused by name: far beyond, the overdamped step's slow
/// pole cancelled to 0.
#[test]
fn an_overdamped_mode_follows_its_lag_up_to_the_largest_damping_ratio() {
    let dt = 1e-4f32;
    let at_limit =
        ModalMechanics { natural_frequency_hz: 1584.0, damping_ratio: ModalMechanics::MAX_DAMPING_RATIO };
    let zoh = at_limit.discretised(dt).unwrap();
    let tau = 2.0 * f64::from(at_limit.damping_ratio) / (2.0 * std::f64::consts::PI * 1584.0);
    let mut s = MechState::default();
    for n in 1..=20 {
        let y = f64::from(zoh.step(&mut s, 1.0));
        let lag = 1.0 - (-(n as f64) * f64::from(dt) / tau).exp();
        assert!((y - lag).abs() < 1e-3 * lag, "sample {n}: {y} against the lag's {lag}");
    }
    let beyond = ModalMechanics { damping_ratio: 1.01 * ModalMechanics::MAX_DAMPING_RATIO, ..at_limit };
    assert_eq!(beyond.discretised(dt).err().map(|e| e.name()), Some("mech.damping_ratio"));
}
