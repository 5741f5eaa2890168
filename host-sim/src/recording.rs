//! Measurement files (docs/formats.md): one header line, then one row per sample;
//! columns recognised by name, order free, extra columns ignored. Every problem is reported with
//! the file, line and column, and nothing is dropped silently.

use std::path::Path;

use anyhow::{Context, Result};

use crate::error::Located;
use crate::files::{echo, output_dir, partial_file, persist, Input};
use crate::located;

/// The recognised columns, in the order the workbench writes them.
pub const COLUMNS: [&str; 6] =
    ["time_s", "command_V", "current_A", "displacement_um", "force_N", "temperature_C"];

/// Largest allowed deviation of one time step from the median step (fraction of the median).
const MAX_JITTER: f64 = 0.01;

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

    fn column(&self, name: &str) -> Option<&Vec<f64>> {
        match name {
            "time_s" => Some(&self.time_s),
            "command_V" => self.command_v.as_ref(),
            "current_A" => self.current_a.as_ref(),
            "displacement_um" => self.displacement_um.as_ref(),
            "force_N" => self.force_n.as_ref(),
            "temperature_C" => self.temperature_c.as_ref(),
            _ => None,
        }
    }

    /// Reads and validates a measurement CSV, all of it (`-` is standard input).
    pub fn read(path: &Path) -> Result<Self> {
        Ok(Self::read_input(Input::open(path)?, usize::MAX)?.0)
    }

    /// Reads an opened input as a stream (memory bounded by `max_samples`, not by the file):
    /// every row is validated, the first `max_samples` are kept. Returns the recording and the
    /// number of data rows in the file.
    pub fn read_input(input: Input, max_samples: usize) -> Result<(Self, u64)> {
        let name = input.name.clone();
        Self::from_reader(&name, input.into_reader(), max_samples)
    }

    /// Parses CSV text; `file` names it in messages.
    pub fn parse(file: &str, text: &[u8]) -> Result<Self> {
        Ok(Self::from_reader(file, text, usize::MAX)?.0)
    }

    /// The streaming reader behind [`Recording::read_window`] and [`Recording::parse`].
    pub fn from_reader<R: std::io::Read>(file: &str, input: R, max_samples: usize) -> Result<(Self, u64)> {
        let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(false).from_reader(input);
        let headers = rdr.headers().map_err(|e| csv_error(file, e))?.clone();
        if headers.iter().all(|h| h.trim().is_empty()) {
            located!(file, Some(1), None; "empty file (no header line); expected a header such as `time_s,current_A,displacement_um`");
        }
        // Map recognised columns to their index; refuse duplicates.
        let mut index: [Option<usize>; COLUMNS.len()] = [None; COLUMNS.len()];
        for (col, h) in headers.iter().enumerate() {
            let h = h.trim();
            if let Some(k) = COLUMNS.iter().position(|c| *c == h) {
                if let Some(first) = index[k] {
                    located!(file, Some(1), Some(col as u64 + 1); "column `{}` appears twice (columns {} and {})", echo(h), first + 1, col + 1);
                }
                index[k] = Some(col);
            }
        }
        if index[0].is_none() {
            let found: Vec<&str> = headers.iter().collect();
            let joined = found.join(", ");
            let hint = [(';', "`;`"), ('\t', "tabs")]
                .iter()
                .find(|(c, _)| joined.contains(*c) && joined.contains("time_s"))
                .map(|(_, name)| format!(" — the file seems to separate columns with {name}; measurement files are comma-separated"))
                .unwrap_or_default();
            located!(file, Some(1), None;
                "no `time_s` column (header has: {}); recognised columns are {}{hint}",
                echo(&joined),
                COLUMNS.join(", ")
            );
        }
        if index[1].is_none() && index[2].is_none() {
            located!(file, Some(1), None; "needs a drive column: `current_A` or `command_V`");
        }
        let time_col = index[0].unwrap_or(0) + 1;
        let mut cols: [Vec<f64>; COLUMNS.len()] = Default::default();
        let mut time = TimeCheck::default();
        let mut rows: u64 = 0;
        let mut rec = csv::StringRecord::new();
        let mut values = [0.0; COLUMNS.len()];
        while rdr.read_record(&mut rec).map_err(|e| csv_error(file, e))? {
            let line = rec.position().map(|p| p.line()).unwrap_or(rows + 2);
            for (k, idx) in index.iter().enumerate() {
                let Some(c) = *idx else { continue };
                let raw = rec.get(c).unwrap_or("").trim();
                values[k] = cell(file, line, c + 1, k, raw)?;
            }
            time.push(file, line, time_col, values[0])?;
            if (rows as usize) < max_samples {
                for (k, idx) in index.iter().enumerate() {
                    if idx.is_some() {
                        cols[k].push(values[k]);
                    }
                }
            }
            rows += 1;
        }
        if rows < 3 {
            located!(file;
                "{rows} data row{}; a recording needs at least 3",
                if rows == 1 { "" } else { "s" }
            );
        }
        time.finish(file, time_col)?;
        let take =
            |k: usize, cols: &mut [Vec<f64>; COLUMNS.len()]| index[k].map(|_| std::mem::take(&mut cols[k]));
        let r = Recording {
            name: file.to_string(),
            command_v: take(1, &mut cols),
            current_a: take(2, &mut cols),
            displacement_um: take(3, &mut cols),
            force_n: take(4, &mut cols),
            temperature_c: take(5, &mut cols),
            time_s: std::mem::take(&mut cols[0]),
        };
        Ok((r, rows))
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

    /// Writes the CSV atomically (temporary file in the same directory, then rename), streamed
    /// through a buffer rather than built in memory.
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut buf = std::io::BufWriter::with_capacity(1 << 16, partial_file(output_dir(path))?);
        self.write_csv(&mut buf).with_context(|| format!("writing {}", crate::files::display(path)))?;
        let tmp = buf
            .into_inner()
            .map_err(|e| anyhow::anyhow!("writing {}: {}", crate::files::display(path), e.error()))?;
        persist(tmp, path)
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
    [(1e10, "s"), (1e4, "V"), (1e3, "A"), (1e6, "µm"), (1e7, "N"), (1e4, "°C")];

/// One cell: a finite number within the column's plausible range.
fn cell(file: &str, line: u64, col: usize, k: usize, raw: &str) -> Result<f64> {
    let name = COLUMNS[k];
    let at = (Some(line), Some(col as u64));
    if raw.is_empty() {
        located!(file, at.0, at.1; "column `{name}` is empty");
    }
    let Ok(v) = raw.parse::<f64>() else {
        located!(file, at.0, at.1; "column `{name}`: `{}` is not a number", echo(raw));
    };
    if !v.is_finite() {
        located!(file, at.0, at.1; "column `{name}`: `{}` is not a finite number", echo(raw));
    }
    if let Err(why) = plausible(k, v) {
        located!(file, at.0, at.1; "column `{name}`: {} {why}", echo(raw));
    }
    Ok(v)
}

/// Whether `v` is a plausible value of column `k` (of [`COLUMNS`]); the error says why not.
pub fn plausible(k: usize, v: f64) -> std::result::Result<(), String> {
    let (limit, unit) = PLAUSIBLE[k];
    if v.is_finite() && v.abs() <= limit {
        Ok(())
    } else {
        Err(format!("is beyond ±{limit:e} {unit}, not a plausible value (wrong unit or a corrupt export?)"))
    }
}

/// A csv error as `file:line: what`.
fn csv_error(file: &str, e: csv::Error) -> anyhow::Error {
    let line = e.position().map(|p| p.line()).unwrap_or(1);
    match e.into_kind() {
        csv::ErrorKind::UnequalLengths { expected_len, len, .. } => Located::at(
            file,
            line,
            None,
            format!("{len} fields, but the header has {expected_len} (a missing or extra comma?)"),
        )
        .into(),
        csv::ErrorKind::Utf8 { err, .. } => Located::at(
            file,
            line,
            Some(err.field() as u64 + 1),
            "not UTF-8 text (a binary file, or a text encoding other than UTF-8?)",
        )
        .into(),
        csv::ErrorKind::Io(io) => crate::files::read_error(file, io),
        other => Located::at(file, line, None, format!("{:?}", other)).into(),
    }
}

/// Number of time steps whose median sets the reference step for the jitter check.
const REFERENCE_STEPS: usize = 1024;

/// Streaming time-axis check: strictly increasing, and every step within [`MAX_JITTER`] of the
/// median of the first [`REFERENCE_STEPS`] steps.
#[derive(Default)]
struct TimeCheck {
    last: Option<f64>,
    /// Steps (line, step) held until the reference step is known.
    pending: Vec<(u64, f64)>,
    reference: Option<f64>,
}

impl TimeCheck {
    fn push(&mut self, file: &str, line: u64, col: usize, t: f64) -> Result<()> {
        let Some(last) = self.last.replace(t) else { return Ok(()) };
        if t <= last {
            located!(file, Some(line), Some(col as u64); "time_s does not increase ({t} s after {last} s on the line before)");
        }
        let step = t - last;
        match self.reference {
            Some(dt) => jitter(file, line, col, step, dt),
            None => {
                self.pending.push((line, step));
                if self.pending.len() == REFERENCE_STEPS {
                    self.settle(file, col)?;
                }
                Ok(())
            }
        }
    }

    fn settle(&mut self, file: &str, col: usize) -> Result<()> {
        let steps: Vec<f64> = self.pending.iter().map(|p| p.1).collect();
        let dt = median(steps);
        let (lo, hi) = (model_core::DT_MIN_S as f64, model_core::DT_MAX_S as f64);
        if !(lo..=hi).contains(&dt) {
            located!(file, self.pending.first().map(|p| p.0), Some(col as u64);
                "sample period {dt:.3e} s is outside [{lo:e}, {hi:e}] s (is time_s in seconds?)");
        }
        self.reference = Some(dt);
        for (line, step) in std::mem::take(&mut self.pending) {
            jitter(file, line, col, step, dt)?;
        }
        Ok(())
    }

    fn finish(mut self, file: &str, col: usize) -> Result<()> {
        if self.reference.is_none() {
            self.settle(file, col)?;
        }
        Ok(())
    }
}

fn jitter(file: &str, line: u64, col: usize, step: f64, dt: f64) -> Result<()> {
    if (step - dt).abs() > MAX_JITTER * dt {
        located!(file, Some(line), Some(col as u64);
            "time step {step:.3e} s differs from the median step {dt:.3e} s by more \
             than {:.0} % (missing samples or jittered time; resample the recording uniformly)",
            MAX_JITTER * 100.0
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        format!("{:#}", Recording::parse("rig.csv", text.as_bytes()).unwrap_err())
    }

    #[test]
    fn reads_columns_by_name_in_any_order() {
        let r = Recording::parse(
            "rig.csv",
            b"displacement_um,extra,time_s,current_A\n1.0,x,0.0,0.1\n2.0,y,0.001,0.2\n3.5,z,0.002,0.3\n",
        )
        .unwrap();
        assert_eq!(r.time_s, vec![0.0, 0.001, 0.002]);
        assert_eq!(r.displacement_um.unwrap(), vec![1.0, 2.0, 3.5]);
        assert_eq!(r.current_a.unwrap(), vec![0.1, 0.2, 0.3]);
        assert!(r.command_v.is_none());
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = err("time_s,current_A\n0,1\n0.001,abc\n0.002,1\n");
        assert!(e.contains("rig.csv:3:2") && e.contains("`abc` is not a number"), "{e}");
        let e = err("time_s,current_A\n0,1\n0.001,NaN\n0.002,1\n");
        assert!(e.contains("rig.csv:3:2") && e.contains("not a finite"), "{e}");
        let e = err("time_s,current_A\n0,1\n0.001\n0.002,1\n");
        assert!(e.contains("rig.csv:3") && e.contains("1 fields"), "{e}");
        let e = err("time_s,current_A\n0,1\n0.002,1\n0.001,1\n");
        assert!(e.contains("rig.csv:4:1") && e.contains("does not increase"), "{e}");
        let e = err("time_s,current_A\n0,1\n0.001,1\n0.0021,1\n0.003,1\n");
        assert!(e.contains("rig.csv:4:1") && e.contains("median step"), "{e}");
        let e = err("t,current_A\n0,1\n");
        assert!(e.contains("no `time_s` column"), "{e}");
        let e = err("time_s,displacement_um\n0,1\n0.001,1\n0.002,1\n");
        assert!(e.contains("drive column"), "{e}");
        let e = err("time_s,current_A,current_A\n0,1,1\n");
        assert!(e.contains("appears twice"), "{e}");
    }

    #[test]
    fn spreadsheet_exports_with_a_byte_order_mark_and_crlf_are_read() {
        let r = Recording::parse("rig.csv", b"\xEF\xBB\xBFtime_s,current_A\r\n0,1\r\n0.001,2\r\n0.002,3\r\n")
            .unwrap();
        assert_eq!(r.current_a.unwrap(), vec![1.0, 2.0, 3.0]);
    }

    #[test]
    fn round_trips_through_csv() {
        let mut r = Recording::with_time("a", 5, 1e-4);
        r.current_a = Some(vec![0.0, 0.5, 1.0, 0.5, 0.0]);
        r.displacement_um = Some(vec![1.0, 2.0, 3.0, 2.0, 1.0]);
        let back = Recording::parse("a", r.to_csv().as_bytes()).unwrap();
        assert_eq!(back.current_a, r.current_a);
        assert_eq!(back.displacement_um, r.displacement_um);
        assert!((back.dt_s() - 1e-4).abs() < 1e-12);
    }
}
