//! `gma fit --fix/--bound`: parameters held at their start value, and narrowed search ranges.

use anyhow::{bail, Result};
use model_core::{Actuator, ActuatorParams, ModelSpec};

use super::free_params::{identifiable, FreeParam};
use crate::recording::Recording;
use crate::search::Bound;

/// `gma fit --fix/--bound`: parameters held at their start value, and narrowed search ranges.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Constraints {
    /// Held at their start value: not searched, not reported as identified.
    pub fixed: Vec<&'static str>,
    /// Narrowed ranges (name, lo, hi), within the registry's.
    pub bounds: Vec<(&'static str, f64, f64)>,
}

impl Constraints {
    /// Parses `--fix NAME[=VALUE]` and `--bound NAME=LO:HI` for `spec` on `files`; a fixed
    /// VALUE is written into `init`. Refuses (naming the option) unknown names, a name given
    /// twice, values outside the registry's range, and ranges that are empty or leave it: a
    /// bound only narrows.
    pub fn parse(
        spec: ModelSpec,
        files: &[Recording],
        fix: &[String],
        bound: &[String],
        init: &mut ActuatorParams,
    ) -> Result<Self> {
        let known = identifiable(spec, files)?;
        let names = || known.iter().map(|f| format!("`{}`", f.name())).collect::<Vec<_>>().join(", ");
        let find = |opt: &str, name: &str| -> Result<FreeParam> {
            let name = name.trim();
            known.iter().find(|f| f.name() == name).copied().ok_or_else(|| {
                anyhow::anyhow!(
                    "{opt} {}: model `{spec}` identifies no such parameter on these files (it identifies {})",
                    crate::files::echo(name),
                    names()
                )
            })
        };
        let number = |opt: &str, what: &str, text: &str| -> Result<f64> {
            text.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                anyhow::anyhow!("{opt} {what}: `{}` is not a number", crate::files::echo(text.trim()))
            })
        };
        let mut c = Constraints::default();
        let mut seen: Vec<&'static str> = Vec::new();
        let mut once = |opt: &str, name: &'static str| -> Result<()> {
            if seen.contains(&name) {
                bail!("{opt} {name}: `{name}` is already fixed or bounded (give each parameter one --fix or --bound)");
            }
            seen.push(name);
            Ok(())
        };
        for arg in fix {
            let (name, value) = match arg.split_once('=') {
                Some((n, v)) => (n, Some(v)),
                None => (arg.as_str(), None),
            };
            let f = find("--fix", name)?;
            once("--fix", f.name())?;
            if let Some(text) = value {
                let v = number("--fix", f.name(), text)?;
                let b = f.bound;
                if !(b.lo..=b.hi).contains(&v) {
                    bail!("--fix {}={v}: outside its range [{}, {}]", f.name(), b.lo, b.hi);
                }
                (f.set)(init, v);
                // Inside its own range, but it may not fit the file's other values.
                if let Err(e) = Actuator::new(spec, init) {
                    bail!("--fix {}={v}: with the start set's other values: {e}", f.name());
                }
            }
            c.fixed.push(f.name());
        }
        for arg in bound {
            let Some((name, range)) = arg.split_once('=') else {
                bail!("--bound {}: expected NAME=LO:HI", crate::files::echo(arg));
            };
            let f = find("--bound", name)?;
            once("--bound", f.name())?;
            let Some((lo, hi)) = range.split_once(':') else {
                bail!("--bound {}: expected NAME=LO:HI, got `{}`", f.name(), crate::files::echo(range));
            };
            let (lo, hi) = (number("--bound", f.name(), lo)?, number("--bound", f.name(), hi)?);
            let b = f.bound;
            if lo >= hi {
                bail!(
                    "--bound {}={lo}:{hi}: empty range (LO must be below HI; to hold a value use --fix)",
                    f.name()
                );
            }
            if lo < b.lo || hi > b.hi {
                bail!(
                    "--bound {}={lo}:{hi}: leaves the parameter's range [{}, {}] (a bound can only narrow it)",
                    f.name(),
                    b.lo,
                    b.hi
                );
            }
            // The start is moved into the range: it may not fit the file's other values there.
            let mut moved = *init;
            let narrowed = Bound { lo, hi, ..b };
            let used = narrowed.from_unit(narrowed.to_unit((f.get)(init)));
            (f.set)(&mut moved, used);
            if let Err(e) = Actuator::new(spec, &moved) {
                bail!("--bound {}={lo}:{hi}: the start value moved into it, {used:.4e}, with the start set's other values: {e}", f.name());
            }
            c.bounds.push((f.name(), lo, hi));
        }
        Ok(c)
    }

    /// Whether `name` is held fixed.
    pub fn is_fixed(&self, name: &str) -> bool {
        self.fixed.contains(&name)
    }

    /// `b` narrowed by a `--bound` on its parameter.
    pub fn narrow(&self, b: Bound) -> Bound {
        match self.bounds.iter().find(|(n, _, _)| *n == b.name) {
            Some(&(_, lo, hi)) => Bound { lo, hi, ..b },
            None => b,
        }
    }
}
