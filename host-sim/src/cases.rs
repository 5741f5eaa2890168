//! Hidden-effect cases: SIMULATED rigs (the plant simulator) where one effect of the contract is
//! present in the actuator but missing from the engineer's model, plus one case where nothing is
//! missing. Each has fit and validation excitations at different frequencies and amplitudes.
//! Used by the test suite, `gma demo` and the benchmarks; the data are generated, never stored.

use anyhow::Result;
use model_core::{ActuatorParams, Effect, ModelSpec};

use crate::excitation::Excitation;
use crate::plant::Plant;
use crate::recording::Recording;

/// One case.
#[derive(Debug, Clone)]
pub struct Case {
    /// Short name (the hidden effect's contract name, or `complete`).
    pub name: &'static str,
    /// The effect the engineer's model lacks (None: nothing).
    pub hidden: Option<Effect>,
    /// The engineer's model.
    pub model: ModelSpec,
    /// The engineer's starting parameter file (the demo set: the rig differs from it).
    pub init: ActuatorParams,
    /// The simulated rig.
    pub plant: Plant,
    /// Fit excitations and durations [s].
    pub fit: Vec<(Excitation, f64)>,
    /// Validation excitations and durations [s].
    pub val: Vec<(Excitation, f64)>,
}

fn sine(freq_hz: f64, amplitude: f64, bias: f64) -> Excitation {
    Excitation::Sine { freq_hz, amplitude, bias }
}

fn spec(text: &str) -> ModelSpec {
    ModelSpec::parse(text).expect("built-in spec")
}

impl Case {
    /// Generates the fit and validation recordings (deterministic for `seed`).
    pub fn recordings(&self, seed: u64) -> Result<(Vec<Recording>, Vec<Recording>)> {
        let gen = |set: &[(Excitation, f64)], split: &str, salt: u64| -> Result<Vec<Recording>> {
            set.iter()
                .enumerate()
                .map(|(i, (exc, dur))| {
                    let mut plant = self.plant.clone();
                    // Sensors are re-zeroed by hand between runs: a different offset each file.
                    plant.offset_um = 3.0 * (i as f64 + 1.0) - 5.0;
                    let name = format!("{}-{split}{}.csv", self.name, i + 1);
                    plant.record(&name, exc, *dur, seed.wrapping_mul(1000).wrapping_add(salt + i as u64))
                })
                .collect()
        };
        Ok((gen(&self.fit, "fit", 0)?, gen(&self.val, "val", 100)?))
    }
}

/// The rig's true parameters: 002's rod 3 J–A set and its own dynamics, not the engineer's
/// start values (the demo set).
fn rig() -> ActuatorParams {
    let mut base = ActuatorParams::TERFENOL_DEMO;
    base.ja = model_core::magnetization::JaParams {
        ms_a_per_m: 6.0e5,
        a_a_per_m: 7012.0,
        alpha: -0.01,
        k_a_per_m: 4283.0,
        c: 0.18,
        variant: model_core::magnetization::JaVariant::Bulk,
    };
    base.anhysteretic.a_a_per_m = 7500.0;
    base.magnetostriction.lambda_s = 1.2e-3;
    base.mech = model_core::chain::ModalMechanics { natural_frequency_hz: 1300.0, damping_ratio: 0.25 };
    base.delay_samples = 4.0;
    base
}

/// `gma demo`: a rig with eddy currents and a mechanical resonance; the engineer's model is
/// quasi-static J–A. Two effects to find, one after the other.
pub fn demo() -> Case {
    let mut p = rig();
    p.eddy_tau_s = 2.5e-4;
    Case {
        name: "demo",
        hidden: None,
        model: spec("ja"),
        init: ActuatorParams::TERFENOL_DEMO,
        plant: Plant::new(spec("ja+eddy+mech"), p),
        fit: vec![(sine(80.0, 1.5, 0.0), 0.08), (sine(500.0, 1.0, 0.3), 0.04), (sine(20.0, 2.0, 0.0), 0.1)],
        val: vec![(sine(200.0, 1.2, 0.0), 0.05), (sine(800.0, 0.8, 0.3), 0.03)],
    }
}

/// The suite: one case per contract effect, and the complete case.
pub fn all() -> Vec<Case> {
    let base = rig();
    // A case is named after the effect it hides.
    let case = |hidden: Option<Effect>, model: ModelSpec, params: ActuatorParams, fit, val| {
        let name = hidden.map_or("complete", |e| e.name());
        let plant_spec = match hidden {
            Some(e) => model.with(e),
            None => model,
        };
        let init = ActuatorParams::TERFENOL_DEMO;
        Case { name, hidden, model, init, plant: Plant::new(plant_spec, params), fit, val }
    };
    let anhysteretic = ModelSpec::LINEAR.with(Effect::Saturation);
    let ja = ModelSpec::LINEAR.with(Effect::Hysteresis);
    let quasi_static_fit = vec![(sine(5.0, 2.0, 0.0), 0.4), (sine(20.0, 1.0, 0.5), 0.2)];
    let quasi_static_val = vec![(sine(10.0, 1.5, 0.0), 0.3), (sine(30.0, 2.5, 0.5), 0.2)];
    let dynamic_fit = vec![(sine(60.0, 1.5, 0.0), 0.1), (sine(250.0, 1.0, 0.3), 0.06)];
    let dynamic_val = vec![(sine(130.0, 1.2, 0.0), 0.08), (sine(400.0, 1.0, 0.3), 0.05)];
    let mut v = Vec::new();
    v.push(case(
        Some(Effect::Saturation),
        ModelSpec::LINEAR,
        base,
        quasi_static_fit.clone(),
        quasi_static_val.clone(),
    ));
    v.push(case(
        Some(Effect::Hysteresis),
        anhysteretic,
        base,
        quasi_static_fit.clone(),
        quasi_static_val.clone(),
    ));
    let mut p = base;
    p.eddy_tau_s = 3e-4;
    v.push(case(Some(Effect::EddyCurrent), ja, p, dynamic_fit.clone(), dynamic_val.clone()));
    v.push(case(
        Some(Effect::MechanicalDynamics),
        ja,
        base,
        vec![(sine(100.0, 1.5, 0.0), 0.06), (sine(700.0, 1.0, 0.3), 0.03)],
        vec![(sine(350.0, 1.2, 0.0), 0.04), (sine(900.0, 1.0, 0.3), 0.03)],
    ));
    let mut p = base;
    p.amp.tau_s = 4e-4;
    let mut amp = case(Some(Effect::AmplifierDynamics), ja, p, dynamic_fit.clone(), dynamic_val.clone());
    amp.plant.log_current = false; // the rig logs the command only
    v.push(amp);
    let mut p = base;
    p.aftereffect.fraction = 0.15;
    p.aftereffect.tau_s = 0.05;
    let square = |f, a, b| Excitation::Square { freq_hz: f, amplitude: a, bias: b };
    v.push(case(
        Some(Effect::MagneticAftereffect),
        ja,
        p,
        vec![(square(2.0, 1.0, 0.0), 1.0), (sine(10.0, 1.5, 0.0), 0.2)],
        vec![(square(4.0, 1.5, 0.3), 0.6), (sine(7.0, 1.0, 0.0), 0.3)],
    ));
    // Coil heating on a rig without hysteresis: J–A's own slow drift of biased minor loops
    // (accommodation) looks like heating over seconds, so the two are not separable on a J–A rig.
    let mut p = base;
    p.dt_s = 5e-4; // 2 kHz is plenty for a 20 Hz drive over seconds
    p.thermal.tau_s = 2.0;
    v.push(case(
        Some(Effect::ThermalDrift),
        anhysteretic,
        p,
        vec![(sine(20.0, 1.0, 1.0), 4.0), (sine(35.0, 1.5, 0.0), 2.0)],
        vec![(sine(25.0, 1.2, 0.8), 3.0), (sine(15.0, 1.0, -0.5), 3.0)],
    ));
    v.push(case(Some(Effect::SensorDelay), ja, base, dynamic_fit.clone(), dynamic_val.clone()));
    v.push(case(None, ja, base, dynamic_fit, dynamic_val));
    v
}
