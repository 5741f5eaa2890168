//! Measurement files (shared/docs/contracts.md): one header line, then one row per sample;
//! columns recognised by name, order free, extra columns ignored. Every problem is reported with
//! the file, line and column, and nothing is dropped silently.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

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

    /// Reads and validates a measurement CSV, all of it.
    pub fn read(path: &Path) -> Result<Self> {
        Ok(Self::read_window(path, usize::MAX)?.0)
    }

    /// Reads a measurement CSV as a stream (memory bounded by `max_samples`, not by the file):
    /// every row is validated, the first `max_samples` are kept. Returns the recording and the
    /// number of data rows in the file.
    pub fn read_window(path: &Path, max_samples: usize) -> Result<(Self, u64)> {
        let file = path.display().to_string();
        let f = std::fs::File::open(path).with_context(|| format!("{file}: cannot read"))?;
        Self::from_reader(&file, std::io::BufReader::with_capacity(1 << 16, f), max_samples)
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
            bail!("{file}:1: empty file (no header line); expected a header such as `time_s,current_A,displacement_um`");
        }
        // Map recognised columns to their index; refuse duplicates.
        let mut index: [Option<usize>; COLUMNS.len()] = [None; COLUMNS.len()];
        for (col, h) in headers.iter().enumerate() {
            let h = h.trim();
            if let Some(k) = COLUMNS.iter().position(|c| *c == h) {
                if let Some(first) = index[k] {
                    bail!("{file}:1: column `{h}` appears twice (columns {} and {})", first + 1, col + 1);
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
            bail!(
                "{file}:1: no `time_s` column (header has: {joined}); recognised columns are {}{hint}",
                COLUMNS.join(", ")
            );
        }
        if index[1].is_none() && index[2].is_none() {
            bail!("{file}:1: needs a drive column: `current_A` or `command_V`");
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
            bail!(
                "{file}: {rows} data row{}; a recording needs at least 3",
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

    /// Writes the CSV (only the channels present) to `out`.
    pub fn write_csv(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        let present: Vec<&str> = COLUMNS.iter().copied().filter(|c| self.column(c).is_some()).collect();
        writeln!(out, "{}", present.join(","))?;
        let cols: Vec<&Vec<f64>> = present.iter().filter_map(|c| self.column(c)).collect();
        for k in 0..self.len() {
            for (i, col) in cols.iter().enumerate() {
                let v = col[k];
                match i {
                    0 => write!(out, "{v:.7}")?,
                    _ => write!(out, ",{v:.6}")?,
                }
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
        self.write_csv(&mut buf).with_context(|| format!("writing {}", path.display()))?;
        let tmp =
            buf.into_inner().map_err(|e| anyhow::anyhow!("writing {}: {}", path.display(), e.error()))?;
        persist(tmp, path)
    }
}

/// Writes `bytes` to `path` through a temporary file and a rename, so that readers never see a
/// half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = output_dir(path);
    let mut tmp = partial_file(dir)?;
    tmp.write_all(bytes).with_context(|| format!("writing {}", path.display()))?;
    persist(tmp, path)
}

/// The folder `path` is written into (`.` for a bare file name).
pub fn output_dir(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Reads a text file (parameter or loop file); a non-UTF-8 file is an error naming its line.
/// Returns the file's display name and its text.
pub fn read_text(path: &Path) -> Result<(String, String)> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).with_context(|| format!("{name}: cannot read"))?;
    match String::from_utf8(bytes) {
        Ok(text) => Ok((name, text)),
        Err(e) => {
            let bytes = e.as_bytes();
            let line = bytes[..e.utf8_error().valid_up_to()].iter().filter(|b| **b == b'\n').count() + 1;
            bail!("{name}:{line}: not UTF-8 text (a binary file, or a text encoding other than UTF-8?)")
        }
    }
}

/// Checks before any work that `path` can be written (its folder exists), so a long fit does
/// not end in "cannot create a file".
pub fn check_output(path: &Path) -> Result<()> {
    let dir = output_dir(path);
    if !dir.is_dir() {
        bail!("cannot write {}: the folder {} does not exist", path.display(), dir.display());
    }
    if path.is_dir() {
        bail!("cannot write {}: it is a folder", path.display());
    }
    Ok(())
}

/// A temporary file in `dir` for an output being written (`.gma-*.partial`: a run killed
/// mid-write leaves one of these, never a truncated result under the final name).
pub fn partial_file(dir: &Path) -> Result<tempfile::NamedTempFile> {
    tempfile::Builder::new()
        .prefix(".gma-")
        .suffix(".partial")
        .tempfile_in(dir)
        .with_context(|| format!("cannot create a file in {}", dir.display()))
}

/// Moves a finished temporary file into place (synced, ordinary permissions, atomic rename).
pub fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    tmp.as_file().sync_all()?;
    // Temporary files are private (0600); results are ordinary files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
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
    if raw.is_empty() {
        bail!("{file}:{line}:{col}: column `{name}` is empty");
    }
    let Ok(v) = raw.parse::<f64>() else {
        bail!("{file}:{line}:{col}: column `{name}`: `{raw}` is not a number");
    };
    if !v.is_finite() {
        bail!("{file}:{line}:{col}: column `{name}`: `{raw}` is not a finite number");
    }
    let (limit, unit) = PLAUSIBLE[k];
    if v.abs() > limit {
        bail!(
            "{file}:{line}:{col}: column `{name}`: {raw} is beyond ±{limit:e} {unit}, not a plausible value \
             (wrong unit or a corrupt export?)"
        );
    }
    Ok(v)
}

/// A csv error as `file:line: what`.
fn csv_error(file: &str, e: csv::Error) -> anyhow::Error {
    let line = e.position().map(|p| p.line()).unwrap_or(1);
    match e.kind() {
        csv::ErrorKind::UnequalLengths { expected_len, len, .. } => anyhow::anyhow!(
            "{file}:{line}: {len} fields, but the header has {expected_len} (a missing or extra comma?)"
        ),
        csv::ErrorKind::Utf8 { err, .. } => anyhow::anyhow!(
            "{file}:{line}:{}: not UTF-8 text (a binary file, or a text encoding other than UTF-8?)",
            err.field() + 1
        ),
        csv::ErrorKind::Io(io) => anyhow::anyhow!("{file}: cannot read: {io}"),
        _ => anyhow::anyhow!("{file}:{line}: {e}"),
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
            bail!("{file}:{line}:{col}: time_s does not increase ({t} s after {last} s on the line before)");
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
        bail!(
            "{file}:{line}:{col}: time step {step:.3e} s differs from the median step {dt:.3e} s by more \
             than {:.0} % (missing samples or jittered time; resample the recording uniformly)",
            MAX_JITTER * 100.0
        );
    }
    Ok(())
}

/// A path list as the CLI prints it.
pub fn names(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
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
