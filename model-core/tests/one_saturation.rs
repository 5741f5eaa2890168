//! One rod has one saturation magnetization: a set whose `[magnetostriction]` M_s disagrees
//! with its magnetization law's is refused by the strain's key (issue 78: half the `[ja]` M_s
//! drove the strain to 3.3× saturation, and a fit answered with λ_s a quarter of the truth). A
//! law without an M_s (`linear`) leaves the strain's its own; a decimal round trip passes.

use model_core::{Actuator, ActuatorParams, ModelSpec};

const DEMO: ActuatorParams = ActuatorParams::TERFENOL_DEMO;

fn refused_by(law: &str, p: &ActuatorParams) -> Option<&'static str> {
    Actuator::new(ModelSpec::parse(law).unwrap(), p).err().map(|e| e.name())
}

#[test]
fn a_strain_saturation_unlike_the_laws_is_refused_by_its_key() {
    let mut half = DEMO;
    half.magnetostriction.ms_a_per_m = DEMO.ja.ms_a_per_m / 2.0;
    for law in ["ja", "ja+mech", "preisach", "anhysteretic"] {
        assert_eq!(refused_by(law, &half), Some("magnetostriction.ms_a_per_m"), "{law}");
    }
    // Each law reads its own table: a `[preisach]` M_s unlike the strain's refuses `preisach` only.
    let mut preisach_off = DEMO;
    preisach_off.preisach.ms_a_per_m *= 1.01;
    assert_eq!(refused_by("preisach", &preisach_off), Some("magnetostriction.ms_a_per_m"));
    assert_eq!(refused_by("ja", &preisach_off), None);
    // `linear` has no M_s of its own.
    assert_eq!(refused_by("linear", &half), None);
    // The same number written to six digits in each table.
    let mut rounded = DEMO;
    rounded.magnetostriction.ms_a_per_m = "600000.04".parse().unwrap();
    assert_eq!(refused_by("ja", &rounded), None);
}
