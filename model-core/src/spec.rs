//! Model specifications: a `+`-joined list of effects on top of the minimal model (linear
//! magnetization, quadratic magnetostriction, static mechanics, ideal amplifier, no eddy
//! currents). The words are the registry's ([`crate::effects`]): names, aliases and shorthands.

use core::fmt;

pub use crate::effects::Effect;
use crate::effects::{spec_words, Inverse, MagnetizationLaw, EFFECTS, SHORTHANDS};

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

/// The effects the drive's feedback handles instead of its compensator. None of them is implied
/// by another effect (checked here at compile time), so removing them keeps a spec closed.
const LEFT_TO_FEEDBACK: u16 = {
    let mut mask = 0;
    let mut k = 0;
    while k < EFFECTS.len() {
        if matches!(EFFECTS[k].inverse, Inverse::LeftToFeedback) {
            mask |= EFFECTS[k].effect.bit();
        }
        k += 1;
    }
    let mut k = 0;
    while k < EFFECTS.len() {
        if let Some(implied) = EFFECTS[k].implies {
            assert!(mask & implied.bit() == 0, "an implied effect cannot be left to feedback");
        }
        k += 1;
    }
    mask
};

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
            if let Some((_, effects)) = SHORTHANDS.iter().find(|(w, _)| *w == word) {
                for e in effects.iter() {
                    spec = spec.with(*e);
                }
                continue;
            }
            match Effect::from_name(word) {
                Some(e) => spec = spec.with(e),
                None => {
                    return Err(SpecError::UnknownEffect {
                        start,
                        end: start + word.len(),
                        suggestion: nearest_word(word),
                    })
                }
            }
        }
        // Laws that replace each other: every law present must be implied by the most
        // specific one (hysteresis brings saturation; Preisach brings neither).
        let law_effects = || spec.effects().filter(|e| e.info().law.is_some());
        if let Some(top) = law_effects().max_by_key(|e| e.info().law) {
            for other in
                law_effects().filter(|e| *e != top).collect::<heapless::Vec<Effect, 8>>().iter().rev()
            {
                if top.info().implies != Some(*other) {
                    return Err(SpecError::Conflict { first: *other, second: top });
                }
            }
        }
        Ok(spec)
    }

    /// This spec with `effect` added (and what it implies: hysteresis brings saturation).
    pub const fn with(self, effect: Effect) -> ModelSpec {
        ModelSpec { bits: self.bits | effect.bit() }.closed()
    }

    /// This spec without `effect` (what a remaining effect implies stays).
    pub const fn without(self, effect: Effect) -> ModelSpec {
        ModelSpec { bits: self.bits & !effect.bit() }.closed()
    }

    /// Adds what the present effects imply.
    const fn closed(self) -> ModelSpec {
        let mut bits = self.bits;
        let mut k = 0;
        while k < EFFECTS.len() {
            if let Some(implied) = EFFECTS[k].implies {
                if bits & EFFECTS[k].effect.bit() != 0 {
                    bits |= implied.bit();
                }
            }
            k += 1;
        }
        ModelSpec { bits }
    }

    /// The magnetization law the spec selects.
    pub fn law(self) -> MagnetizationLaw {
        MagnetizationLaw::of(self.effects())
    }

    /// Whether the magnetization law carries a history (J–A, Preisach), so that a run starts
    /// from an initial magnetic state of its own (the spec-level twin of
    /// [`crate::Actuator::has_magnetic_memory`]).
    pub fn has_magnetic_memory(self) -> bool {
        matches!(self.law(), MagnetizationLaw::JilesAtherton | MagnetizationLaw::Preisach)
    }

    /// The part of the model the drive's inverse compensator inverts (without the effects its
    /// feedback handles). A mask known at compile time, so that the firmware's optimiser sees
    /// which stages can never be built and leaves their code out.
    pub const fn for_compensator(self) -> ModelSpec {
        ModelSpec { bits: self.bits & !LEFT_TO_FEEDBACK }
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
            // A shorthand stands for its effects when all are present, at its last one's place.
            let shorthand = SHORTHANDS
                .iter()
                .find(|(_, es)| es.len() > 1 && es.contains(&e) && es.iter().all(|x| self.has(*x)));
            let word = match shorthand {
                Some((_, es)) if es.last() != Some(&e) => continue,
                Some((w, _)) => w,
                None => e.alias().unwrap_or(e.name()),
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
    for w in spec_words() {
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
        assert!(ModelSpec::parse(Effect::Hysteresis.name()).unwrap().has(Effect::Saturation));
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
            Err(SpecError::UnknownEffect {
                start: 3,
                end: 7,
                suggestion: Effect::MechanicalDynamics.alias()
            })
        );
        assert_eq!(
            ModelSpec::parse("ja+eddy_curent"),
            Err(SpecError::UnknownEffect { start: 3, end: 14, suggestion: Some(Effect::EddyCurrent.name()) })
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
