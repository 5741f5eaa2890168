//! Field-valued parameters [A/m] at magnitudes only a unit slip gives: a value written in kA/m
//! into an A/m key reads 1000× too small, and a magnetic model run there scores far from the rod
//! with nothing else to say why (the fit's strain scale then takes the blame).

use model_core::{ActuatorParams, ModelSpec};

/// A field [A/m] below this share of the lowest value its search tries (or, for one the fit
/// never searches, below the floor [`FIELD_FLOORS`] gives) is read as a kA/m slip: a = 7 for
/// 7 kA/m is 70× below the 500 A/m any Terfenol-D loop needs.
const KILO_SLIP_SHARE: f64 = 0.05;

/// Fields of a set no search covers, with the least magnitude a Terfenol-D actuator's can have
/// [A/m] (0 stays allowed where it means "none": a rod without a bias magnet).
const FIELD_FLOORS: [(&str, f64); 3] =
    [("coil.bias_a_per_m", 100.0), ("ja.ms_a_per_m", 1e4), ("magnetostriction.ms_a_per_m", 1e4)];

/// The field-valued parameters of `p` that `spec` uses whose magnitude only a value written in
/// kA/m (or MA/m) into an A/m key gives, with their values: the bias, J–A's a and k, a Preisach
/// spread at a few A/m. A magnetic model there runs, and scores, far from the rod.
pub fn fields_in_kilo(spec: ModelSpec, p: &ActuatorParams) -> Vec<(&'static str, f64)> {
    let searched = spec.law().params().iter().chain(spec.effects().flat_map(|e| e.info().params));
    let mut found: Vec<(&'static str, f64)> = searched
        .filter(|q| q.unit == "A/m" && q.lo > 0.0)
        .map(|q| (q.key, (q.get)(p), q.lo * KILO_SLIP_SHARE))
        .chain(FIELD_FLOORS.iter().filter_map(|&(key, floor)| {
            let value = field_floor_value(spec, p, key)?;
            Some((key, value, floor))
        }))
        .filter(|&(_, v, floor)| v != 0.0 && v.abs() < floor)
        .map(|(key, v, _)| (key, v))
        .collect();
    found.dedup_by_key(|f| f.0);
    found
}

/// The value of floor-checked `key` in `p`, where `spec` uses it.
fn field_floor_value(spec: ModelSpec, p: &ActuatorParams, key: &str) -> Option<f64> {
    let ja = spec.law() == model_core::MagnetizationLaw::JilesAtherton;
    match key {
        "coil.bias_a_per_m" => Some(p.coil.bias_a_per_m as f64),
        "ja.ms_a_per_m" if ja => Some(p.ja.ms_a_per_m as f64),
        "magnetostriction.ms_a_per_m" => Some(p.magnetostriction.ms_a_per_m as f64),
        _ => None,
    }
}

/// The doubt about set `name` (as a command says it) when it holds a field in kA/m for `spec`.
pub fn kilo_doubt(name: &str, spec: ModelSpec, p: &ActuatorParams) -> Option<String> {
    let kilo = fields_in_kilo(spec, p);
    (!kilo.is_empty()).then(|| format!("{name} holds {}", kilo_words(&kilo)))
}

/// [`fields_in_kilo`] in words: "`coil.bias_a_per_m` = 8 A/m (…)".
pub fn kilo_words(fields: &[(&'static str, f64)]) -> String {
    let each: Vec<String> = fields.iter().map(|(k, v)| format!("`{k}` = {v} A/m")).collect();
    let v = fields.first().map_or(0.0, |f| f.1);
    format!(
        "{}, a field no Terfenol-D actuator has: the file's fields are in A/m, so a value written in kA/m \
         reads 1000× too small ({v} kA/m is {} A/m)",
        each.join(", "),
        v * 1000.0
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(text: &str) -> ModelSpec {
        crate::params::parse_spec(text).unwrap()
    }

    /// A field written in kA/m into an A/m key is named (bias, a, M_s); the demo set under every
    /// structure and a rod without a bias magnet (0) are not.
    #[test]
    fn a_field_in_kilo_amperes_per_metre_is_named() {
        for text in ["ja+mech", "preisach+eddy+mech", "anhysteretic", "linear+amp", "ja+delay+eddy+thermal"] {
            assert_eq!(fields_in_kilo(spec(text), &ActuatorParams::TERFENOL_DEMO), vec![], "{text}");
        }
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.coil.bias_a_per_m = 0.0;
        assert_eq!(fields_in_kilo(spec("ja+mech"), &p), vec![]);
        p.coil.bias_a_per_m = -8.0;
        p.ja.a_a_per_m = 7.0;
        p.ja.ms_a_per_m = 765.0;
        let found: Vec<&str> = fields_in_kilo(spec("ja+mech"), &p).iter().map(|f| f.0).collect();
        assert_eq!(found, ["ja.a_a_per_m", "coil.bias_a_per_m", "ja.ms_a_per_m"]);
        // Another law does not use J–A's values.
        let found: Vec<&str> = fields_in_kilo(spec("preisach+mech"), &p).iter().map(|f| f.0).collect();
        assert_eq!(found, ["coil.bias_a_per_m"]);
        assert!(kilo_words(&[("coil.bias_a_per_m", 8.0)]).contains("8 kA/m is 8000 A/m"));
    }
}
