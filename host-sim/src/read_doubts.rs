//! What the measurement reader says about a file it read, beside its numbers: the columns it did
//! not use, a column whose name looks like a recognised quantity under a name it does not read
//! (with the `--column` that reads it), time stamps held as offsets from the first, and a time
//! axis implausible for an actuator rig. Said on stderr and listed in the JSON `warnings`
//! ([`crate::warning::Warning::Read`]), so that no column and no unit slips by unsaid.

use std::fmt;

use crate::columns::{column_option, suggested, unit_names, ReadOptions, COLUMNS, UNITS};
use crate::files::echo;

/// Lowest drive frequency plausible for a magnetostrictive actuator's rig [Hz]: a cycle every
/// 100 s. A 10 Hz drive logged in ms under `time_s` lands at 0.01 Hz.
pub const MIN_DRIVE_HZ: f64 = 0.01;

/// Highest plausible drive frequency [Hz]: eddy currents and the mechanics end a rod's response
/// far below 100 kHz.
pub const MAX_DRIVE_HZ: f64 = 1e5;

/// Fewest samples per cycle of the drive or the displacement that still trace its shape: fewer,
/// and the signal is aliased, or the time axis is not the one the samples were taken on.
pub const MIN_SAMPLES_PER_CYCLE: f64 = 4.0;

/// Longest sample period [s] of a fast recording (1 MHz): an oscilloscope's, not a rig's logger.
pub const FAST_STEP_S: f64 = 1e-6;

/// Highest drive frequency [Hz] a fast recording is taken plausible at: a magnetostrictive
/// actuator is driven below about 20 kHz (eddy currents and the rod's modes end it). Above, at
/// a fast step, is what a file in seconds read as milliseconds looks like (its drive 1000×
/// faster, its samples per cycle unchanged).
pub const FAST_DRIVE_HZ: f64 = 2e4;

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
    /// A time axis far faster than a rig's, with a drive faster than an actuator takes: a file
    /// in seconds read in ms or µs.
    TimeTooFast {
        /// The file.
        file: String,
        /// Its sample period [s].
        step_s: f64,
        /// The drive's cycles per second as read [Hz].
        drive_hz: f64,
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
                "{file}: time stamps read as offsets from the first, {} s (more than 1e9 sample periods \
                 from zero, where a 64-bit float resolves the period to worse than 2e-7 of it; the offsets \
                 are exact, and the `time_s` gma writes for this file are these offsets)",
                echo(origin)
            ),
            ReadDoubt::TimeTooFast { file, step_s, drive_hz } => write!(
                f,
                "{file}: the time axis is implausible for an actuator rig: a sample rate of {:.3e} Hz with the \
                 drive's cycles at {drive_hz:.3e} Hz (a rig samples at 1–100 kHz and drives a magnetostrictive \
                 actuator below {FAST_DRIVE_HZ:.0e} Hz); is `time_s` read in a unit it is not in? A column in \
                 seconds mapped with `:ms` (or `:us`) reads 1000× (10⁶×) too fast: map it without a unit \
                 (`--column time_s=HEADER`), or drop the mapping",
                1.0 / step_s
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
    crate::signal::reversals(x) as f64 / 2.0
}

/// The doubt about a recording's time axis, if it is implausible for an actuator rig: the drive
/// frequency it implies below [`MIN_DRIVE_HZ`] or above [`MAX_DRIVE_HZ`], a slow logger's step
/// with fewer than [`MIN_SLOW_SAMPLES_PER_CYCLE`] samples per drive cycle, or the drive or the
/// displacement going through a cycle in fewer than [`MIN_SAMPLES_PER_CYCLE`] samples.
/// `file` sampled at `step_s` over `duration` [s]; `drive` its current (or command), if any.
pub fn time_doubt(
    file: &str,
    step_s: f64,
    duration: f64,
    drive: Option<&[f64]>,
    displacement: Option<&[f64]>,
) -> Option<ReadDoubt> {
    let drive = drive?;
    let n = drive.len() as f64;
    let drive_cycles = cycles(drive);
    let why = if drive_cycles >= 1.0 && duration > 0.0 {
        let (hz, per_cycle) = (drive_cycles / duration, n / drive_cycles);
        if step_s <= FAST_STEP_S && hz > FAST_DRIVE_HZ {
            let file = file.to_string();
            return Some(ReadDoubt::TimeTooFast { file, step_s, drive_hz: hz });
        }
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
        let channels = [("drive", Some(drive)), ("displacement", displacement)];
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
    Some(ReadDoubt::ImplausibleTime { file: file.to_string(), step_s, why })
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
