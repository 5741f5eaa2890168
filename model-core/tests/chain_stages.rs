//! The actuator chain's partial steps and queries (`Actuator::step_field`,
//! `step_magnetic_on_branch`, the hysteresis refinements): each is the corresponding part of a
//! whole `step`, so a caller that splits a sample gets what the whole sample gives.

use model_core::chain::MAX_INPUT;
use model_core::magnetization::JaBranch;
use model_core::{Actuator, ActuatorParams, ModelSpec, StepError};

fn model(spec: &str) -> Actuator {
    Actuator::new(ModelSpec::parse(spec).unwrap(), &ActuatorParams::TERFENOL_DEMO).unwrap()
}

/// A drive with both signs and a reversal (coil current or command [V]).
fn drive(n: usize) -> f32 {
    3.0 * libm::sinf(n as f32 * 0.05) + 1.5 * libm::sinf(n as f32 * 0.31)
}

/// `step_field` moves the amplifier and eddy lag exactly as a whole step does, returns that
/// step's current and rod field, and leaves the magnetic state alone.
#[test]
fn step_field_is_the_first_stages_of_a_step() {
    for spec in ["ja", "ja+eddy", "ja+amp", "ja+eddy+amp+aftereffect", "preisach+eddy+amp"] {
        let m = model(spec);
        let (mut split, mut whole) = (m.rest_state(), m.rest_state());
        for n in 0..300 {
            let u = drive(n);
            let (ja_before, preisach_before) = (split.ja, split.preisach);
            let (current, h) = m.step_field(&mut split, u).unwrap();
            let out = m.step(&mut whole, u).unwrap();
            assert_eq!((current, h), (out.current_a, out.field_a_per_m), "{spec}, sample {n}");
            assert_eq!((split.amp, split.rod_field_a_per_m), (whole.amp, whole.rod_field_a_per_m));
            assert!(
                split.ja == ja_before && split.preisach == preisach_before,
                "{spec}: magnetic state moved"
            );
            // Keep the magnetic states together for the next sample.
            (split.ja, split.preisach) = (whole.ja, whole.preisach);
        }
    }
}

/// The field follows the drive's sign: a positive current raises the rod's field above the
/// bias, a negative one lowers it, by the coil's turns per metre without an eddy lag.
#[test]
fn step_field_moves_the_field_with_the_drive() {
    let p = ActuatorParams::TERFENOL_DEMO;
    let m = model("ja");
    for i in [2.0f32, -2.0] {
        let mut s = m.rest_state();
        let (current, h) = m.step_field(&mut s, i).unwrap();
        assert_eq!(current, i);
        assert!((h - (p.coil.bias_a_per_m + p.coil.turns_per_m * i)).abs() < 1e-3 * h.abs().max(1.0), "{h}");
        assert_eq!(s.rod_field_a_per_m.value(), h);
        assert_eq!(s.amp.current_a, i);
    }
}

/// An input that is not a drive is refused and moves nothing; the largest one is taken.
#[test]
fn step_field_refuses_what_step_refuses() {
    let m = model("ja+eddy+amp");
    for bad in [f32::NAN, f32::INFINITY, -f32::INFINITY, 1.5 * MAX_INPUT, -1.5 * MAX_INPUT] {
        let mut s = m.rest_state();
        assert_eq!(m.step_field(&mut s, bad), Err(StepError::InputOutOfRange), "{bad}");
        assert_eq!(s, m.rest_state(), "{bad}");
    }
    let mut s = m.rest_state();
    assert!(m.step_field(&mut s, MAX_INPUT).is_ok());
}

/// A drive stepped on its own branches without noise (directions from the clean drive) gives
/// what plain steps give; laws without hysteresis ignore the branch.
#[test]
fn a_clean_drive_on_branches_is_the_plain_step() {
    for spec in ["ja+eddy", "linear+anhysteretic", "preisach"] {
        let m = model(spec);
        let (mut plain, mut on_branch) = (m.rest_state(), m.rest_state());
        let mut b = JaBranch::from(on_branch.ja);
        let mut prev_h = on_branch.rod_field_a_per_m.value();
        for n in 0..400 {
            let u = drive(n);
            let want = m.step_magnetic(&mut plain, u, |h| h).unwrap();
            let dir = if plain.rod_field_a_per_m.value() >= prev_h { 1.0 } else { -1.0 };
            prev_h = plain.rod_field_a_per_m.value();
            let got = m.step_magnetic_on_branch(&mut on_branch, &mut b, u, dir).unwrap();
            assert_eq!(got, want, "{spec}, sample {n}");
        }
        assert_eq!(
            m.step_magnetic_on_branch(&mut on_branch, &mut b, f32::NAN, 1.0),
            Err(StepError::InputOutOfRange)
        );
    }
}

/// The queries say what the spec built: a voltage input only with an amplifier, magnetic
/// memory only for the hysteresis laws, and the spec itself back.
#[test]
fn the_model_says_what_it_is() {
    for (spec, voltage, memory) in [
        ("ja", false, true),
        ("ja+amp", true, true),
        ("preisach+eddy", false, true),
        ("linear", false, false),
        ("linear+anhysteretic+amp", true, false),
    ] {
        let m = model(spec);
        assert_eq!(m.spec(), ModelSpec::parse(spec).unwrap());
        assert_eq!((m.input_is_voltage(), m.has_magnetic_memory()), (voltage, memory), "{spec}");
    }
}

/// Second-order sub-steps change a J–A model's output at a fast drive (and bring it closer to
/// a 16× finer integration than the explicit one); a law without sub-steps is left as it is.
#[test]
fn second_order_hysteresis_refines_only_the_hysteresis_law() {
    let run = |m: &Actuator| {
        let mut s = m.rest_state();
        (0..200)
            .map(|n| m.step(&mut s, 8.0 * libm::sinf(n as f32 * 0.3)).unwrap().displacement_m)
            .collect::<Vec<_>>()
    };
    let explicit = model("ja");
    let (corrected, fine) = (explicit.with_second_order_hysteresis(), explicit.with_finer_hysteresis(16));
    let (e, c, f) = (run(&explicit), run(&corrected), run(&fine));
    let gap = |x: &[f32]| x.iter().zip(&f).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(
        c != e && gap(&c) < 0.8 * gap(&e),
        "corrected {} m, explicit {} m from the fine run",
        gap(&c),
        gap(&e)
    );
    for spec in ["linear+anhysteretic", "preisach"] {
        let m = model(spec);
        assert_eq!(m.with_second_order_hysteresis(), m, "{spec}");
        assert_eq!(m.with_finer_hysteresis(4), m, "{spec}");
    }
}

/// A wiggling drive on branches is the law's own branch step (`step_on_branch` at the rod's
/// field), which opens no minor loop: it differs from the plain step, which does.
#[test]
fn a_wiggling_drive_on_branches_is_the_laws_branch_step() {
    use model_core::magnetization::{JaState, JilesAtherton};
    let p = ActuatorParams::TERFENOL_DEMO;
    let (m, ja) = (model("ja"), JilesAtherton::new(p.ja).unwrap());
    let (mut s, mut plain) = (m.rest_state(), m.rest_state());
    let (mut b, mut law): (JaBranch, JaState) = (JaBranch::from(s.ja), s.ja);
    let mut b_law = JaBranch::from(law);
    let mut apart = 0.0f32;
    for n in 0..400 {
        let clean = 3.0 * libm::sinf(n as f32 * 0.02);
        let dir = if libm::cosf(n as f32 * 0.02) >= 0.0 { 1.0 } else { -1.0 };
        let u = clean + if n % 2 == 0 { 0.01 } else { -0.01 };
        let got = m.step_magnetic_on_branch(&mut s, &mut b, u, dir).unwrap();
        let h = p.coil.bias_a_per_m + p.coil.turns_per_m * u;
        let want = ja.step_on_branch(&mut law, &mut b_law, h, dir);
        assert_eq!(got.magnetization_a_per_m, want, "sample {n}");
        apart =
            apart.max((m.step_magnetic(&mut plain, u, |h| h).unwrap().magnetization_a_per_m - want).abs());
    }
    assert!(apart > 1e-3 * p.ja.ms_a_per_m, "the plain steps open minor loops: {apart} A/m apart");
}

/// The rod at rest is demagnetised and then brought to the bias field: so a bias of the other
/// sign gives the opposite magnetization (the hysteresis laws start from no preferred
/// direction), and the state equals the one `rest_state_at` builds at zero drive where both
/// construct the same thing (Preisach: the demagnetised plane raised to the bias).
#[test]
fn the_rest_state_is_the_demagnetised_rod_at_the_bias() {
    for spec in ["ja", "preisach"] {
        let mut q = ActuatorParams::TERFENOL_DEMO;
        let m_up = model(spec).rest_state();
        q.coil.bias_a_per_m = -q.coil.bias_a_per_m;
        let m_down = Actuator::new(ModelSpec::parse(spec).unwrap(), &q).unwrap().rest_state();
        let (up, down) = (m_up.m_slow_a_per_m.value(), m_down.m_slow_a_per_m.value());
        assert!(up > 0.0 && down < 0.0, "{spec}: {up} and {down} A/m at ± bias");
        // J–A's demagnetised state is symmetric; the Preisach plane's is so only to within its
        // staircase's last turning points.
        let tol = if spec == "ja" { 1e-3 } else { 0.1 };
        assert!((up + down).abs() < tol * up, "{spec}: {up} and {down} A/m at ± bias");
    }
    let m = model("preisach+eddy");
    assert_eq!(m.rest_state(), m.rest_state_at(0.0, 0.0));
}

/// An excursion of the field from the demagnetised rest and back ends at the rest field,
/// leaves more magnetization the further up it went, and (the law being rate independent) is
/// the state one step out and one back gives.
#[test]
fn a_rest_excursion_leaves_more_magnetization_the_higher_it_went() {
    use model_core::magnetization::JilesAtherton;
    let p = ActuatorParams::TERFENOL_DEMO;
    let (m, ja) = (model("ja+eddy"), JilesAtherton::new(p.ja).unwrap());
    let h0 = p.coil.bias_a_per_m;
    let mut after = Vec::new();
    for excursion in [6_000.0f32, -6_000.0] {
        let s = m.rest_state_at(0.0, excursion);
        let mut by_hand = ja.demagnetized_at(h0);
        ja.step(&mut by_hand, h0 + excursion);
        ja.step(&mut by_hand, h0);
        assert_eq!(s.ja.h_a_per_m, s.rod_field_a_per_m.value(), "{excursion}");
        assert!(
            (s.ja.m_a_per_m - by_hand.m_a_per_m).abs() < 5e-3 * p.ja.ms_a_per_m,
            "{excursion}: {} against {} A/m",
            s.ja.m_a_per_m,
            by_hand.m_a_per_m
        );
        after.push(s.ja);
    }
    assert!(after[0].m_a_per_m > after[1].m_a_per_m && after[0].m_irr_a_per_m > after[1].m_irr_a_per_m);
    // Without one the rod is the demagnetised state itself.
    assert_eq!(m.rest_state_at(0.0, 0.0).ja, ja.demagnetized_at(h0));
}

/// A refused step says why in words.
#[test]
fn a_refused_step_says_why() {
    let text = StepError::InputOutOfRange.to_string();
    assert!(text.contains("not finite") && text.contains("10000"), "{text}");
}
