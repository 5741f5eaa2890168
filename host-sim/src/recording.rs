//! Measurement files (docs/formats.md): one header line, then one row per sample;
//! columns recognised by name, order free, extra columns ignored. Every problem is reported with
//! the file, line and column, and nothing is dropped silently.

use std::path::Path;

use anyhow::{Context, Result};

use crate::error::Located;
use crate::files::{echo, OutputWriter};
use crate::located;
use crate::read_doubts::{time_doubt, ReadDoubt};

pub use crate::columns::COLUMNS;

mod reader;

/// What [`Recording::from_reader_with`] read.
#[derive(Debug, Clone)]
pub struct ReadOutcome {
    /// The recording (trimmed, and resampled when asked).
    pub recording: Recording,
    /// Data rows in the file at or after the `--trim-start` point (all rows without it).
    pub rows: u64,
    /// Of those, the rows kept (at most `max_samples`), before any resampling.
    pub kept: usize,
    /// What is to be said about how it was read (columns not used, the time axis).
    pub doubts: Vec<ReadDoubt>,
}

/// One recording: uniformly sampled channels in SI units (displacement in µm, as in the file).
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Where it came from (for messages and reports).
    pub name: String,
    /// Time [s], strictly increasing, uniform within 1 %.
    pub time_s: Vec<f64>,
    /// Amplifier command [V].
    pub command_v: Option<Vec<f64>>,
    /// Coil current [A].
    pub current_a: Option<Vec<f64>>,
    /// Output displacement [µm], arbitrary offset.
    pub displacement_um: Option<Vec<f64>>,
    /// Output force [N].
    pub force_n: Option<Vec<f64>>,
    /// Coil or rod temperature [°C].
    pub temperature_c: Option<Vec<f64>>,
    /// Mean flux density of the rod [T] from a search coil around it (arbitrary offset: an
    /// integrator's zero).
    pub flux_density_t: Option<Vec<f64>>,
    /// The columns as the source names them (a file's header, the arrays' names), for messages
    /// about a column it lacks; empty for a recording made in memory.
    pub header: Vec<String>,
}

impl Recording {
    /// An empty recording with only a time axis of `n` samples at `dt_s`.
    pub fn with_time(name: impl Into<String>, n: usize, dt_s: f64) -> Self {
        Self {
            name: name.into(),
            time_s: (0..n).map(|k| k as f64 * dt_s).collect(),
            command_v: None,
            current_a: None,
            displacement_um: None,
            force_n: None,
            temperature_c: None,
            flux_density_t: None,
            header: Vec::new(),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// The first `n` samples (all of them if shorter).
    pub fn head(&self, n: usize) -> Recording {
        let n = n.min(self.len());
        let cut = |v: &Option<Vec<f64>>| v.as_ref().map(|v| v[..n].to_vec());
        Recording {
            name: self.name.clone(),
            time_s: self.time_s[..n].to_vec(),
            command_v: cut(&self.command_v),
            current_a: cut(&self.current_a),
            displacement_um: cut(&self.displacement_um),
            force_n: cut(&self.force_n),
            temperature_c: cut(&self.temperature_c),
            flux_density_t: cut(&self.flux_density_t),
            header: self.header.clone(),
        }
    }

    /// Sample period [s] (median step).
    pub fn dt_s(&self) -> f64 {
        median_step(&self.time_s)
    }

    /// Duration [s].
    pub fn duration_s(&self) -> f64 {
        self.time_s.last().copied().unwrap_or(0.0) - self.time_s.first().copied().unwrap_or(0.0)
    }

    /// A channel by its canonical name (`time_s`, `current_A`, …), when the recording has it.
    pub fn column(&self, name: &str) -> Option<&Vec<f64>> {
        match name {
            "time_s" => Some(&self.time_s),
            "command_V" => self.command_v.as_ref(),
            "current_A" => self.current_a.as_ref(),
            "displacement_um" => self.displacement_um.as_ref(),
            "force_N" => self.force_n.as_ref(),
            "temperature_C" => self.temperature_c.as_ref(),
            "flux_density_T" => self.flux_density_t.as_ref(),
            _ => None,
        }
    }

    /// Why the recording cannot be compared with a model: it has no `displacement_um`. Names the
    /// columns it has and, for one that looks like a displacement under another name or unit,
    /// the `--column` that reads it.
    pub fn no_displacement_error(&self) -> anyhow::Error {
        let what = "nothing to compare the model with";
        if self.header.is_empty() {
            return crate::error::InRecording::error(
                &self.name,
                format!("no `displacement_um` column: {what}"),
            );
        }
        let units = crate::columns::UNITS[3];
        let candidate = self.header.iter().find(|h| looks_like_displacement(h));
        // The unit a name ends in: `displacement_mm`, `x(mm)`, `x [mm]`.
        let unit = candidate.and_then(|h| {
            let tail = h.rsplit(['_', '(', '[', ' ']).next()?.trim_end_matches([')', ']']);
            units.iter().find(|u| u.name == tail).map(|u| u.name)
        });
        let header = candidate.map_or("HEADER".to_string(), |h| echo(h));
        let mut hint = match candidate {
            Some(_) => format!("if `{header}` is the displacement, read it with "),
            None => "a displacement column of another name or unit is read with ".to_string(),
        };
        let arg = format!("displacement_um={header}:{}", unit.unwrap_or("UNIT"));
        // Quoted when a shell would split or expand it (`x [mm]`), so it pastes as is.
        let arg =
            if arg.chars().any(|c| !(c.is_alphanumeric() || "_=:.-/".contains(c))) && !arg.contains('\'') {
                format!("'{arg}'")
            } else {
                arg
            };
        hint.push_str(&format!("`--column {arg}`"));
        if unit.is_none() {
            let names: Vec<&str> = units.iter().map(|u| u.name).collect();
            hint.push_str(&format!(" (UNIT: {})", names.join(", ")));
        }
        let message = format!(
            "no `displacement_um` column (header has: {}): {what}; {hint}",
            header_list(self.header.iter().map(String::as_str))
        );
        Located::at(&self.name, 1, None, message).into()
    }

    /// The doubt about this recording's time axis ([`time_doubt`]).
    pub(crate) fn time_doubt(&self) -> Option<ReadDoubt> {
        let drive = self.current_a.as_deref().or(self.command_v.as_deref());
        time_doubt(&self.name, self.dt_s(), self.duration_s(), drive, self.displacement_um.as_deref())
    }

    /// The recording linearly interpolated onto a uniform grid from its first sample to its last
    /// (at most `max_samples` points), at the step nearest its median step that lands on both:
    /// the median's whole number of steps over the span, rounded (floored, a median a little
    /// above the mean step of jittered stamps dropped the last sample); every channel alike.
    pub fn resampled_linear(&self, max_samples: usize) -> Result<Recording> {
        let median = self.dt_s();
        let (t0, t_end) = (self.time_s[0], self.time_s[self.len() - 1]);
        let steps = ((t_end - t0) / median).round().max(1.0);
        let dt = (t_end - t0) / steps;
        let n = (steps as usize + 1).min(max_samples);
        if n < 3 {
            located!(self.name; "resampled at the median step {dt:.3e} s, the recording has {n} samples; at least 3 are needed");
        }
        let grid: Vec<f64> = (0..n).map(|k| t0 + k as f64 * dt).collect();
        // For every grid point: the segment [j, j+1] of the original time axis it falls in.
        let mut at = Vec::with_capacity(n);
        let mut j = 0;
        for &t in &grid {
            while j + 2 < self.len() && self.time_s[j + 1] <= t {
                j += 1;
            }
            let (a, b) = (self.time_s[j], self.time_s[j + 1]);
            at.push((j, ((t - a) / (b - a)).clamp(0.0, 1.0)));
        }
        let interp = |v: &Option<Vec<f64>>| {
            v.as_ref().map(|v| at.iter().map(|&(j, w)| v[j] + w * (v[j + 1] - v[j])).collect::<Vec<f64>>())
        };
        Ok(Recording {
            name: self.name.clone(),
            time_s: grid,
            command_v: interp(&self.command_v),
            current_a: interp(&self.current_a),
            displacement_um: interp(&self.displacement_um),
            force_n: interp(&self.force_n),
            temperature_c: interp(&self.temperature_c),
            flux_density_t: interp(&self.flux_density_t),
            header: self.header.clone(),
        })
    }

    /// Checks every value against the reader's plausible ranges (what this workbench writes, it
    /// must read back).
    pub fn check_plausible(&self) -> Result<()> {
        for (k, name) in COLUMNS.iter().enumerate() {
            let Some(col) = self.column(name) else { continue };
            if let Some((i, v)) = col.iter().enumerate().find(|(_, v)| plausible(k, **v).is_err()) {
                anyhow::bail!(
                    "{}: sample {i}: `{name}` = {v:e} {}",
                    self.name,
                    plausible(k, *v).unwrap_err()
                );
            }
        }
        Ok(())
    }

    /// Writes the CSV (only the channels present) to `out`.
    pub fn write_csv(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let present: Vec<&str> = COLUMNS.iter().copied().filter(|c| self.column(c).is_some()).collect();
        writeln!(out, "{}", present.join(","))?;
        let cols: Vec<&Vec<f64>> = present.iter().filter_map(|c| self.column(c)).collect();
        let decimals = time_decimals(self.dt_s());
        for k in 0..self.len() {
            write!(out, "{:.*}", decimals, self.time_s[k])?;
            // Channels to single precision, shortest form that reads back to the same f32 (`{:?}`
            // switches to an exponent for very small or large values).
            for col in &cols[1..] {
                write!(out, ",{:?}", col[k] as f32)?;
            }
            writeln!(out)?;
        }
        Ok(())
    }

    /// The CSV text (only the channels present).
    pub fn to_csv(&self) -> String {
        let mut out = Vec::new();
        self.write_csv(&mut out).expect("writing to memory");
        String::from_utf8(out).expect("ASCII")
    }

    /// Writes the CSV atomically (temporary file in the same directory, then rename; `-`:
    /// standard output), streamed through a buffer rather than built in memory.
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut buf = std::io::BufWriter::with_capacity(1 << 16, OutputWriter::create(path)?);
        self.write_csv(&mut buf).with_context(|| format!("writing {}", crate::files::display(path)))?;
        let out = buf
            .into_inner()
            .map_err(|e| anyhow::anyhow!("writing {}: {}", crate::files::display(path), e.error()))?;
        out.finish(path)
    }
}

/// Decimals that resolve a time step `dt` to 0.1 % (so a file we write passes our own jitter
/// check at any sample rate): 7 at 10 kHz.
pub fn time_decimals(dt: f64) -> usize {
    if dt.is_finite() && dt > 0.0 {
        ((-dt.log10()).ceil() + 3.0).clamp(1.0, 15.0) as usize
    } else {
        7
    }
}

fn median_step(t: &[f64]) -> f64 {
    median(t.windows(2).map(|w| w[1] - w[0]).collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Largest plausible magnitude per column (same order as [`COLUMNS`]); a value beyond is a unit
/// or export mistake, not a measurement. Time allows Unix-epoch seconds.
const PLAUSIBLE: [(f64, &str); COLUMNS.len()] =
    [(1e10, "s"), (1e4, "V"), (1e3, "A"), (1e6, "µm"), (1e7, "N"), (1e4, "°C"), (1e2, "T")];

/// Whether `v` is a plausible value of column `k` (of [`COLUMNS`]); the error says why not.
pub fn plausible(k: usize, v: f64) -> std::result::Result<(), String> {
    let (limit, unit) = PLAUSIBLE[k];
    if v.is_finite() && v.abs() <= limit {
        Ok(())
    } else {
        Err(format!("is beyond ±{limit:e} {unit}, not a plausible value (wrong unit or a corrupt export?)"))
    }
}

/// The header's names as a message lists them: each quoted as a cell, at most 24.
fn header_list<'a>(headers: impl IntoIterator<Item = &'a str>) -> String {
    const SHOWN: usize = 24;
    let (mut names, mut more) = (Vec::new(), 0);
    for h in headers {
        if names.len() < SHOWN {
            names.push(echo(h.trim()));
        } else {
            more += 1;
        }
    }
    if more > 0 {
        names.push(format!("… ({more} more)"));
    }
    names.join(", ")
}

/// Whether a column's name suggests a displacement under another name or unit
/// (`displacement_mm`, `disp`, `x_um`, `x [mm]`, `x`).
fn looks_like_displacement(header: &str) -> bool {
    let h = header.trim().to_ascii_lowercase();
    let stem = h.split(['_', '(', '[', ' ']).next().unwrap_or("");
    stem.starts_with("disp") || stem == "x"
}
