//! Which parameters a model spec identifies, their bounds and scales, and parameter files.
//!
//! Scale ambiguities are removed by fixing, not fitting: the strain scale is carried by λ_s alone
//! (magnetization is normalised by the magnetostriction's M_s, which is also the anhysteretic and
//! J–A M_s), the coil's turns per metre and bias field come from the parameter file (geometry and
//! magnet are known), and the rod length is fixed. With a measured current the amplifier gain is
//! irrelevant; with a command only, its gain is identified (ideal or dynamic amplifier).

use std::path::Path;

use anyhow::{Context, Result};
use model_core::{Actuator, ActuatorParams, Effect, ModelSpec};

use crate::error::Located;
use crate::files::{echo, Input};
use crate::search::Bound;

/// One identified parameter: its bounds and scale ([`Bound`], named as in parameter files,
/// e.g. `ja.k_a_per_m`) and how to read and write it in a parameter set.
#[derive(Clone, Copy)]
pub struct FreeParam {
    /// Name, range and scale.
    pub bound: Bound,
    /// Reads it from a parameter set.
    pub get: fn(&ActuatorParams) -> f64,
    /// Writes it into a parameter set.
    pub set: fn(&mut ActuatorParams, f64),
}

impl FreeParam {
    /// Name as in parameter files.
    pub fn name(&self) -> &'static str {
        self.bound.name
    }

    /// Maps a value to [0, 1] (clamped; 0.5 for a value the scale cannot map).
    pub fn to_unit(&self, v: f64) -> f64 {
        self.bound.to_unit(v)
    }

    /// Maps [0, 1] back to a value (clamped into the bounds).
    pub fn from_unit(&self, u: f64) -> f64 {
        self.bound.from_unit(u)
    }
}

macro_rules! param {
    ($name:literal, $lo:expr, $hi:expr, $log:expr, $($field:ident).+) => {
        FreeParam {
            bound: Bound { name: $name, lo: $lo, hi: $hi, log: $log },
            get: |p| p.$($field).+ as f64,
            set: |p, v| p.$($field).+ = v as f32,
        }
    };
}

/// The parameters `spec` identifies. `command_driven`: the files give the command, not the
/// current, so the amplifier gain is identified too.
pub fn free_params(spec: ModelSpec, command_driven: bool) -> Vec<FreeParam> {
    let mut v = vec![param!("magnetostriction.lambda_s", 1e-5, 1e-2, true, magnetostriction.lambda_s)];
    if spec.has(Effect::Preisach) {
        v.push(param!("preisach.coercive_a_per_m", 100.0, 3e4, true, preisach.coercive_a_per_m));
        v.push(param!("preisach.spread_a_per_m", 500.0, 6e4, true, preisach.spread_a_per_m));
    } else if spec.has(Effect::Hysteresis) {
        v.push(param!("ja.a_a_per_m", 500.0, 5e4, true, ja.a_a_per_m));
        v.push(param!("ja.k_a_per_m", 100.0, 3e4, true, ja.k_a_per_m));
        v.push(param!("ja.alpha", -0.1, 0.1, false, ja.alpha));
        v.push(param!("ja.c", 0.0, 0.95, false, ja.c));
    } else if spec.has(Effect::Saturation) {
        v.push(param!("anhysteretic.a_a_per_m", 500.0, 1e5, true, anhysteretic.a_a_per_m));
    } else {
        v.push(param!("linear.susceptibility", 0.1, 200.0, true, linear.susceptibility));
        v.push(param!("linear.offset_a_per_m", -3e5, 3e5, false, linear.offset_a_per_m));
    }
    if command_driven {
        v.push(param!("amp.gain_a_per_v", 0.05, 50.0, true, amp.gain_a_per_v));
    }
    if spec.has(Effect::AmplifierDynamics) {
        v.push(param!("amp.tau_s", 1e-6, 1e-2, true, amp.tau_s));
    }
    if spec.has(Effect::EddyCurrent) {
        v.push(param!("eddy_tau_s", 1e-6, 1e-2, true, eddy_tau_s));
    }
    if spec.has(Effect::MechanicalDynamics) {
        v.push(param!("mech.natural_frequency_hz", 50.0, 2e4, true, mech.natural_frequency_hz));
        v.push(param!("mech.damping_ratio", 0.02, 5.0, true, mech.damping_ratio));
    }
    if spec.has(Effect::MagneticAftereffect) {
        v.push(param!("aftereffect.fraction", 1e-3, 0.6, true, aftereffect.fraction));
        v.push(param!("aftereffect.tau_s", 1e-3, 30.0, true, aftereffect.tau_s));
    }
    if spec.has(Effect::ThermalDrift) {
        v.push(param!(
            "thermal.thermal_resistance_c_per_w",
            1e-3,
            100.0,
            true,
            thermal.thermal_resistance_c_per_w
        ));
        v.push(param!("thermal.tau_s", 0.05, 3000.0, true, thermal.tau_s));
    }
    v
}

/// Largest sensor delay searched [samples].
pub const MAX_DELAY_SEARCH: u16 = 16;

/// Loads a parameter file (TOML as `--params-out` writes), or the built-in demo set, and checks
/// it for `spec` (every stage the spec uses must be valid).
pub fn load(path: Option<&Path>, spec: ModelSpec) -> Result<ActuatorParams> {
    load_input(path.map(Input::open).transpose()?, spec)
}

/// As [`load`], from an opened input.
pub fn load_input(input: Option<Input>, spec: ModelSpec) -> Result<ActuatorParams> {
    match input {
        None => Ok(ActuatorParams::TERFENOL_DEMO),
        Some(input) => {
            let name = input.name.clone();
            parse(&name, &input.into_text(MAX_PARAM_FILE_BYTES)?, spec)
        }
    }
}

/// Largest parameter file read [bytes] (they are a few KB).
const MAX_PARAM_FILE_BYTES: u64 = 1 << 20;

/// Parses and checks parameter-file text; errors name the file, line and parameter.
pub fn parse(file: &str, text: &str, spec: ModelSpec) -> Result<ActuatorParams> {
    let p: ActuatorParams = toml::from_str(text).map_err(|e| toml_error(file, text, &e))?;
    Actuator::new(spec, &p).map_err(|e| Located::file(file, format!("{e} (checked for model `{spec}`)")))?;
    Ok(p)
}

/// `file:line:column: message`, naming the parameter a missing field belongs to.
fn toml_error(file: &str, text: &str, e: &toml::de::Error) -> anyhow::Error {
    let msg = e.message().trim();
    let Some(span) = e.span() else {
        return Located::file(file, format!("not a valid parameter file: {msg}")).into();
    };
    let before = &text[..span.start.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    let at = echo(text.get(span.clone()).unwrap_or("").trim());
    let here = |m: String| -> anyhow::Error { Located::at(file, line as u64, Some(col as u64), m).into() };
    // A missing field is reported at its table's header: name it as `table.field`.
    if let Some(field) = msg.strip_prefix("missing field `").and_then(|m| m.strip_suffix('`')) {
        let table = at.strip_prefix('[').and_then(|t| t.strip_suffix(']'));
        let full = table.map_or(field.to_string(), |t| format!("{t}.{field}"));
        return Located::at(file, line as u64, None, format!("parameter `{full}` is missing")).into();
    }
    match key_at(before) {
        Some(key) => here(format!("parameter `{}`: {msg} (found `{at}`)", echo(&key))),
        None => here(format!("{msg} (at `{at}`)")),
    }
}

/// The dotted key (`table.key`) whose value starts where `before` ends, if that is a value.
fn key_at(before: &str) -> Option<String> {
    let (head, line) = before.rsplit_once('\n').unwrap_or(("", before));
    let key = line.split_once('=')?.0.trim();
    let table = head.lines().rev().map(str::trim).find(|l| l.starts_with('['));
    let table = table.map(|t| t.trim_matches(|c| c == '[' || c == ']').trim());
    Some(table.map_or(key.to_string(), |t| format!("{t}.{key}")))
}

/// The TOML text of a parameter set, with a header saying where it came from.
pub fn to_toml(p: &ActuatorParams, header: &str) -> Result<String> {
    let body = toml::to_string(p).context("serialising parameters")?;
    let mut out = String::new();
    for line in header.lines() {
        out.push_str("# ");
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(&body);
    Ok(out)
}

/// Parses a spec, turning an error's byte range into the offending word.
pub fn parse_spec(text: &str) -> Result<ModelSpec> {
    ModelSpec::parse(text).map_err(|e| match e {
        model_core::SpecError::UnknownEffect { start, end, suggestion } => {
            let hint = suggestion.map(|s| format!("; did you mean `{s}`?")).unwrap_or_default();
            anyhow::anyhow!(
                "model spec `{text}`: unknown effect `{}`{hint} (effects: saturation|anhysteretic, hysteresis, ja, \
                 preisach, eddy_current|eddy, mechanical_dynamics|mech, amplifier_dynamics|amp, \
                 magnetic_aftereffect|aftereffect, thermal_drift|thermal, sensor_delay|delay)",
                &text[start..end]
            )
        }
        other => anyhow::anyhow!("model spec `{text}`: {other}"),
    })
}
