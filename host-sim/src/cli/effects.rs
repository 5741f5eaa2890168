//! `gma effects`: the effect registry — names, what each adds, where it acts, its identified
//! parameters with units and ranges — as text, as the Markdown tables of docs/cli.md, or JSON.

use anyhow::Result;
use clap::Args;
use model_core::effects::{
    Candidacy, EffectInfo, Inverse, JaVariant, MagnetizationLaw, Param, Scale, Signature, Stage,
    AMPLIFIER_GAIN, EFFECTS, JA_VARIANT_KEY, ROD_THERMAL_LAG, SHORTHANDS, STRAIN_SCALE,
};
use model_core::ActuatorParams;
use serde_json::json;

/// Options of `gma effects`.
#[derive(Args)]
pub struct EffectsArgs {
    /// The Markdown tables docs/cli.md carries (generated: a test compares them).
    #[arg(long, conflicts_with = "json")]
    pub markdown: bool,
    /// One JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `gma effects`.
pub fn run(a: &EffectsArgs) -> Result<()> {
    if a.json {
        out!("{}", to_json());
    } else if a.markdown {
        out!("{}", markdown());
    } else {
        for e in &EFFECTS {
            let alias = e.alias.map(|a| format!(" ({a})")).unwrap_or_default();
            out!("{}{alias}: {} [{}]", e.name, e.adds, stage(e.stage));
        }
        for (word, effects) in SHORTHANDS {
            let names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
            out!(
                "{word}: {}",
                if names.is_empty() { "no effects (the minimal model)".into() } else { names.join(" + ") }
            );
        }
        out!("parameters a fit identifies (key [unit], search range, scale, default), by when:");
        for (when, params) in identified() {
            out!("  {when}:");
            for p in params {
                out!("    {}", param_line(p));
            }
        }
        for v in JaVariant::ALL {
            out!("{JA_VARIANT_KEY} = \"{}\"{}: {} ({})", v.name(), default_mark(v), v.equation(), v.paper());
        }
    }
    Ok(())
}

fn stage(s: Stage) -> &'static str {
    match s {
        Stage::Amplifier => "amplifier",
        Stage::RodField => "field in the rod",
        Stage::Magnetization => "magnetization law",
        Stage::MagnetizationCreep => "magnetization creep",
        Stage::Mechanics => "mechanics",
        Stage::Thermal => "thermal strain",
        Stage::Sensor => "displacement sensor",
    }
}

fn signature(s: Signature) -> &'static str {
    match s {
        Signature::Lag => "lag −dy/dt",
        Signature::Resonance => "resonance −ÿ",
        Signature::Branch => "loop opening sign(dH/dt)",
        Signature::Cubic => "cubic (H − H̄)³",
        Signature::Creep => "creep lowpass(y) − y",
        Signature::Heating => "heating ∫i² dt",
        Signature::None => "—",
    }
}

fn candidacy(c: Candidacy) -> &'static str {
    match c {
        Candidacy::Always => "yes",
        Candidacy::NeedsCommand => "when every file has `command_V`",
        Candidacy::RefinesLaw => "when it refines the model's law",
        Candidacy::Never => "no (an alternative law)",
    }
}

fn inverse(i: Inverse) -> &'static str {
    match i {
        Inverse::Inverted => "inverted",
        Inverse::LeftToFeedback => "left to feedback",
    }
}

fn range(p: &Param) -> String {
    // Plain numbers where they read well, exponents for the very small and large.
    let num =
        |v: f64| if v == 0.0 || (1e-3..1e5).contains(&v.abs()) { format!("{v}") } else { format!("{v:e}") };
    format!("[{}, {}]", num(p.lo), num(p.hi))
}

fn scale(p: &Param) -> &'static str {
    match p.scale {
        Scale::Linear => "linear",
        Scale::Log => "log",
    }
}

/// The demo set's value (parameter sets are single precision: shown as such).
fn default(p: &Param) -> f32 {
    (p.get)(&ActuatorParams::TERFENOL_DEMO) as f32
}

/// A default that lies outside its parameter's search range: what it means, and when the range
/// is searched instead. The rod's thermal lag defaults to 0, no lag; it is searched only on
/// files that log the coil's temperature (docs/formats.md, `[thermal] rod_tau_s`).
struct OffRange {
    /// What the default means.
    means: &'static str,
    /// When the search range applies.
    searched_when: &'static str,
}

fn off_range(p: &Param) -> Option<OffRange> {
    (p.key == ROD_THERMAL_LAG.key).then_some(OffRange {
        means: "no lag (the rod follows the coil at once)",
        searched_when: "a file logs `temperature_C`",
    })
}

fn param_line(p: &Param) -> String {
    match off_range(p) {
        Some(o) => format!(
            "{} [{}], default {} = {}; searched in {} ({}) when {}",
            p.key,
            p.unit,
            default(p),
            o.means,
            range(p),
            scale(p),
            o.searched_when
        ),
        None => format!("{} [{}] in {} ({}), default {}", p.key, p.unit, range(p), scale(p), default(p)),
    }
}

/// The words a JSON parameter carries about its default (`null` when the default is in range).
fn json_note(p: &Param) -> Option<String> {
    off_range(p).map(|o| {
        format!("default {} = {}; searched in {} when {}", default(p), o.means, range(p), o.searched_when)
    })
}

/// Which parameters are identified when: (condition, parameters).
fn identified() -> Vec<(String, Vec<&'static Param>)> {
    let mut rows = vec![("always (least squares)".to_string(), vec![&STRAIN_SCALE])];
    for law in MagnetizationLaw::ALL {
        let by = EFFECTS
            .iter()
            .filter(|e| e.law == Some(law))
            .map(|e| format!("`{}`", e.name))
            .collect::<Vec<_>>();
        let when = if by.is_empty() {
            "linear law (no law effect)".to_string()
        } else {
            format!("{} law", by.join(", "))
        };
        rows.push((when, law.params().iter().collect()));
    }
    rows.push(("files without `current_A`, or `amplifier_dynamics`".into(), vec![&AMPLIFIER_GAIN]));
    for e in EFFECTS.iter().filter(|e| !e.params.is_empty()) {
        rows.push((format!("`{}`", e.name), e.params.iter().collect()));
    }
    rows.push(("`thermal_drift` on files with `temperature_C`".into(), vec![&ROD_THERMAL_LAG]));
    rows
}

/// The two tables of docs/cli.md.
pub fn markdown() -> String {
    let mut s = String::from(
        "| effect | alias | what it adds | stage | residual signature | diagnosis tries it | drive's compensator |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for e in &EFFECTS {
        s.push_str(&effect_row(e));
    }
    s.push_str("\nShorthands: ");
    let words: Vec<String> = SHORTHANDS
        .iter()
        .map(|(w, es)| {
            let names: Vec<String> = es.iter().map(|e| format!("`{}`", e.name())).collect();
            format!("`{w}` = {}", if names.is_empty() { "no effects".into() } else { names.join(" + ") })
        })
        .collect();
    s.push_str(&words.join("; "));
    s.push_str(
        ".\n\n| identified when | key | unit | search range | scale | default |\n|---|---|---|---|---|---|\n",
    );
    for (when, params) in identified() {
        for (k, p) in params.iter().enumerate() {
            let w = if k == 0 { when.as_str() } else { "" };
            let (searched, default) = match off_range(p) {
                Some(o) => (
                    format!("{} when {}", range(p), o.searched_when),
                    format!("{} = {}", default(p), o.means),
                ),
                None => (range(p), default(p).to_string()),
            };
            s.push_str(&format!(
                "| {w} | `{}` | {} | {searched} | {} | {default} |\n",
                p.key,
                p.unit,
                scale(p)
            ));
        }
    }
    s.push_str(&format!(
        "\nJ–A variants (`[ja] variant = \"…\"` in parameter files, key `{JA_VARIANT_KEY}`; δ = sign dH; \
         δ_M = 1 when δ(M_an − M_irr) > 0, else 0; M_an = M_s L(H_e/a), H_e = H + αM):\n\n\
         | `variant` | equations | paper |\n|---|---|---|\n"
    ));
    for v in JaVariant::ALL {
        s.push_str(&format!("| `{}`{} | {} | {} |\n", v.name(), default_mark(v), v.equation(), v.paper()));
    }
    s.pop();
    s
}

/// Marks the default J–A variant.
fn default_mark(v: JaVariant) -> &'static str {
    if v == JaVariant::default() {
        " (default)"
    } else {
        ""
    }
}

fn effect_row(e: &EffectInfo) -> String {
    format!(
        "| `{}` | {} | {} | {} | {} | {} | {} |\n",
        e.name,
        e.alias.map(|a| format!("`{a}`")).unwrap_or_else(|| "—".into()),
        e.adds,
        stage(e.stage),
        signature(e.signature),
        candidacy(e.candidacy),
        inverse(e.inverse)
    )
}

fn to_json() -> serde_json::Value {
    // The default as the tables print it (a JSON number from an f32 would carry its binary digits).
    let stated = |v: f32| v.to_string().parse::<f64>().unwrap_or(f64::from(v));
    let param = |p: &Param| json!({"key": p.key, "unit": p.unit, "lo": p.lo, "hi": p.hi, "scale": scale(p), "default": stated(default(p)), "note": json_note(p)});
    json!({
        "effects": EFFECTS.iter().map(|e| json!({
            "name": e.name, "alias": e.alias, "adds": e.adds, "stage": stage(e.stage),
            "signature": signature(e.signature), "diagnosis": candidacy(e.candidacy), "compensator": inverse(e.inverse),
            "params": e.params.iter().map(param).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "shorthands": SHORTHANDS.iter().map(|(w, es)| json!({"word": w, "effects": es.iter().map(|e| e.name()).collect::<Vec<_>>()})).collect::<Vec<_>>(),
        "ja_variants": JaVariant::ALL.iter().map(|v| json!({"name": v.name(), "default": *v == JaVariant::default(), "equations": v.equation(), "paper": v.paper()})).collect::<Vec<_>>(),
        "identified": identified().iter().map(|(when, ps)| json!({"when": when, "params": ps.iter().map(|p| param(p)).collect::<Vec<_>>()})).collect::<Vec<_>>(),
    })
}

/// The effects for `gma --help`: `name|alias` for each, and the shorthands.
pub fn help_words() -> String {
    let mut words: Vec<String> = SHORTHANDS.iter().map(|(w, _)| w.to_string()).collect();
    words.extend(EFFECTS.iter().map(|e| match e.alias {
        Some(a) => format!("{}|{a}", e.name),
        None => e.name.to_string(),
    }));
    words.join(", ")
}
