//! Parameter files: reading, checking and writing a model's parameter set (which of them a
//! fit identifies is `fit::free_params`).
//!
//! Scale ambiguities are removed by fixing, not fitting: the strain scale is carried by λ_s alone
//! (magnetization is normalised by the magnetostriction's M_s, which is also the anhysteretic and
//! J–A M_s), the coil's turns per metre and bias field come from the parameter file (geometry and
//! magnet are known), and the rod length is fixed. With a measured current the amplifier gain is
//! irrelevant; with a command only, its gain is identified (ideal or dynamic amplifier).

use std::path::Path;

use anyhow::{Context, Result};
use model_core::effects::{
    parameter_tables, spec_words, table_of, AMPLIFIER_GAIN, PARAMETER_FILE_FORMAT, ROD_THERMAL_LAG,
};
use model_core::{Actuator, ActuatorParams, Effect, ModelSpec};
use serde::Deserialize as _;

use crate::error::Located;
use crate::files::{echo, Input};
use crate::located;

/// Loads a parameter file (TOML as `--params-out` writes), or the built-in demo set, and checks
/// it for `spec` (every stage the spec uses must be valid).
pub fn load(path: Option<&Path>, spec: ModelSpec) -> Result<ActuatorParams> {
    Ok(load_input(path.map(Input::open).transpose()?, spec, "the parameter set")?.0)
}

/// As [`load`] from a file (or `-`), also giving where they came from, the name messages call
/// it by and its text, for a caller that checks more and points into it ([`located_parameter`]).
pub fn load_with_text(path: &Path, spec: ModelSpec) -> Result<(ActuatorParams, ParamSource, String)> {
    let input = Input::open(path)?;
    let name = input.name.clone();
    let text = input.into_text(MAX_PARAM_FILE_BYTES)?;
    let (params, source) = load_text(&name, &text, spec, None)?;
    Ok((params, source, text))
}

/// Where a command's parameters came from, so no default is silent: said on stderr when loaded
/// and carried into the JSON (`parameters_source`, `parameters_defaulted`).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct ParamSource {
    /// The parameter file as given, or [`DEMO_SET`].
    pub parameters_source: String,
    /// Tables the model uses that the file left out: the demo set's values stand in.
    pub parameters_defaulted: Vec<&'static str>,
    /// Parameters the file marks as not fitted ([`NOT_FITTED`]: no recording constrained them).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub parameters_not_fitted: Vec<&'static str>,
    /// Effects of the command's model that the model the file was written for (its header's)
    /// lacks: their values are start values, never fitted ([`effects_not_fitted`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub effects_not_fitted: Vec<&'static str>,
}

/// `parameters_source` when no parameter file was given.
pub const DEMO_SET: &str = "built-in demo set";

/// As [`load`], from an opened input, saying (a [`crate::warning::note`]) when the built-in demo
/// set (or part of it) stands in; `role` names what the parameters are for (e.g. "start values").
pub fn load_input(
    input: Option<Input>,
    spec: ModelSpec,
    role: &str,
) -> Result<(ActuatorParams, ParamSource)> {
    load_input_also_for(input, spec, None, role)
}

/// As [`load_input`], the file also checked for `also`: a structure the command fits from the
/// same start values (`diagnose --laws`'s other law), named by its role. Its tables must be
/// valid too, and those the file leaves out are said and listed, as the model's own are.
pub fn load_input_also_for(
    input: Option<Input>,
    spec: ModelSpec,
    also: Option<(ModelSpec, &str)>,
    role: &str,
) -> Result<(ActuatorParams, ParamSource)> {
    match input {
        None => {
            crate::warning::note(format_args!(
                "no parameter file given: {role} are the built-in Terfenol-D demo set"
            ));
            let source = ParamSource {
                parameters_source: DEMO_SET.into(),
                parameters_defaulted: Vec::new(),
                parameters_not_fitted: Vec::new(),
                effects_not_fitted: Vec::new(),
            };
            Ok((ActuatorParams::TERFENOL_DEMO, source))
        }
        Some(input) => {
            let name = input.name.clone();
            let text = input.into_text(MAX_PARAM_FILE_BYTES)?;
            load_text(&name, &text, spec, also)
        }
    }
}

/// A parameter file's text (named `name` in messages) checked for `spec` (and `also`, as in
/// [`load_input_also_for`]), saying which tables the demo set fills in and a multivalued J–A set.
pub fn load_text(
    name: &str,
    text: &str,
    spec: ModelSpec,
    also: Option<(ModelSpec, &str)>,
) -> Result<(ActuatorParams, ParamSource)> {
    let mut f = parse_file(name, text, spec)?;
    if let Some(note) = defaulted_note(name, &f.defaulted) {
        crate::warning::note(note);
    }
    if let Some((other, what)) = also {
        let extra: Vec<&'static str> = parse_file(name, text, other)?
            .defaulted
            .into_iter()
            .filter(|t| !f.defaulted.contains(t))
            .collect();
        if !extra.is_empty() {
            crate::warning::note(format_args!(
                "{name} has no {} for `{other}` ({what}): the demo set's values stand in",
                extra.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", ")
            ));
        }
        f.defaulted.extend(extra);
    }
    // Valid to model-core (it steps), but not a J–A model: said wherever the file is used.
    if let Some(why) = multivalued_ja(spec, &f.params) {
        crate::warning::warn(format_args!(
            "{name}: {why}; a fit and the drive refuse it, other commands use it as given"
        ));
    }
    if let Some(doubt) = crate::field_units::kilo_doubt(name, spec, &f.params) {
        crate::warning::warn(doubt);
    }
    let parameters_not_fitted = not_fitted_in(text);
    Ok((
        f.params,
        ParamSource {
            parameters_source: name.into(),
            parameters_defaulted: f.defaulted,
            parameters_not_fitted,
            effects_not_fitted: effects_not_fitted(text, spec),
        },
    ))
}

/// Largest parameter file read [bytes] (they are a few KB).
const MAX_PARAM_FILE_BYTES: u64 = 1 << 20;

/// The parameter-file format this version writes (model-core's `PARAMETER_FILE_FORMAT`: 2 added
/// `format_version` and made the tables of effects and laws optional; every earlier format loads).
pub const FORMAT_VERSION: i64 = PARAMETER_FILE_FORMAT;

/// The tables `spec` uses.
fn tables_used(spec: ModelSpec) -> Vec<&'static str> {
    let effects = spec.effects().flat_map(|e| e.info().params);
    spec.law().params().iter().chain(effects).map(|p| table_of(p.key)).collect()
}

/// A parameter file, read.
#[derive(Debug, Clone)]
pub struct ParamFile {
    /// The parameters.
    pub params: ActuatorParams,
    /// Its format (1 when it names none).
    pub format_version: i64,
    /// Tables it left out that the model uses: the demo set's values stand in.
    pub defaulted: Vec<&'static str>,
}

/// Parses and checks parameter-file text; errors name the file, line and parameter.
pub fn parse(file: &str, text: &str, spec: ModelSpec) -> Result<ActuatorParams> {
    Ok(parse_file(file, text, spec)?.params)
}

/// As [`parse`], saying which tables were left out and the file's format.
pub fn parse_file(file: &str, text: &str, spec: ModelSpec) -> Result<ParamFile> {
    let mut table: toml::Table = toml::from_str(text).map_err(|e| toml_error(file, text, &e))?;
    let format_version = match table.remove("format_version") {
        None => 1,
        Some(toml::Value::Integer(v)) if (1..=FORMAT_VERSION).contains(&v) => v,
        Some(v) => {
            let line = line_of(text, "format_version").map(|(line, _)| line);
            // Only a whole number can be a format a newer gma wrote.
            let why = match v.as_integer() {
                Some(n) if n > FORMAT_VERSION => "a newer gma wrote it?",
                Some(_) => "formats count from 1",
                None => "it is not an integer",
            };
            located!(file, line, None; "format_version = {v}: this gma reads formats 1 to {FORMAT_VERSION} ({why})")
        }
    };
    let missing: Vec<&'static str> = parameter_tables().filter(|t| !table.contains_key(*t)).collect();
    // The file as written, first: its own errors keep their line and column.
    let strict = toml::from_str::<ActuatorParams>(&without_format_version(text));
    let params = match strict {
        Ok(p) => p,
        Err(e) if missing.is_empty() || !is_missing_one_of(&e, &missing) => {
            return Err(toml_error(file, text, &e))
        }
        Err(_) => {
            let demo =
                toml::Table::try_from(ActuatorParams::TERFENOL_DEMO).context("serialising the demo set")?;
            for t in &missing {
                if let Some(v) = demo.get(*t) {
                    table.insert(t.to_string(), v.clone());
                }
            }
            ActuatorParams::deserialize(table).map_err(|e| {
                let msg = e.message().trim().to_string();
                let what = match msg.strip_prefix("missing field `").and_then(|m| m.strip_suffix('`')) {
                    Some(field) => format!("parameter `{field}` is missing"),
                    None => format!("not a valid parameter file: {msg}"),
                };
                Located::file(file, what)
            })?
        }
    };
    Actuator::new(spec, &params)
        .map_err(|e| located_parameter(file, text, e.name(), format!("{e} (checked for model `{spec}`)")))?;
    // model-core checks the stages the model uses; a NaN or ±inf elsewhere (or a number beyond
    // f32's range) would be kept as read and written on by `fit --params-out`.
    if let Some(name) = non_finite(&toml::Table::try_from(params).context("serialising the parameters")?, "")
    {
        return Err(located_parameter(
            file,
            text,
            &name,
            format!("parameter `{name}` is not a finite number"),
        )
        .into());
    }
    let used = tables_used(spec);
    let defaulted = missing.into_iter().filter(|t| used.contains(t)).collect();
    Ok(ParamFile { params, format_version, defaulted })
}

/// `what` is wrong with parameter `name` (dotted, `ja.alpha`) of the parameter file `text`, at
/// the line that sets it with the value found there; the whole file when no line sets it (a
/// table the file left out, the demo set's).
pub fn located_parameter(file: &str, text: &str, name: &str, what: String) -> Located {
    match line_of(text, name) {
        // Not reached from `drive load`: parsing refuses such a number before the board's check.
        Some((line, value)) if beyond_f32(value) => {
            Located::at(file, line, None, beyond_f32_words(name, value))
        }
        // A whole table (`[mech]`) is named at its header, which has no value to quote.
        Some((line, "")) => Located::at(file, line, None, what),
        Some((line, value)) => Located::at(file, line, None, format!("{what}; found `{}`", echo(value))),
        None => Located::file(file, what),
    }
}

/// A finite number in the file that f32, the precision the models run in, cannot hold (it
/// reads as ±inf, which the checks would call "not a finite number").
fn beyond_f32(value: &str) -> bool {
    value.trim().replace('_', "").parse::<f64>().is_ok_and(|v| v.is_finite() && v.abs() > f64::from(f32::MAX))
}

fn beyond_f32_words(name: &str, value: &str) -> String {
    format!(
        "parameter `{name}` = {} is beyond the range of f32 (±3.4e38), the precision the models run in",
        echo(value)
    )
}

/// The dotted name (`table.key`) of the first non-finite number in `table`, if any.
fn non_finite(table: &toml::Table, prefix: &str) -> Option<String> {
    table.iter().find_map(|(key, value)| {
        let name = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
        match value {
            toml::Value::Float(x) if !x.is_finite() => Some(name),
            toml::Value::Table(t) => non_finite(t, &name),
            _ => None,
        }
    })
}

/// The line (1-based) and value text of parameter `name` in parameter-file text: `table.key`
/// under `[table]`, a top-level `key`, or a table's `[name]` header (value empty).
fn line_of<'t>(text: &'t str, name: &str) -> Option<(u64, &'t str)> {
    // model-core names the second-order amplifier's table by its short name.
    fn table_name(t: &str) -> &str {
        if t == "amp2" {
            "amp_second_order"
        } else {
            t
        }
    }
    // The key is after the last dot: a nested table's name has dots of its own.
    let (table, key) = match name.rsplit_once('.') {
        Some((t, k)) => (Some(table_name(t)), Some(k)),
        None => (None, Some(table_name(name))),
    };
    let mut current: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        let body = line.split('#').next().unwrap_or("").trim();
        if let Some(header) = body.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
            current = Some(header.trim());
            if table.is_none() && current == key {
                return Some((i as u64 + 1, ""));
            }
            continue;
        }
        let Some((k, v)) = body.split_once('=') else { continue };
        if current == table && Some(k.trim()) == key {
            return Some((i as u64 + 1, v.trim()));
        }
    }
    None
}

/// `text` with its top-level `format_version` line blanked with spaces: every byte keeps its
/// offset (line endings too), so an error's span gives the file's line, column and text.
fn without_format_version(text: &str) -> String {
    let mut top_level = true;
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive('\n') {
        top_level &= !line.trim_start().starts_with('[');
        let body = line.trim_end_matches(['\r', '\n']);
        let key = body.split_once('=').map(|(k, _)| k.trim());
        if top_level && key == Some("format_version") {
            out.push_str(&" ".repeat(body.len()));
            out.push_str(&line[body.len()..]);
        } else {
            out.push_str(line);
        }
    }
    out
}

/// Whether `e` is a missing top-level field among `missing`.
fn is_missing_one_of(e: &toml::de::Error, missing: &[&str]) -> bool {
    e.message()
        .trim()
        .strip_prefix("missing field `")
        .and_then(|m| m.strip_suffix('`'))
        .is_some_and(|f| missing.contains(&f))
}

/// The note for tables a file left out that the model uses.
pub fn defaulted_note(file: &str, defaulted: &[&str]) -> Option<String> {
    (!defaulted.is_empty()).then(|| {
        format!(
            "{file} has no {} for this model: the demo set's values stand in (`gma effects` lists them)",
            defaulted.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", ")
        )
    })
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
        None => here(format!("{msg} (at `{at}`){}", top_level_key_hint(before, msg))),
    }
}

/// For a top-level key written below a `[table]` header (TOML puts it in that table): where it
/// belongs. Empty otherwise.
fn top_level_key_hint(before: &str, msg: &str) -> String {
    let Some(field) = msg.strip_prefix("unknown field `").and_then(|m| m.split_once('`')).map(|(f, _)| f)
    else {
        return String::new();
    };
    let Some(table) = before.lines().rev().map(str::trim).find(|l| l.starts_with('[')) else {
        return String::new();
    };
    let top_level = toml::Table::try_from(ActuatorParams::TERFENOL_DEMO)
        .is_ok_and(|t| t.get(field).is_some_and(|v| !v.is_table()));
    if !top_level {
        return String::new();
    }
    format!(
        " — `{field}` is a top-level key: move it above the first `[table]` line (below `{}` it belongs to that table)",
        echo(table)
    )
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
    out.push_str(&format!("format_version = {FORMAT_VERSION}\n"));
    out.push_str(&body);
    Ok(out)
}

/// As [`to_toml`], for a set fitted with `spec`: each table (or top-level key) of an effect or
/// law `spec` does not use is marked as such, since its values are the start values', not
/// fitted (a file is kept whole, so that it loads into any model), and so is each parameter in
/// `not_fitted` ([`not_fitted`]: no recording constrained it), with [`NOT_FITTED`], which
/// commands that would use its value read back ([`not_fitted_in`]).
pub fn to_toml_for(p: &ActuatorParams, header: &str, spec: ModelSpec, not_fitted: &[&str]) -> Result<String> {
    let used = tables_used(spec);
    // `[amp]`'s gain drives every model from `command_V` when a file has no `current_A` (and is
    // fitted then), with `amp` in the spec or not: never said to be unused.
    let amp = table_of(AMPLIFIER_GAIN.key);
    let unused = |t: &str| parameter_tables().any(|u| u == t) && !used.contains(&t) && t != amp;
    let note = format!("not used by model `{spec}`: the start values', not fitted");
    let mut out = String::new();
    let mut table: Option<&str> = None;
    for line in to_toml(p, header)?.lines() {
        if let Some(t) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            table = Some(t);
            if unused(t) {
                out.push_str(&format!("# [{t}]: {note}\n"));
            }
        }
        out.push_str(line);
        let key = (!line.starts_with('#')).then(|| line.split_once('=')).flatten().map(|(k, _)| k.trim());
        match (table, key) {
            (None, Some(k)) if unused(k) => out.push_str(&format!("  # {note}")),
            (Some(t), Some(k)) if not_fitted.contains(&format!("{t}.{k}").as_str()) => {
                out.push_str(&format!("  {NOT_FITTED} no recording constrained it (the start value)"))
            }
            _ => {}
        }
        out.push('\n');
    }
    Ok(out)
}

/// The mark after a value no recording constrained (a fit from current-driven files leaves the
/// amplifier gain at its start value).
pub const NOT_FITTED: &str = "# not fitted:";

/// The parameters parameter-file `text` marks [`NOT_FITTED`].
pub fn not_fitted_in(text: &str) -> Vec<&'static str> {
    let lines: Vec<&str> = text.lines().collect();
    [AMPLIFIER_GAIN.key, ROD_THERMAL_LAG.key]
        .into_iter()
        .filter(|name| {
            line_of(text, name)
                .and_then(|(line, _)| lines.get(line as usize - 1))
                .is_some_and(|l| l.contains(NOT_FITTED))
        })
        .collect()
}

/// The model a parameter file says it was fitted or written for, from its header (`# gma fit
/// --model SPEC …`, `# gma demo, model SPEC`, `# gma.fit (Python) --model SPEC …`), when the
/// drive's compensator would differ from that model's ([`ModelSpec::for_compensator`]: the
/// effects left to feedback do not count): the file's values for the other effects were never
/// fitted.
pub fn written_for_another_model(file: &str, text: &str, spec: ModelSpec) -> Option<String> {
    let written = written_for(text)?;
    (written.for_compensator() != spec.for_compensator()).then(|| {
        let unfitted: Vec<&str> = spec
            .for_compensator()
            .effects()
            .filter(|e| !written.has(*e))
            .map(|e| e.alias().unwrap_or(e.name()))
            .collect();
        let unfitted = if unfitted.is_empty() {
            String::new()
        } else {
            format!(" (its values for `{}` were not fitted)", unfitted.join("`, `"))
        };
        format!(
            "{file} was written for model `{written}` and is loaded as `{spec}`: a set fitted with one \
             structure is not a fit of the other{unfitted}; refit with `--model {spec}`, or load it with \
             `--model {written}`"
        )
    })
}

/// The model a parameter file's header says it was fitted or written for (`# gma fit --model
/// SPEC …`, `# gma demo, model SPEC`, `# gma.fit (Python) --model SPEC …`).
fn written_for(text: &str) -> Option<ModelSpec> {
    let header = text.lines().next().filter(|l| l.starts_with('#'))?;
    let after = header.split_once("--model ").or_else(|| header.split_once(", model "))?.1;
    ModelSpec::parse(after.split_whitespace().next()?).ok()
}

/// The effects of `spec` that the model parameter-file `text` was written for lacks (by their
/// short names): a set fitted as `ja+mech` and run as `eddy+ja+mech` runs the eddy lag's start
/// value. Nothing when the header names no model.
pub fn effects_not_fitted(text: &str, spec: ModelSpec) -> Vec<&'static str> {
    use model_core::MagnetizationLaw as Law;
    let Some(written) = written_for(text) else { return Vec::new() };
    let mut missing: Vec<&'static str> =
        spec.effects().filter(|e| !written.has(*e)).map(|e| e.alias().unwrap_or(e.name())).collect();
    // Another law reads its own table (`ja` implies saturation, but fits `[ja]`, not
    // `[anhysteretic]`): the law run is not the one fitted.
    if spec.law() != written.law() && missing.is_empty() {
        missing.push(match spec.law() {
            Law::Linear => "linear",
            Law::Anhysteretic => "anhysteretic",
            Law::JilesAtherton => "ja",
            Law::Preisach => "preisach",
        });
    }
    missing
}

/// Parses a spec, turning an error's byte range into the offending word. An effect named twice
/// is read once (the documented rule) and warned about: most often it is a typo for another.
pub fn parse_spec(text: &str) -> Result<ModelSpec> {
    let spec = parse_spec_quietly(text)?;
    if let Some(warning) = repeated_effect(text) {
        crate::warning::warn(warning);
    }
    Ok(spec)
}

/// The first effect `text` (a valid spec) names twice, said as a warning. What an effect implies
/// is not named by it: `hysteresis+saturation` names each once, `ja+anhysteretic` saturation twice.
fn repeated_effect(text: &str) -> Option<String> {
    let mut named: Vec<(Effect, &str, usize)> = Vec::new();
    let mut offset = 0;
    for raw in text.split('+') {
        let word = raw.trim();
        let at = offset + raw.len() - raw.trim_start().len();
        offset += raw.len() + 1;
        let effects: Vec<Effect> = match Effect::from_name(word) {
            Some(e) => vec![e],
            None => ModelSpec::parse(word).map(|s| s.effects().collect()).unwrap_or_default(),
        };
        for e in effects {
            if let Some((_, first, first_at)) = named.iter().find(|(n, ..)| *n == e) {
                return Some(format!(
                    "model spec `{text}`: `{e}` is named twice (`{first}` at byte {first_at}, `{word}` at byte \
                     {at}) and counted once; a typo for another effect? (`gma effects` lists them)"
                ));
            }
            named.push((e, word, at));
        }
    }
    None
}

fn parse_spec_quietly(text: &str) -> Result<ModelSpec> {
    ModelSpec::parse(text).map_err(|e| match e {
        model_core::SpecError::UnknownEffect { start, end, suggestion } => {
            // `ja,mech` or `ja mech`: the nearest single word would drop an effect.
            let joined = text
                .split(|c: char| matches!(c, '+' | ',' | ';' | '|' | '&' | '/') || c.is_whitespace())
                .filter(|w| !w.is_empty())
                .collect::<Vec<_>>()
                .join("+");
            let hint = if joined != text && ModelSpec::parse(&joined).is_ok() {
                format!("; effects are joined by `+`: did you mean `{joined}`?")
            } else {
                suggestion.map(|s| format!("; did you mean `{s}`?")).unwrap_or_default()
            };
            anyhow::anyhow!(
                "model spec `{text}`: unknown effect `{}` at byte {start}{hint} (words: {})",
                &text[start..end],
                spec_words().collect::<Vec<_>>().join(", ")
            )
        }
        other => anyhow::anyhow!("model spec `{text}`: {other}"),
    })
}

/// Why a parameter set cannot be a J–A fit result: α·M_s/(3a) ≥ 1 makes the anhysteretic
/// curve multivalued, where a J–A loop is an artefact of the integration (and of the sample
/// rate), not physics. `None` for other laws.
pub fn multivalued_ja(spec: ModelSpec, p: &ActuatorParams) -> Option<String> {
    let ratio = p.ja.mean_field_ratio();
    (spec.law() == model_core::MagnetizationLaw::JilesAtherton && ratio >= 1.0).then(|| {
        format!(
            "J–A α·M_s/(3a) = {ratio:.2} ≥ 1 (α = {}, M_s = {} A/m, a = {} A/m): the anhysteretic curve is \
             multivalued there and the loop an artefact of the integration",
            p.ja.alpha, p.ja.ms_a_per_m, p.ja.a_a_per_m
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORMAT_1: &str = include_str!("../tests/data/params-format-1.toml");

    #[test]
    fn a_parameter_is_found_by_its_table_and_key_or_its_header() {
        let text = "delay_samples = 3\n[mech]\nmass_kg = 0.1 # kg\n\n[amp_second_order]\nk_u = -1.0\n[ja]\nc = 0.2\n";
        assert_eq!(line_of(text, "delay_samples"), Some((1, "3")));
        assert_eq!(line_of(text, "mech"), Some((2, "")));
        assert_eq!(line_of(text, "mech.mass_kg"), Some((3, "0.1")));
        assert_eq!(line_of(text, "amp2.k_u"), Some((6, "-1.0")));
        assert_eq!(line_of(text, "ja.c"), Some((8, "0.2")));
        // Another table's key of the same name, or a table the file left out: no line.
        assert_eq!(line_of(text, "amp.k_u"), None);
        assert_eq!(line_of(text, "thermal.tau_s"), None);
    }

    fn spec(text: &str) -> ModelSpec {
        parse_spec(text).unwrap()
    }

    #[test]
    fn a_file_written_for_another_model_is_said_by_its_header() {
        let said = written_for_another_model("p.toml", FORMAT_1, spec("ja+eddy+mech")).unwrap();
        assert!(
            said.contains("written for model `ja`") && said.contains("for `eddy` were not fitted"),
            "{said}"
        );
        // The effects the drive leaves to feedback do not change its compensator: nothing to say.
        assert_eq!(written_for_another_model("p.toml", FORMAT_1, spec("ja+mech")), None);
        assert_eq!(written_for_another_model("p.toml", FORMAT_1, spec("ja")), None);
        let demo = "# gma demo, model eddy+ja+mech\nformat_version = 2\n";
        assert_eq!(written_for_another_model("p.toml", demo, spec("ja+mech+eddy")), None);
        assert!(
            written_for_another_model("p.toml", demo, spec("ja")).is_some_and(|s| !s.contains("not fitted"))
        );
        let python = "# gma.fit (Python) --model ja (seed 1) on a.csv\nformat_version = 2\n";
        assert!(written_for_another_model("p.toml", python, spec("preisach")).is_some());
        // No header, or one that names no model: nothing to say.
        assert_eq!(written_for_another_model("p.toml", "format_version = 2\n", spec("ja")), None);
    }

    #[test]
    fn a_file_of_the_first_format_still_loads_unchanged() {
        let f = parse_file("old.toml", FORMAT_1, spec("ja+mech")).unwrap();
        assert_eq!(f.format_version, 1);
        assert!(f.defaulted.is_empty());
        assert_eq!(f.params.ja.k_a_per_m, 4174.6553);
        assert_eq!(f.params.magnetostriction.lambda_s, 0.001026324);
        // Written again, it names its format and reads back to the same set.
        let again = parse_file("new.toml", &to_toml(&f.params, "test").unwrap(), spec("ja+mech")).unwrap();
        assert_eq!(again.format_version, FORMAT_VERSION);
        assert_eq!(again.params, f.params);
    }

    /// A fitted set's file marks the tables its model does not use (their values were not
    /// fitted), each once, and reads back to the same set.
    #[test]
    fn a_fitted_file_marks_the_tables_its_model_does_not_use() {
        let p = ActuatorParams::TERFENOL_DEMO;
        let text = to_toml_for(&p, "gma fit --model ja+mech", spec("ja+mech"), &[]).unwrap();
        let note = "not used by model `ja+mech`: the start values', not fitted";
        for unused in ["[preisach]", "[aftereffect]", "[thermal]", "[linear]", "[anhysteretic]"] {
            assert_eq!(
                text.matches(&format!("# {unused}: {note}\n{unused}\n")).count(),
                1,
                "{unused}: {text}"
            );
        }
        for key in ["eddy_tau_s", "delay_samples"] {
            assert!(
                text.lines().any(|l| l.starts_with(key) && l.ends_with(&format!("  # {note}"))),
                "{key}: {text}"
            );
        }
        // What the model uses, and the core every model uses, is not marked.
        // `[amp]`: its gain drives any model from `command_V`.
        for used in ["[ja]", "[mech]", "[magnetostriction]", "[coil]", "[amp]"] {
            assert!(!text.contains(&format!("# {used}")), "{used}: {text}");
        }
        assert!(text.lines().any(|l| l == "rod_length_m = 0.08"), "{text}");
        assert_eq!(text.matches("not used by model").count(), 7, "{text}");
        assert_eq!(parse_file("p.toml", &text, spec("ja+mech")).unwrap().params, p);
    }

    /// A whole sensor delay is written as an integer (as files held it before fractional
    /// delays), a fractional one as a float, and both read back exactly.
    #[test]
    fn a_whole_delay_is_written_as_an_integer_and_a_fraction_reads_back() {
        for (delay, line) in [(3.0, "delay_samples = 3\n"), (3.25, "delay_samples = 3.25\n")] {
            let p = ActuatorParams { delay_samples: delay, ..ActuatorParams::TERFENOL_DEMO };
            let text = to_toml(&p, "test").unwrap();
            assert!(text.contains(line), "{text}");
            assert_eq!(parse_file("p.toml", &text, spec("ja+delay")).unwrap().params.delay_samples, delay);
        }
    }

    #[test]
    fn a_table_left_out_takes_the_defaults_and_says_so_only_when_the_model_uses_it() {
        let start = FORMAT_1.find("[mech]").unwrap();
        let end = FORMAT_1.find("[aftereffect]").unwrap();
        let text = format!("{}{}", &FORMAT_1[..start], &FORMAT_1[end..]);
        let with_mech = parse_file("p.toml", &text, spec("ja+mech")).unwrap();
        assert_eq!(with_mech.defaulted, ["mech"]);
        assert_eq!(with_mech.params.mech, ActuatorParams::TERFENOL_DEMO.mech);
        assert!(defaulted_note("p.toml", &with_mech.defaulted).unwrap().contains("`mech`"));
        assert!(parse_file("p.toml", &text, spec("ja")).unwrap().defaulted.is_empty());
        // A top-level key of an effect (the eddy time constant) too.
        let text = FORMAT_1.replace("eddy_tau_s = 0.00015\n", "");
        assert_eq!(parse_file("p.toml", &text, spec("ja+eddy")).unwrap().defaulted, ["eddy_tau_s"]);
    }

    #[test]
    fn required_values_a_newer_format_and_errors_in_the_file_are_still_refused_with_their_place() {
        let no_dt = FORMAT_1.replace("dt_s = 0.0001\n", "");
        let e = parse_file("p.toml", &no_dt, spec("ja")).unwrap_err().to_string();
        assert!(e.contains("dt_s") && e.contains("missing"), "{e}");
        let newer = format!("format_version = 99\n{FORMAT_1}");
        let e = parse_file("p.toml", &newer, spec("ja")).unwrap_err().to_string();
        assert!(e.contains("format_version = 99"), "{e}");
        // A type error in a file that also leaves a table out keeps its line and column.
        let start = FORMAT_1.find("[mech]").unwrap();
        let end = FORMAT_1.find("[aftereffect]").unwrap();
        let text =
            format!("{}{}", &FORMAT_1[..start], &FORMAT_1[end..]).replace("c = 0.19454733", "c = \"x\"");
        let e = parse_file("p.toml", &text, spec("ja+mech")).unwrap_err().to_string();
        assert!(e.starts_with("p.toml:") && e.contains("ja.c"), "{e}");
        let line = text.lines().position(|l| l.starts_with("c = ")).unwrap() + 1;
        assert!(e.starts_with(&format!("p.toml:{line}:")), "{e}");
    }

    #[test]
    fn the_ja_variant_is_read_by_name_and_defaults_for_old_files_and_a_bad_name_is_placed() {
        use model_core::magnetization::JaVariant;
        // Old files (no key) mean the default, which written files then name.
        let old = parse_file("old.toml", FORMAT_1, spec("ja")).unwrap();
        assert_eq!(old.params.ja.variant, JaVariant::Bulk);
        assert!(to_toml(&old.params, "t").unwrap().contains("variant = \"bulk\""));
        for v in [JaVariant::Original1986, JaVariant::Szewczyk, JaVariant::Ungated1986] {
            let text = FORMAT_1.replace("c = 0.19454733\n", &format!("c = 0.19454733\nvariant = \"{v}\"\n"));
            let f = parse_file("p.toml", &text, spec("ja")).unwrap();
            assert_eq!(f.params.ja.variant, v);
            let written = to_toml(&f.params, "t").unwrap();
            assert!(written.contains(&format!("variant = \"{v}\"")), "{written}");
            assert_eq!(parse_file("again.toml", &written, spec("ja")).unwrap().params, f.params);
        }
        let text = FORMAT_1.replace("c = 0.19454733\n", "c = 0.19454733\nvariant = \"ja-1986\"\n");
        let e = parse_file("p.toml", &text, spec("ja")).unwrap_err().to_string();
        let line = text.lines().position(|l| l.starts_with("variant")).unwrap() + 1;
        assert!(e.starts_with(&format!("p.toml:{line}:")), "{e}");
        assert!(e.contains("ja-1986") && e.contains("\"ja1986\""), "{e}");
    }
}
