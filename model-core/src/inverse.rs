//! Inverse (feedforward) compensator: desired displacement → drive input, through the inverse
//! of every static and first-order stage of an [`Actuator`] (003 §2–3: a compensator C with
//! H ∘ C ≈ identity).
//!
//! - magnetostriction: closed form, on the magnetization branch of the bias field's sign;
//! - magnetization: closed form for linear, safeguarded Newton for the Langevin curve, monotone
//!   secant search on the compensator's own relay memory for Preisach (from pair sums kept in
//!   [`CompensatorState`], two Everett look-ups per evaluation), and for
//!   Jiles–Atherton a bounded per-step solve (Newton on the model's own incremental
//!   susceptibility, then two secant corrections on trial copies of the state) that advances
//!   the compensator's own hysteresis state, so it follows the same branches as the plant;
//! - aftereffect, eddy lag and amplifier: their exact one-step inverses;
//! - thermal elongation: predicted from the compensator's own coil-heating state and subtracted;
//! - mechanics: static (gain 1); resonance is left to the feedback loop;
//! - sensor delay: not inverted (it is a measurement delay, not an actuator one).

use crate::chain::{Actuator, ActuatorState, Magnetization, MAX_INPUT};
use crate::magnetization::{InverseCache, JaState, JilesAtherton};
use crate::math::{at_least, within};

/// The compensator (immutable): the model it inverts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensator {
    model: Actuator,
    branch_sign: f32,
}

/// The compensator's copy of the model's internal states (mutable, per sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorState {
    model: ActuatorState,
    /// The Preisach staircase's pair sums (unused by the other laws).
    preisach_cache: InverseCache,
    last_input: f32,
}

impl Compensator {
    /// Inverts `model`.
    pub fn new(model: Actuator) -> Self {
        let branch_sign = if model.coil.bias_a_per_m < 0.0 { -1.0 } else { 1.0 };
        Self { model, branch_sign }
    }

    /// The model being inverted.
    pub fn model(&self) -> &Actuator {
        &self.model
    }

    /// State matching the model's rest state.
    pub fn rest_state(&self) -> CompensatorState {
        let model = self.model.rest_state();
        let preisach_cache = match &self.model.magnetization {
            Magnetization::Preisach(p) => p.inverse_cache(&model.preisach),
            _ => InverseCache::default(),
        };
        CompensatorState { model, preisach_cache, last_input: 0.0 }
    }

    /// The drive input (command voltage [V] with an amplifier, else coil current [A]) that makes
    /// the model's displacement (before mechanics dynamics and sensor delay) equal `y_ref_m`.
    /// Always finite and within ±[`MAX_INPUT`]; a non-finite reference repeats the last input.
    pub fn step(&self, s: &mut CompensatorState, y_ref_m: f32) -> f32 {
        if !y_ref_m.is_finite() {
            return s.last_input;
        }
        let md = &self.model;
        let st = &mut s.model;
        let preisach_cache = &mut s.preisach_cache;
        let thermal =
            md.thermal.as_ref().map_or(0.0, |th| th.elongation_m(st.rod_temperature_rise_c.value()));
        let strain = (y_ref_m - thermal) / md.rod_length_m;
        let m_obs = md.magnetostriction.magnetization_for(strain, self.branch_sign);
        let m = match &md.aftereffect {
            Some(ae) => {
                let m = ae.magnetization_for(&st.m_slow_a_per_m, m_obs);
                ae.step(&mut st.m_slow_a_per_m, m);
                m
            }
            None => m_obs,
        };
        let h_rod = match &md.magnetization {
            Magnetization::Linear(l) => l.field_for(m),
            Magnetization::Anhysteretic(a) => a.field_for(m),
            Magnetization::JilesAtherton(j) => ja_field_for(j, &mut st.ja, m),
            Magnetization::Preisach(p) => p.field_for_with(&mut st.preisach, preisach_cache, m),
        };
        let h_coil = match &md.eddy {
            Some(lag) => {
                let h = lag.input_for(&st.rod_field_a_per_m, h_rod);
                lag.step(&mut st.rod_field_a_per_m, h);
                h
            }
            None => h_rod,
        };
        let current = within(md.coil.current_for(h_coil), MAX_INPUT);
        if let Some(th) = &md.thermal {
            th.step(&mut st.temperature_rise_c, &mut st.rod_temperature_rise_c, current);
        }
        let input = match &md.amp {
            Some(amp) => {
                let u = within(amp.input_for(&st.amp, current), MAX_INPUT);
                amp.step(&mut st.amp, u);
                u
            }
            None => current,
        };
        s.last_input = if input.is_finite() { input } else { s.last_input };
        s.last_input
    }
}

/// Advances `s` to the field that gives magnetization `m_target` (clamped inside ±M_s) and
/// returns that field. Bounded: three model steps per sample.
fn ja_field_for(j: &JilesAtherton, s: &mut JaState, m_target: f32) -> f32 {
    let p = j.params();
    let m_target = within(m_target, 0.999 * p.ms_a_per_m);
    let (h0, m0) = (s.h_a_per_m, s.m_a_per_m);
    let dm = m_target - m0;
    if dm == 0.0 {
        return h0;
    }
    let dir = if dm > 0.0 { 1.0 } else { -1.0 };
    // Largest field move per sample the solve allows (far beyond any real drive's slew).
    let reach = 50.0 * p.a_a_per_m.max(p.k_a_per_m);
    let floor = 1e-3 * p.ms_a_per_m / p.a_a_per_m;
    let chi = at_least(j.susceptibility(s, dir), floor);
    let mut h_a = h0;
    let mut m_a = m0;
    let mut h_b = h0 + within(dm / chi, reach);
    for _ in 0..2 {
        let mut trial = *s;
        let m_b = j.step(&mut trial, h_b);
        let slope = (m_b - m_a) / (h_b - h_a);
        if !slope.is_finite() || slope <= 0.0 {
            break;
        }
        let h_next = h_b + within((m_target - m_b) / slope, reach);
        h_a = h_b;
        m_a = m_b;
        h_b = h_next;
    }
    j.step(s, h_b);
    h_b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::ActuatorParams;
    use crate::spec::ModelSpec;
    use proptest::prelude::*;

    /// Drives the compensator with a smooth random reference, feeds its output to the model it
    /// inverts, and returns max |y − y_ref| / stroke.
    fn round_trip_error(spec: &str, amplitudes: &[f32], freqs: &[f32]) -> f32 {
        round_trip_error_with(spec, spec, amplitudes, freqs)
    }

    /// As above, with the compensator built for `comp_spec` and the plant for `plant_spec`.
    fn round_trip_error_with(comp_spec: &str, plant_spec: &str, amplitudes: &[f32], freqs: &[f32]) -> f32 {
        round_trip_error_params(&ActuatorParams::TERFENOL_DEMO, comp_spec, plant_spec, amplitudes, freqs)
    }

    fn round_trip_error_params(
        p: &ActuatorParams,
        comp_spec: &str,
        plant_spec: &str,
        amplitudes: &[f32],
        freqs: &[f32],
    ) -> f32 {
        let model = Actuator::new(ModelSpec::parse(plant_spec).unwrap(), p).unwrap();
        let comp = Compensator::new(Actuator::new(ModelSpec::parse(comp_spec).unwrap(), p).unwrap());
        let mut cs = comp.rest_state();
        let mut ms = model.rest_state();
        let y0 = ms.mech.displacement_m;
        let stroke = 30e-6;
        let mut worst = 0.0f32;
        for n in 0..4000 {
            let t = n as f32 * 1e-4;
            let mut r = 0.5 * stroke;
            for (a, f) in amplitudes.iter().zip(freqs) {
                r += a * stroke * libm::sinf(2.0 * core::f32::consts::PI * f * t);
            }
            let y_ref = y0 + r;
            let u = comp.step(&mut cs, y_ref);
            let out = model.step(&mut ms, u).unwrap();
            // The model's y_free (static mechanics, no delay in these specs).
            worst = worst.max((out.displacement_m - y_ref).abs() / stroke);
        }
        worst
    }

    #[test]
    fn inverse_of_each_static_chain_is_identity() {
        for spec in [
            "linear",
            "linear+anhysteretic",
            "ja",
            "ja+eddy",
            "ja+amp",
            "ja+aftereffect",
            "ja+thermal+eddy+amp",
            "linear+preisach",
            "preisach+eddy+amp",
        ] {
            let e = round_trip_error(spec, &[0.3, 0.15], &[10.0, 37.0]);
            assert!(e <= 0.005, "{spec}: error {:.3} % of stroke", e * 100.0);
        }
    }

    /// 002's second-order amplifier in the chain is inverted exactly too.
    #[test]
    fn second_order_amplifier_is_inverted() {
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.amp_second_order = Some(crate::amplifier::SecondOrderAmpParams::TSMA_002);
        let e = round_trip_error_params(&p, "ja+eddy+amp", "ja+eddy+amp", &[0.3, 0.15], &[10.0, 137.0]);
        assert!(e <= 0.005, "error {:.3} % of stroke", e * 100.0);
    }

    /// Fast reversals (400 Hz, 25 samples per period): the descending branch after each
    /// maximum needs the secant correction as much as the ascending one.
    #[test]
    fn fast_reversals_are_tracked() {
        let e = round_trip_error("ja", &[0.25], &[400.0]);
        assert!(e <= 0.005, "400 Hz: error {:.3} % of stroke", e * 100.0);
    }

    /// The check can fail: a compensator that ignores hysteresis misses a J–A plant by far.
    #[test]
    fn mismatched_inverse_is_detected() {
        let e = round_trip_error_with("linear+anhysteretic", "ja", &[0.3, 0.15], &[10.0, 37.0]);
        assert!(e > 0.05, "a saturation-only inverse on a J–A plant should miss by > 5 %, got {e}");
    }

    /// An eddy lag of 1e4 s (a typo for 1e-4) is 1e8 samples at 10 kHz: accepted, and the
    /// compensator inverts it (at its current limit: the lag is that slow). Before, e^{−dt/τ}
    /// rounded to 1: the rod field never moved and the inverse divided 0 by 0, its state NaN and
    /// its output frozen at 0.
    #[test]
    fn a_very_slow_eddy_lag_is_inverted_not_frozen() {
        let p = ActuatorParams { eddy_tau_s: 1e4, ..ActuatorParams::TERFENOL_DEMO };
        let comp = Compensator::new(Actuator::new(ModelSpec::parse("ja+eddy").unwrap(), &p).unwrap());
        let mut cs = comp.rest_state();
        let y0 = comp.model().rest_state().mech.displacement_m;
        for _ in 0..200 {
            let u = comp.step(&mut cs, y0 + 20e-6);
            assert!(u.is_finite() && u > 0.0, "{u}");
        }
        let h = cs.model.rod_field_a_per_m.value();
        assert!(h.is_finite() && h > p.coil.bias_a_per_m, "the rod field rises: {h} A/m");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(40))]
        #[test]
        fn ja_inverse_within_half_a_percent_of_stroke(
            a1 in 0.05f32..0.45, a2 in 0.0f32..0.2, f1 in 1.0f32..80.0, f2 in 1.0f32..200.0,
        ) {
            let e = round_trip_error("ja+eddy", &[a1, a2], &[f1, f2]);
            prop_assert!(e <= 0.005, "error {:.3} % of stroke", e * 100.0);
        }
    }
}
