//! Measurement files (shared/docs/contracts.md): one header line, then one row per sample;
//! columns recognised by name, order free, extra columns ignored. Every problem is reported with
//! the file, line and column, and nothing is dropped silently.

use std::fmt::Write as _;
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

    /// Reads and validates a measurement CSV.
    pub fn read(path: &Path) -> Result<Self> {
        let file = path.display().to_string();
        let text = std::fs::read(path).with_context(|| format!("{file}: cannot read"))?;
        Self::parse(&file, &text)
    }

    /// Parses CSV text; `file` names it in messages.
    pub fn parse(file: &str, text: &[u8]) -> Result<Self> {
        let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(false).from_reader(text);
        let headers =
            rdr.headers().with_context(|| format!("{file}:1: cannot read the header line"))?.clone();
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
            bail!(
                "{file}:1: no `time_s` column (header has: {}); recognised columns are {}",
                found.join(", "),
                COLUMNS.join(", ")
            );
        }
        if index[1].is_none() && index[2].is_none() {
            bail!("{file}:1: needs a drive column: `current_A` or `command_V`");
        }
        let mut cols: [Vec<f64>; COLUMNS.len()] = Default::default();
        for (row, rec) in rdr.records().enumerate() {
            let line = row + 2;
            let rec = rec.map_err(|e| match e.kind() {
                csv::ErrorKind::UnequalLengths { expected_len, len, .. } => anyhow::anyhow!(
                    "{file}:{line}: {len} fields, but the header has {expected_len} (a missing or extra comma?)"
                ),
                _ => anyhow::anyhow!("{file}:{line}: {e}"),
            })?;
            for (k, idx) in index.iter().enumerate() {
                let Some(c) = *idx else { continue };
                let raw = rec.get(c).unwrap_or("").trim();
                let v: f64 = raw.parse().map_err(|_| {
                    if raw.is_empty() {
                        anyhow::anyhow!("{file}:{line}:{}: column `{}` is empty", c + 1, COLUMNS[k])
                    } else {
                        anyhow::anyhow!(
                            "{file}:{line}:{}: column `{}`: `{raw}` is not a number",
                            c + 1,
                            COLUMNS[k]
                        )
                    }
                })?;
                if !v.is_finite() {
                    bail!("{file}:{line}:{}: column `{}`: `{raw}` is not a finite number", c + 1, COLUMNS[k]);
                }
                cols[k].push(v);
            }
        }
        let n = cols[0].len();
        if n < 3 {
            bail!("{file}: {n} data rows; a recording needs at least 3");
        }
        check_time(file, &cols[0], index[0].unwrap_or(0) + 1)?;
        let take =
            |k: usize, cols: &mut [Vec<f64>; COLUMNS.len()]| index[k].map(|_| std::mem::take(&mut cols[k]));
        Ok(Recording {
            name: file.to_string(),
            command_v: take(1, &mut cols),
            current_a: take(2, &mut cols),
            displacement_um: take(3, &mut cols),
            force_n: take(4, &mut cols),
            temperature_c: take(5, &mut cols),
            time_s: std::mem::take(&mut cols[0]),
        })
    }

    /// The CSV text (only the channels present).
    pub fn to_csv(&self) -> String {
        let present: Vec<&str> = COLUMNS.iter().copied().filter(|c| self.column(c).is_some()).collect();
        let mut out = present.join(",");
        out.push('\n');
        for k in 0..self.len() {
            for (i, c) in present.iter().enumerate() {
                let v = self.column(c).map(|col| col[k]).unwrap_or(f64::NAN);
                if i > 0 {
                    out.push(',');
                }
                let _ = match *c {
                    "time_s" => write!(out, "{v:.7}"),
                    _ => write!(out, "{v:.6}"),
                };
            }
            out.push('\n');
        }
        out
    }

    /// Writes the CSV atomically (temporary file in the same directory, then rename).
    pub fn write(&self, path: &Path) -> Result<()> {
        write_atomic(path, self.to_csv().as_bytes())
    }
}

/// Writes `bytes` to `path` through a temporary file and a rename, so that readers never see a
/// half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("cannot create a file in {}", dir.display()))?;
    tmp.write_all(bytes)?;
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
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.is_empty() {
        return 0.0;
    }
    steps.sort_by(f64::total_cmp);
    steps[steps.len() / 2]
}

/// Strictly increasing and uniform within [`MAX_JITTER`] of the median step.
fn check_time(file: &str, t: &[f64], col: usize) -> Result<()> {
    for (k, w) in t.windows(2).enumerate() {
        if w[1] <= w[0] {
            bail!(
                "{file}:{}:{col}: time_s does not increase ({} s after {} s on the line before)",
                k + 3,
                w[1],
                w[0]
            );
        }
    }
    let dt = median_step(t);
    for (k, w) in t.windows(2).enumerate() {
        let step = w[1] - w[0];
        if (step - dt).abs() > MAX_JITTER * dt {
            bail!(
                "{file}:{}:{col}: time step {step:.3e} s differs from the median step {dt:.3e} s by more \
                 than {:.0} % (missing samples or jittered time; resample the recording uniformly)",
                k + 3,
                MAX_JITTER * 100.0
            );
        }
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
