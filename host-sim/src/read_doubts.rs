//! What the measurement reader says about a file it read, beside its numbers: the columns it did
//! not use, a column whose name looks like a recognised quantity under a name it does not read
//! (with the `--column` that reads it), time stamps held as offsets from the first, and a time
//! axis implausible for an actuator rig. Said on stderr and listed in the JSON `warnings`
//! ([`crate::warning::Warning::Read`]), so that no column and no unit slips by unsaid.

use std::fmt;

use crate::columns::{unit_names, ReadOptions, UNITS};
use crate::files::echo;
use crate::recording::{Recording, COLUMNS};

/// Lowest drive frequency plausible for a magnetostrictive actuator's rig [Hz]: a cycle every
/// 100 s. A 10 Hz drive logged in ms under `time_s` lands at 0.01 Hz.
pub const MIN_DRIVE_HZ: f64 = 0.01;

/// Highest plausible drive frequency [Hz]: eddy currents and the mechanics end a rod's response
/// far below 100 kHz.
pub const MAX_DRIVE_HZ: f64 = 1e5;

/// Fewest samples per cycle of the drive or the displacement that still trace its shape: fewer,
/// and the signal is aliased, or the time axis is not the one the samples were taken on.
pub const MIN_SAMPLES_PER_CYCLE: f64 = 4.0;

/// Shortest sample period [s] from which on a recording is a slow logger's: a rig recording an
/// actuator's response samples at 1–100 kHz, and 10 ms is 100 Hz.
pub const SLOW_STEP_S: f64 = 0.01;

/// Fewest samples per drive cycle a slow logger ([`SLOW_STEP_S`]) plausibly takes: a slow drive
/// logged slowly for a quasi-static loop has hundreds. Fewer at such a step is what a 10 kHz
/// recording's time in ms read as seconds looks like (its drive 1000× slower, its samples per
/// cycle unchanged).
pub const MIN_SLOW_SAMPLES_PER_CYCLE: f64 = 200.0;

/// A doubt about how a file was read.
#[derive(Debug, Clone, PartialEq)]
pub enum ReadDoubt {
    /// Columns the reader did not use (a note).
    UnusedColumns {
        /// The file.
        file: String,
        /// Their headers.
        columns: Vec<String>,
    },
    /// A column not read whose name says a recognised quantity.
    LooksLike {
        /// The file.
        file: String,
        /// Its header.
        header: String,
        /// The recognised column it looks like (one of [`COLUMNS`]).
        canonical: usize,
        /// The header that column is read from, when the file has one.
        read_from: Option<String>,
        /// The `--column` argument that reads it (quoted for a shell where needed).
        option: String,
    },
    /// Time stamps too large for an `f64` to resolve the step, held as offsets from the first
    /// (a note).
    StampsFromFirst {
        /// The file.
        file: String,
        /// The first stamp as written [s].
        origin: String,
    },
    /// A time axis that no actuator rig records on.
    ImplausibleTime {
        /// The file.
        file: String,
        /// Its sample period [s].
        step_s: f64,
        /// What is implausible.
        why: String,
    },
}

impl ReadDoubt {
    /// Whether this is a note (what was done, said) rather than a doubt about the result.
    pub fn is_note(&self) -> bool {
        matches!(self, ReadDoubt::UnusedColumns { .. } | ReadDoubt::StampsFromFirst { .. })
    }
}

impl fmt::Display for ReadDoubt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadDoubt::UnusedColumns { file, columns } => write!(
                f,
                "{file}: column{} not used: {} (not a recognised column; `--column CANONICAL=HEADER[:UNIT]` \
                 reads one as {})",
                if columns.len() == 1 { "" } else { "s" },
                columns.iter().map(|c| format!("`{}`", echo(c))).collect::<Vec<_>>().join(", "),
                COLUMNS.join(", ")
            ),
            ReadDoubt::LooksLike { file, header, canonical, read_from, option } => write!(
                f,
                "{file}: `{}` looks like {} but is not read ({}): if it is, read it with `--column {option}` \
                 (without `:UNIT` its values are read in {}; the units: one of {})",
                echo(header),
                QUANTITY[*canonical],
                match read_from {
                    Some(h) => format!("`{}` is read from `{}`", COLUMNS[*canonical], echo(h)),
                    None => format!("the file has no `{}`", COLUMNS[*canonical]),
                },
                UNITS[*canonical][0].name,
                unit_names(*canonical)
            ),
            ReadDoubt::StampsFromFirst { file, origin } => write!(
                f,
                "{file}: time stamps read as offsets from the first, {} s (at that magnitude a 64-bit \
                 float does not resolve the sample period; the offsets are exact)",
                echo(origin)
            ),
            ReadDoubt::ImplausibleTime { file, step_s, why } => write!(
                f,
                "{file}: the time axis is implausible for an actuator rig: {why} (a sample every {step_s:.4e} s); \
                 is `time_s` in seconds? A time column in ms is read with `--column time_s=HEADER:ms` (the \
                 file's own `time_s` too: `--column time_s=time_s:ms`), one in µs with `:us`"
            ),
        }
    }
}

/// What each recognised column's quantity is called in a message (same order as [`COLUMNS`]).
const QUANTITY: [&str; COLUMNS.len()] = [
    "a time axis",
    "the amplifier command",
    "the coil current",
    "the displacement",
    "the force",
    "the coil temperature",
    "the flux density",
];

/// The recognised column a header's name suggests (by its words, case ignored), if any:
/// `T_coil (°C)`, `coil_temp_C`, `Temperature [K]` a temperature, `I_coil` a current, `x_um` a
/// displacement, `B_search` a flux density, `cmd` a command.
pub(crate) fn suggested(header: &str) -> Option<usize> {
    let lower = header.trim().to_lowercase();
    let words: Vec<&str> = lower.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).collect();
    let first = words.first().copied().unwrap_or("");
    let any = |p: &dyn Fn(&str) -> bool| words.iter().any(|w| p(w));
    if any(&|w| w.starts_with("time"))
        || (first == "t" && words.get(1).is_some_and(|u| ["s", "ms", "us", "µs"].contains(u)))
    {
        Some(0)
    } else if any(&|w| w.starts_with("temp")) || lower.contains("°c") || (first == "t" && words.len() > 1) {
        Some(5)
    } else if any(&|w| w.starts_with("curr")) || first == "i" {
        Some(2)
    } else if any(&|w| w.starts_with("disp") || w.starts_with("stroke") || w.starts_with("position"))
        || first == "x"
    {
        Some(3)
    } else if any(&|w| w.starts_with("flux")) || first == "b" {
        Some(6)
    } else if any(&|w| w.starts_with("command") || w.starts_with("cmd") || w.starts_with("volt"))
        || first == "u"
    {
        Some(1)
    } else if any(&|w| w.starts_with("force")) {
        Some(4)
    } else {
        None
    }
}

/// A `--column` argument that reads `header` as column `k`: with the unit its name ends in
/// (`x_mm` → `:mm`, `T (kelvin)` → `:K`), or `:UNIT` to be filled in when it ends in a unit in
/// brackets that is not one of the column's; quoted where a shell would split it.
pub(crate) fn column_option(k: usize, header: &str) -> String {
    let ends_in = |u: &str| {
        ["_", " ", "/"].iter().any(|sep| header.ends_with(&format!("{sep}{u}")))
            || header.ends_with(&format!("[{u}]"))
            || header.ends_with(&format!("({u})"))
    };
    let bracketed = header.ends_with([')', ']']);
    let unit = match UNITS[k].iter().find(|u| ends_in(u.name)) {
        Some(u) if u.is_identity() => None,
        Some(u) => Some(u.name),
        None if k == 5 && header.to_lowercase().contains("kelvin") => Some("K"),
        None if bracketed => Some("UNIT"),
        None => None,
    };
    let arg = match unit {
        Some(u) => format!("{}={header}:{u}", COLUMNS[k]),
        None => format!("{}={header}", COLUMNS[k]),
    };
    crate::files::shell_word(std::path::Path::new(&arg))
}

/// The doubts about a file's columns: `headers` as in the file, `used` whether each was read.
pub fn column_doubts(file: &str, headers: &[&str], used: &[bool], opts: &ReadOptions) -> Vec<ReadDoubt> {
    let unused: Vec<&str> = headers.iter().zip(used).filter(|(_, u)| !**u).map(|(h, _)| h.trim()).collect();
    if unused.is_empty() {
        return Vec::new();
    }
    let read_from = |k: usize| match opts.map_of(k) {
        Some(m) => Some(m.header.clone()),
        None => headers.iter().any(|h| h.trim() == COLUMNS[k]).then(|| COLUMNS[k].to_string()),
    };
    let mut doubts = vec![ReadDoubt::UnusedColumns {
        file: file.to_string(),
        columns: unused.iter().map(|h| h.to_string()).collect(),
    }];
    for header in unused {
        // Time is always read: another column named like it is not the axis.
        if let Some(k) = suggested(header).filter(|&k| k != 0) {
            doubts.push(ReadDoubt::LooksLike {
                file: file.to_string(),
                header: header.to_string(),
                canonical: k,
                read_from: read_from(k),
                option: column_option(k, header),
            });
        }
    }
    doubts
}

/// Cycles of `x` (half its direction reversals, ignoring wiggles below 10 % of its span).
fn cycles(x: &[f64]) -> f64 {
    crate::diagnose::reversals(x) as f64 / 2.0
}

/// The doubt about a recording's time axis, if it is implausible for an actuator rig: the drive
/// frequency it implies below [`MIN_DRIVE_HZ`] or above [`MAX_DRIVE_HZ`], a slow logger's step
/// with fewer than [`MIN_SLOW_SAMPLES_PER_CYCLE`] samples per drive cycle, or the drive or the
/// displacement going through a cycle in fewer than [`MIN_SAMPLES_PER_CYCLE`] samples.
pub fn time_doubt(r: &Recording) -> Option<ReadDoubt> {
    let (n, step_s, duration) = (r.len() as f64, r.dt_s(), r.duration_s());
    let drive = r.current_a.as_deref().or(r.command_v.as_deref())?;
    let drive_cycles = cycles(drive);
    let why = if drive_cycles >= 1.0 && duration > 0.0 {
        let (hz, per_cycle) = (drive_cycles / duration, n / drive_cycles);
        if hz < MIN_DRIVE_HZ {
            Some(format!("the drive's cycles come at {hz:.3e} Hz, below {MIN_DRIVE_HZ} Hz"))
        } else if hz > MAX_DRIVE_HZ {
            Some(format!("the drive's cycles come at {hz:.3e} Hz, above {MAX_DRIVE_HZ:.0e} Hz"))
        } else if step_s >= SLOW_STEP_S && per_cycle < MIN_SLOW_SAMPLES_PER_CYCLE {
            Some(format!(
                "a sample rate of {:.3} Hz with {per_cycle:.0} samples per drive cycle ({hz:.3e} Hz): a rig \
                 recording an actuator samples at 1–100 kHz, and a slow drive logged slowly has hundreds \
                 per cycle",
                1.0 / step_s
            ))
        } else {
            None
        }
    } else {
        None
    };
    let why = why.or_else(|| {
        let channels = [("drive", Some(drive)), ("displacement", r.displacement_um.as_deref())];
        channels.into_iter().find_map(|(what, x)| {
            let per_cycle = n / cycles(x?);
            (per_cycle < MIN_SAMPLES_PER_CYCLE).then(|| {
                format!(
                    "the {what} goes through a cycle every {per_cycle:.1} samples ({:.3e} Hz)",
                    1.0 / (per_cycle * step_s)
                )
            })
        })
    })?;
    Some(ReadDoubt::ImplausibleTime { file: r.name.clone(), step_s, why })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_and_other_quantities_are_told_by_their_names() {
        for (h, k) in [
            ("T_coil (°C)", Some(5)),
            ("coil_temp_C", Some(5)),
            ("Temperature [K]", Some(5)),
            ("I_coil", Some(2)),
            ("x_um", Some(3)),
            ("B_search", Some(6)),
            ("cmd", Some(1)),
            ("t_ms", Some(0)),
            ("faults", None),
            ("reference_um", None),
        ] {
            assert_eq!(suggested(h), k, "{h}");
        }
    }

    #[test]
    fn the_proposed_mapping_parses_and_converts_the_unit() {
        for (k, h, option) in [
            (5, "Temperature [K]", "'temperature_C=Temperature [K]:K'"),
            (5, "coil_temp_C", "temperature_C=coil_temp_C"),
            (5, "T_coil (°C)", "'temperature_C=T_coil (°C)'"),
            (5, "Temperature (kelvin)", "'temperature_C=Temperature (kelvin):K'"),
            (3, "x_mm", "displacement_um=x_mm:mm"),
        ] {
            let o = column_option(k, h);
            assert_eq!(o, option);
            let m = crate::columns::ColumnMap::parse(o.trim_matches('\'')).unwrap();
            assert_eq!((m.canonical, m.header.as_str()), (k, h));
        }
    }
}
