//! Model specifications: a `+`-joined list of effects on top of the minimal model (linear
//! magnetization, quadratic magnetostriction, static mechanics, ideal amplifier, no eddy
//! currents), with the names of `docs/cli.md` (the model specification). `linear` is the minimal model.

use core::fmt;

/// One physical effect a model can include.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Effect {
    /// Langevin anhysteretic magnetization instead of the linear one.
    Saturation,
    /// Jiles–Atherton irreversible magnetization (implies saturation).
    Hysteresis,
    /// Rate-dependent field lag in the rod.
    EddyCurrent,
    /// Preisach (relay-plane) hysteresis instead of the linear or Jiles–Atherton magnetization.
    Preisach,
    /// Mass-spring-damper between strain and displacement.
    MechanicalDynamics,
    /// Command voltage → coil current dynamics.
    AmplifierDynamics,
    /// Slow magnetization creep.
    MagneticAftereffect,
    /// Coil heating → thermal expansion of the rod.
    ThermalDrift,
    /// Pure transport delay of the displacement measurement.
    SensorDelay,
}

impl Effect {
    /// Every effect, in chain order.
    pub const ALL: [Effect; 9] = [
        Effect::AmplifierDynamics,
        Effect::EddyCurrent,
        Effect::Saturation,
        Effect::Hysteresis,
        Effect::Preisach,
        Effect::MagneticAftereffect,
        Effect::MechanicalDynamics,
        Effect::ThermalDrift,
        Effect::SensorDelay,
    ];

    /// The contract name.
    pub const fn name(self) -> &'static str {
        match self {
            Effect::Saturation => "saturation",
            Effect::Hysteresis => "hysteresis",
            Effect::EddyCurrent => "eddy_current",
            Effect::Preisach => "preisach",
            Effect::MechanicalDynamics => "mechanical_dynamics",
            Effect::AmplifierDynamics => "amplifier_dynamics",
            Effect::MagneticAftereffect => "magnetic_aftereffect",
            Effect::ThermalDrift => "thermal_drift",
            Effect::SensorDelay => "sensor_delay",
        }
    }

    /// The contract alias, if any.
    pub const fn alias(self) -> Option<&'static str> {
        match self {
            Effect::Saturation => Some("anhysteretic"),
            Effect::Hysteresis => None,
            Effect::EddyCurrent => Some("eddy"),
            Effect::Preisach => None,
            Effect::MechanicalDynamics => Some("mech"),
            Effect::AmplifierDynamics => Some("amp"),
            Effect::MagneticAftereffect => Some("aftereffect"),
            Effect::ThermalDrift => Some("thermal"),
            Effect::SensorDelay => Some("delay"),
        }
    }

    const fn bit(self) -> u16 {
        1 << (self as u16)
    }

    /// Looks up a name or alias.
    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s || e.alias() == Some(s))
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of effects (a model structure).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct ModelSpec {
    bits: u16,
}

/// Why a model spec did not parse. Byte offsets point into the spec text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpecError {
    /// The spec is empty.
    Empty,
    /// An empty name between two `+` (at this byte offset).
    EmptyEffect {
        /// Byte offset of the empty slot.
        at: usize,
    },
    /// A name that is no effect; `suggestion` is the nearest known name, if any is close.
    UnknownEffect {
        /// Byte offset where the unknown name starts.
        start: usize,
        /// Byte offset just past it.
        end: usize,
        /// The nearest known name or alias.
        suggestion: Option<&'static str>,
    },
    /// Two effects that replace the same stage (e.g. `preisach` and `hysteresis`).
    Conflict {
        /// One of them.
        first: Effect,
        /// The other.
        second: Effect,
    },
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SpecError::Empty => write!(f, "empty model spec (try `linear` or e.g. `ja+mech`)"),
            SpecError::EmptyEffect { at } => write!(f, "empty effect name at byte {at} (two `+` in a row?)"),
            SpecError::UnknownEffect { start, end, suggestion } => {
                write!(f, "unknown effect at bytes {start}..{end}")?;
                if let Some(s) = suggestion {
                    write!(f, " (did you mean `{s}`?)")?;
                }
                Ok(())
            }
            SpecError::Conflict { first, second } => {
                write!(f, "`{first}` and `{second}` both replace the magnetization stage: choose one")
            }
        }
    }
}

impl core::error::Error for SpecError {}

/// Every accepted word, for suggestions.
const WORDS: [&str; 18] = [
    "linear",
    "preisach",
    "ja",
    "saturation",
    "anhysteretic",
    "hysteresis",
    "eddy_current",
    "eddy",
    "mechanical_dynamics",
    "mech",
    "amplifier_dynamics",
    "amp",
    "magnetic_aftereffect",
    "aftereffect",
    "thermal_drift",
    "thermal",
    "sensor_delay",
    "delay",
];

impl ModelSpec {
    /// The minimal model.
    pub const LINEAR: ModelSpec = ModelSpec { bits: 0 };

    /// Parses `linear`, `ja+mech`, `anhysteretic+eddy+amp`, … (case-sensitive, spaces around `+`
    /// allowed). `ja` = `saturation+hysteresis`; `hysteresis` implies `saturation`.
    pub fn parse(text: &str) -> Result<ModelSpec, SpecError> {
        if text.trim().is_empty() {
            return Err(SpecError::Empty);
        }
        let mut spec = ModelSpec::LINEAR;
        let mut offset = 0;
        for raw in text.split('+') {
            let lead = raw.len() - raw.trim_start().len();
            let word = raw.trim();
            let start = offset + lead;
            offset += raw.len() + 1;
            if word.is_empty() {
                return Err(SpecError::EmptyEffect { at: start });
            }
            match word {
                "linear" => {}
                "ja" => spec = spec.with(Effect::Hysteresis),
                _ => match Effect::from_name(word) {
                    Some(e) => spec = spec.with(e),
                    None => {
                        return Err(SpecError::UnknownEffect {
                            start,
                            end: start + word.len(),
                            suggestion: nearest_word(word),
                        })
                    }
                },
            }
        }
        if spec.has(Effect::Preisach) {
            for other in [Effect::Hysteresis, Effect::Saturation] {
                if spec.has(other) {
                    return Err(SpecError::Conflict { first: other, second: Effect::Preisach });
                }
            }
        }
        Ok(spec)
    }

    /// This spec with `effect` added (hysteresis brings saturation with it).
    pub const fn with(self, effect: Effect) -> ModelSpec {
        let mut bits = self.bits | effect.bit();
        if matches!(effect, Effect::Hysteresis) {
            bits |= Effect::Saturation.bit();
        }
        ModelSpec { bits }
    }

    /// This spec without `effect` (saturation stays while hysteresis needs it).
    pub const fn without(self, effect: Effect) -> ModelSpec {
        let mut bits = self.bits & !effect.bit();
        if bits & Effect::Hysteresis.bit() != 0 {
            bits |= Effect::Saturation.bit();
        }
        ModelSpec { bits }
    }

    /// Whether the spec includes `effect`.
    pub const fn has(self, effect: Effect) -> bool {
        self.bits & effect.bit() != 0
    }

    /// The effects in chain order.
    pub fn effects(self) -> impl Iterator<Item = Effect> {
        Effect::ALL.into_iter().filter(move |e| self.has(*e))
    }
}

/// Canonical text: `linear`, or the short names in chain order (`ja` for saturation+hysteresis).
impl fmt::Display for ModelSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.bits == 0 {
            return f.write_str("linear");
        }
        let mut first = true;
        for e in self.effects() {
            let word = match e {
                Effect::Saturation if self.has(Effect::Hysteresis) => continue,
                Effect::Hysteresis => "ja",
                _ => e.alias().unwrap_or(e.name()),
            };
            if !first {
                f.write_str("+")?;
            }
            f.write_str(word)?;
            first = false;
        }
        Ok(())
    }
}

/// The known word with the smallest edit distance to `word`, if at most 3 (or a prefix match).
fn nearest_word(word: &str) -> Option<&'static str> {
    let mut best: Option<(usize, &'static str)> = None;
    for w in WORDS {
        let d = if w.starts_with(word) && word.len() >= 3 { 1 } else { edit_distance(word, w) };
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, w));
        }
    }
    best.filter(|(d, _)| *d <= 3).map(|(_, w)| w)
}

/// Levenshtein distance over bytes, for names up to 32 bytes (longer words are never close).
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() > 32 || b.len() > 32 {
        return usize::MAX;
    }
    let mut prev = [0usize; 33];
    let mut cur = [0usize; 33];
    for (j, p) in prev.iter_mut().enumerate().take(b.len() + 1) {
        *p = j;
    }
    for i in 1..=a.len() {
        cur[0] = i;
        for j in 1..=b.len() {
            let sub = prev[j - 1] + usize::from(a[i - 1] != b[j - 1]);
            cur[j] = sub.min(prev[j] + 1).min(cur[j - 1] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_contract_names_and_aliases() {
        let s = ModelSpec::parse("ja+mech+eddy").unwrap();
        assert!(s.has(Effect::Saturation) && s.has(Effect::Hysteresis));
        assert!(s.has(Effect::MechanicalDynamics) && s.has(Effect::EddyCurrent));
        assert!(!s.has(Effect::AmplifierDynamics));
        assert_eq!(ModelSpec::parse("linear").unwrap(), ModelSpec::LINEAR);
        assert_eq!(
            ModelSpec::parse("anhysteretic + mech").unwrap(),
            ModelSpec::parse("saturation+mechanical_dynamics").unwrap()
        );
        assert!(ModelSpec::parse("hysteresis").unwrap().has(Effect::Saturation));
        for e in Effect::ALL {
            assert_eq!(ModelSpec::parse(e.name()).unwrap(), ModelSpec::LINEAR.with(e));
        }
    }

    #[test]
    fn canonical_text_round_trips() {
        for text in ["linear", "ja+mech", "amp+eddy+anhysteretic+aftereffect+mech+thermal+delay"] {
            let s = ModelSpec::parse(text).unwrap();
            let mut buf = heapless::String::<128>::new();
            core::fmt::write(&mut buf, format_args!("{s}")).unwrap();
            assert_eq!(ModelSpec::parse(&buf).unwrap(), s, "{text} -> {buf}");
        }
    }

    #[test]
    fn typos_get_a_suggestion_and_a_position() {
        assert_eq!(
            ModelSpec::parse("ja+mehc"),
            Err(SpecError::UnknownEffect { start: 3, end: 7, suggestion: Some("mech") })
        );
        assert_eq!(
            ModelSpec::parse("ja+eddy_curent"),
            Err(SpecError::UnknownEffect { start: 3, end: 14, suggestion: Some("eddy_current") })
        );
        assert!(matches!(
            ModelSpec::parse("quantum_foam"),
            Err(SpecError::UnknownEffect { suggestion: None, .. })
        ));
        assert_eq!(ModelSpec::parse("ja++mech"), Err(SpecError::EmptyEffect { at: 3 }));
        assert_eq!(ModelSpec::parse("  "), Err(SpecError::Empty));
        assert_eq!(
            ModelSpec::parse("preisach+ja"),
            Err(SpecError::Conflict { first: Effect::Hysteresis, second: Effect::Preisach })
        );
    }
}
