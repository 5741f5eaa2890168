//! Reading a measurement CSV into a [`Recording`]: the separator and decimal mark, the columns
//! by name (or as `--column` maps them), every cell checked, the time axis checked as it streams.

use std::path::Path;

use anyhow::Result;

use super::{header_list, median, plausible, ReadOutcome, Recording, COLUMNS};
use crate::columns::{ColumnMap, ReadOptions, Resample, MAX_GAP_STEPS};
use crate::error::Located;
use crate::files::{echo, Input};
use crate::located;
use crate::read_doubts::ReadDoubt;

/// Largest allowed deviation of one time step from the median step (fraction of the median).
const MAX_JITTER: f64 = 0.01;

/// " — `Time_S` differs from `time_s` only in case…" when a header is `name` but for its case.
fn case_hint(headers: &csv::StringRecord, name: &str) -> Option<String> {
    headers.iter().map(str::trim).find(|h| *h != name && h.eq_ignore_ascii_case(name)).map(|h| {
        format!(" — `{h}` differs from `{name}` only in case: column names are case-sensitive (rename it, or map it with `--column {name}={h}`)")
    })
}

impl Recording {
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

    /// [`Recording::read_input`] with column mapping, trimming and resampling
    /// ([`ReadOptions`]).
    pub fn read_input_with(input: Input, max_samples: usize, opts: &ReadOptions) -> Result<ReadOutcome> {
        let name = input.name.clone();
        Self::from_reader_with(&name, input.into_reader(), max_samples, opts)
    }

    /// Parses CSV text; `file` names it in messages.
    pub fn parse(file: &str, text: &[u8]) -> Result<Self> {
        Ok(Self::from_reader(file, text, usize::MAX)?.0)
    }

    /// The streaming reader behind [`Recording::read_input`] and [`Recording::parse`]: the file
    /// as it is, no options. Returns the recording and the number of data rows in the file.
    pub fn from_reader<R: std::io::Read>(file: &str, input: R, max_samples: usize) -> Result<(Self, u64)> {
        let out = Self::from_reader_with(file, input, max_samples, &ReadOptions::default())?;
        Ok((out.recording, out.rows))
    }

    /// The streaming reader with [`ReadOptions`]: mapped columns are read under their canonical
    /// names and converted cell by cell (the plausibility limits apply after conversion); rows
    /// before t0 + `trim_start_s` are checked, then dropped; with `resample`, time steps may
    /// jitter (gaps over [`MAX_GAP_STEPS`] median steps are still refused) and the kept samples
    /// are interpolated onto a uniform grid.
    pub fn from_reader_with<R: std::io::Read>(
        file: &str,
        input: R,
        max_samples: usize,
        opts: &ReadOptions,
    ) -> Result<ReadOutcome> {
        let (delimiter, sep_line, head, input) =
            separated(input, opts.skip_rows).map_err(|e| crate::files::read_error(file, e))?;
        // The header's line: after the skipped preamble and a `sep=` line.
        let header_line = 1 + opts.skip_rows as u64 + u64::from(sep_line);
        // Row lengths are checked row by row (a line of spaces is blank, not a row of one field).
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(true)
            .delimiter(delimiter)
            .from_reader(input);
        let headers = rdr.headers().map_err(|e| csv_error(file, e))?.clone();
        if headers.iter().all(|h| h.trim().is_empty()) {
            // The header is the line before the reader's position (blank lines before it skipped).
            let line = rdr.position().line().saturating_sub(1).max(1);
            if headers.len() > 1 || rdr.records().next().is_some() {
                located!(file, Some(line), None; "the header line names no columns (only separators or blanks); expected a header such as `time_s,current_A,displacement_um`");
            }
            if rdr.position().byte() > 0 {
                located!(file; "the file holds only blank lines (no header line); expected a header such as `time_s,current_A,displacement_um`");
            }
            located!(file, Some(1), None; "empty file (no header line); expected a header such as `time_s,current_A,displacement_um`");
        }
        let (named, mapped) = opts.with_named_units(&headers.iter().collect::<Vec<_>>());
        note_named_units(file, &mapped);
        let opts = &named;
        let index = locate_columns(file, header_line, &headers, opts)?;
        let used: Vec<bool> = (0..headers.len()).map(|c| index.contains(&Some(c))).collect();
        let mut doubts =
            crate::read_doubts::column_doubts(file, &headers.iter().collect::<Vec<_>>(), &used, opts);
        // Cells of a `;` or tab export may have a decimal comma (a European spreadsheet's), and
        // the other mark then groups thousands: the first rows show which.
        let mut mark = (delimiter != b',').then(|| {
            let rows = head.iter().position(|b| *b == b'\n').map_or(&[][..], |end| &head[end + 1..]);
            let read: Vec<usize> = index.iter().flatten().copied().collect();
            crate::cell_text::DecimalMark::sniffed(rows, delimiter, header_line + 1, &read)
        });
        let mut stamps = crate::cell_text::Stamps::default();
        let maps: [Option<&ColumnMap>; COLUMNS.len()] = std::array::from_fn(|k| opts.map_of(k));
        if index[0].is_none() {
            // Only for the refusal: the lines below the first, looked through for a table's header.
            let below = rdr.records().take(PREAMBLE_LINES).filter_map(|r| {
                let r = r.ok()?;
                Some((r.position()?.line(), r.iter().collect::<Vec<_>>().join(",")))
            });
            let hint = preamble_hint(below.collect());
            check_time_and_drive(file, header_line, &headers, &index, hint)?;
        }
        check_time_and_drive(file, header_line, &headers, &index, None)?;
        let time_col = index[0].unwrap_or(0) + 1;
        let mut cols: [Vec<f64>; COLUMNS.len()] = Default::default();
        let mut time = TimeCheck { resample: opts.resample.is_some(), ..TimeCheck::default() };
        let trim = opts.trim_start_s.unwrap_or(0.0);
        let mut t0: Option<f64> = None;
        let (mut rows, mut eligible): (u64, u64) = (0, 0);
        let mut rec = csv::StringRecord::new();
        let mut values = [0.0; COLUMNS.len()];
        while rdr.read_record(&mut rec).map_err(|e| csv_error(file, e))? {
            let line = rec.position().map(|p| p.line()).unwrap_or(rows + 2);
            if rec.len() != headers.len() {
                // A line of spaces or tabs is blank, as an empty one (which the reader skips).
                if rec.len() == 1 && rec[0].trim().is_empty() {
                    continue;
                }
                located!(file, Some(line), None;
                    "{} fields, but the header has {} (a missing or extra comma?)", rec.len(), headers.len());
            }
            for (k, idx) in index.iter().enumerate() {
                let Some(c) = *idx else { continue };
                let raw = rec.get(c).unwrap_or("").trim();
                let raw = match &mut mark {
                    Some(mark) => mark.normalise(file, line, c as u64 + 1, raw)?,
                    None => std::borrow::Cow::Borrowed(raw),
                };
                values[k] = cell(file, line, c + 1, k, &raw, maps[k])?;
                if k == 0 {
                    let (pow10, negated) = maps[0].map_or((0, false), |m| (m.unit.pow10, m.negated));
                    let stamp = stamps.read(&raw, values[0], pow10, negated);
                    values[0] = stamp.t;
                    if stamp.rebased {
                        // The first stamp, read before the second gave the step, is the origin.
                        time.last = Some(0.0);
                        t0 = Some(0.0);
                        if eligible > 0 {
                            cols[0][0] = 0.0;
                        }
                    }
                }
            }
            time.resolution_s = stamps.resolution_s;
            time.push(file, line, time_col, values[0])?;
            let start = *t0.get_or_insert(values[0]);
            if opts.trim_start_s.is_none() || values[0] >= start + trim {
                if (eligible as usize) < max_samples {
                    for (k, idx) in index.iter().enumerate() {
                        if idx.is_some() {
                            cols[k].push(values[k]);
                        }
                    }
                }
                eligible += 1;
            }
            rows += 1;
        }
        if rows < 3 {
            located!(file;
                "{rows} data row{}; a recording needs at least 3",
                if rows == 1 { "" } else { "s" }
            );
        }
        let t_last = time.last.unwrap_or(0.0);
        time.finish(file, time_col)?;
        let take =
            |k: usize, cols: &mut [Vec<f64>; COLUMNS.len()]| index[k].map(|_| std::mem::take(&mut cols[k]));
        let mut r = Recording {
            name: file.to_string(),
            command_v: take(1, &mut cols),
            current_a: take(2, &mut cols),
            displacement_um: take(3, &mut cols),
            force_n: take(4, &mut cols),
            temperature_c: take(5, &mut cols),
            flux_density_t: take(6, &mut cols),
            time_s: std::mem::take(&mut cols[0]),
            header: headers.iter().map(|h| h.trim().to_string()).collect(),
        };
        if r.len() < 3 {
            located!(file;
                "--trim-start {} s leaves {} of the file's {rows} samples (the file spans {:.6e} s); at \
                 least 3 are needed",
                crate::files::short_number(trim),
                r.len(),
                t_last - t0.unwrap_or(0.0)
            );
        }
        let kept = r.len();
        if let Some(Resample::Linear) = opts.resample {
            r = r.resampled_linear(max_samples)?;
        }
        if let Some(origin) = stamps.origin() {
            doubts.push(ReadDoubt::StampsFromFirst { file: file.to_string(), origin: origin.to_string() });
        }
        doubts.extend(r.time_doubt());
        Ok(ReadOutcome { recording: r, rows: eligible, kept, doubts })
    }
}

/// Says which headers were read by the quantity and unit their names give.
fn note_named_units(file: &str, mapped: &[ColumnMap]) {
    for m in mapped {
        let unit = if m.unit.is_identity() {
            String::new()
        } else {
            format!(", {} → {}", m.unit.name, m.unit_canonical())
        };
        crate::warning::note(format_args!(
            "{file}: `{}` read as `{}`{unit} (the quantity and unit its name gives; `--column` maps it otherwise)",
            echo(&m.header),
            COLUMNS[m.canonical]
        ));
    }
}

/// Refuses a header without a time axis or a drive column, saying what it has and how to map one.
fn check_time_and_drive(
    file: &str,
    header_line: u64,
    headers: &csv::StringRecord,
    index: &[Option<usize>],
    preamble: Option<String>,
) -> Result<()> {
    if index[0].is_none() {
        let found: Vec<&str> = headers.iter().collect();
        let joined = found.join(", ");
        let comment = headers.get(0).is_some_and(|h| h.trim_start().starts_with('#'));
        let hint = case_hint(headers, "time_s")
            .or(preamble)
            .or_else(|| {
                comment.then(|| {
                    " — the first line starts with `#`: measurement files have no comment lines; the header \
                     must be the first line (move notes into a file of their own)"
                        .to_string()
                })
            })
            .unwrap_or_default();
        if let Some(loop_hint) = crate::loops::loop_header_hint(headers) {
            located!(file, Some(header_line), None; "no `time_s` column (header has: {}){loop_hint}", echo(&joined));
        }
        located!(file, Some(header_line), None;
            "no `time_s` column (header has: {}); recognised columns are {}{hint}; a time column of \
             another name or unit can be mapped, e.g. `--column time_s=time_ms:ms`",
            echo(&joined),
            COLUMNS.join(", ")
        );
    }
    if index[1].is_none() && index[2].is_none() {
        let hint =
            case_hint(headers, "current_A").or_else(|| case_hint(headers, "command_V")).unwrap_or_default();
        located!(file, Some(header_line), None; "needs a drive column: `current_A` or `command_V` (or one mapped with `--column current_A=HEADER[:UNIT]`){hint}");
    }
    Ok(())
}

/// Lines a logger writes above its table (a LabVIEW header block, an oscilloscope's settings)
/// are looked through for this many lines.
const PREAMBLE_LINES: usize = 200;

/// Where a header below a preamble lies: the first of the file's next `lines` (the line the
/// reader met each at, and its text) that is not numbers and is followed by two lines that
/// are, said with the `--skip-rows` that reads it.
fn preamble_hint(lines: Vec<(u64, String)>) -> Option<String> {
    let numbers = |l: &str| {
        let cells: Vec<&str> = l.split([',', ';', '\t']).map(str::trim).filter(|c| !c.is_empty()).collect();
        !cells.is_empty() && cells.iter().all(|c| c.parse::<f64>().is_ok())
    };
    let k = (0..lines.len().saturating_sub(2))
        .find(|&k| !numbers(&lines[k].1) && numbers(&lines[k + 1].1) && numbers(&lines[k + 2].1))?;
    // A record's line is where the reader met it: blank lines before it count, and
    // `--skip-rows` passing over fewer than them still reads the table (blank lines are).
    let (line, header) = &lines[k];
    let skip = line - 1;
    Some(format!(
        " — a table follows a logger's preamble: its header reads `{}`; read the file from there with \
         `--skip-rows {skip}` (and map its columns with --column if they are named otherwise)",
        echo(header.trim())
    ))
}

/// The column separator of a measurement file, whether a first line named it, the file's first
/// bytes from its header on (as far as one read buffered them: what the decimal mark is sniffed
/// from), and the file to read: a spreadsheet's `sep=X` first line names it (the line is read
/// as blank, so rows keep their line numbers); otherwise a
/// header without a comma but with `;` or tabs is separated by those, else by commas.
fn separated<R: std::io::Read>(
    input: R,
    skip_rows: usize,
) -> std::io::Result<(u8, bool, Vec<u8>, impl std::io::Read)> {
    use std::io::BufRead;
    let mut buf = std::io::BufReader::with_capacity(1 << 16, input);
    // A preamble passed over is read as blank lines, so rows keep the file's line numbers.
    let mut skipped = Vec::new();
    for _ in 0..skip_rows {
        let mut line = Vec::new();
        if buf.read_until(b'\n', &mut line)? == 0 {
            break;
        }
        skipped.push(b'\n');
    }
    let first_line = |bytes: &[u8]| -> String {
        let end = bytes.iter().position(|b| *b == b'\n').unwrap_or(bytes.len());
        String::from_utf8_lossy(&bytes[..end]).trim_start_matches('\u{feff}').trim().to_string()
    };
    let first = first_line(buf.fill_buf()?);
    let named = first.strip_prefix("sep=").and_then(|c| match c.as_bytes() {
        [c] => Some(*c),
        b"\\t" => Some(b'\t'),
        _ => None,
    });
    let (delimiter, blank): (u8, &[u8]) = match named {
        Some(c) => {
            let n = buf.fill_buf()?.iter().position(|b| *b == b'\n').map_or(buf.buffer().len(), |k| k + 1);
            buf.consume(n);
            (c, b"\n")
        }
        None if !first.contains(',') && first.contains(';') => (b';', b""),
        None if !first.contains(',') && first.contains('\t') => (b'\t', b""),
        None => (b',', b""),
    };
    let head = buf.fill_buf()?.to_vec();
    let blanks = std::io::Read::chain(std::io::Cursor::new(skipped), blank);
    Ok((delimiter, named.is_some(), head, std::io::Read::chain(blanks, buf)))
}

/// One cell: a finite number within the column's plausible range (after conversion from a
/// mapped column's unit).
fn cell(file: &str, line: u64, col: usize, k: usize, raw: &str, map: Option<&ColumnMap>) -> Result<f64> {
    let name = match map {
        Some(m) => m.label(),
        None => format!("`{}`", COLUMNS[k]),
    };
    let at = (Some(line), Some(col as u64));
    if raw.is_empty() {
        located!(file, at.0, at.1; "column {name} is empty");
    }
    let Ok(v) = raw.parse::<f64>() else {
        located!(file, at.0, at.1; "column {name}: `{}` is not a number", echo(raw));
    };
    if !v.is_finite() {
        located!(file, at.0, at.1; "column {name}: `{}` is not a finite number", echo(raw));
    }
    let Some(m) = map.filter(|m| !m.is_identity()) else {
        if let Err(why) = plausible(k, v) {
            located!(file, at.0, at.1; "column {name}: {} {why}", echo(raw));
        }
        return Ok(v);
    };
    let converted = m.convert(raw, v);
    if let Err(why) = plausible(k, converted) {
        located!(file, at.0, at.1; "column {name}: {} {} = {converted:e} {why}", echo(raw), m.unit.name);
    }
    Ok(converted)
}

/// A csv error as `file:line: what`.
fn csv_error(file: &str, e: csv::Error) -> anyhow::Error {
    let line = e.position().map(|p| p.line()).unwrap_or(1);
    match e.into_kind() {
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
    /// `--resample`: steps may jitter; only gaps over [`MAX_GAP_STEPS`] median steps are refused.
    resample: bool,
    last: Option<f64>,
    /// How finely the latest stamp's text resolves it [s] (0: not known).
    resolution_s: f64,
    /// Steps (line, step) held until the reference step is known.
    pending: Vec<(u64, f64)>,
    reference: Option<f64>,
}

impl TimeCheck {
    fn push(&mut self, file: &str, line: u64, col: usize, t: f64) -> Result<()> {
        let Some(last) = self.last.replace(t) else { return Ok(()) };
        if t <= last {
            // A stamp repeated where the step is finer than the stamps' last digit.
            let step = self.reference.or(self.pending.last().map(|p| p.1));
            let hint = match t == last {
                true => crate::cell_text::resolution_hint(self.resolution_s, step),
                false => String::new(),
            };
            located!(file, Some(line), Some(col as u64); "time_s does not increase ({t} s after {last} s on the line before){hint}");
        }
        let step = t - last;
        match self.reference {
            Some(dt) => jitter(file, line, col, step, dt, self.resample, self.resolution_s),
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
        // The model steps in f32: the range is checked, and shown, as model-core states it.
        let (lo, hi) = (model_core::DT_MIN_S, model_core::DT_MAX_S);
        if !(lo..=hi).contains(&(dt as f32)) {
            located!(file, self.pending.first().map(|p| p.0), Some(col as u64);
                "sample period {dt:.3e} s is outside [{lo:e}, {hi:e}] s (is time_s in seconds? a time column \
                 in ms maps with `--column time_s=HEADER:ms`)");
        }
        self.reference = Some(dt);
        for (line, step) in std::mem::take(&mut self.pending) {
            jitter(file, line, col, step, dt, self.resample, self.resolution_s)?;
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

/// One time step against the median step `dt`: within [`MAX_JITTER`], or with `resample` at
/// most [`MAX_GAP_STEPS`] steps; `resolution_s` is how finely the stamps are written.
fn jitter(
    file: &str,
    line: u64,
    col: usize,
    step: f64,
    dt: f64,
    resample: bool,
    resolution_s: f64,
) -> Result<()> {
    if resample {
        // A gap of exactly MAX_GAP_STEPS steps is bridged: the time stamps' rounding may add the
        // jitter allowed without resampling.
        if step > MAX_GAP_STEPS * dt * (1.0 + MAX_JITTER) {
            located!(file, Some(line), Some(col as u64);
                "time step {step:.3e} s is more than {MAX_GAP_STEPS} median steps ({dt:.3e} s): a gap (lost \
                 samples), which --resample does not bridge; split the recording at the gap"
            );
        }
        return Ok(());
    }
    if (step - dt).abs() > MAX_JITTER * dt {
        located!(file, Some(line), Some(col as u64);
            "time step {step:.3e} s differs from the median step {dt:.3e} s by more than {:.0} % (missing \
             samples or jittered time stamps; `--resample linear` interpolates jittered time stamps onto \
             a uniform grid and bridges gaps of up to {MAX_GAP_STEPS} steps; split the recording at a \
             longer gap){}",
            MAX_JITTER * 100.0,
            crate::cell_text::resolution_hint(resolution_s, Some(dt))
        );
    }
    Ok(())
}

/// The column index of each canonical column: a mapped column by its header (which must be in
/// the file), any other by its own name unless a mapping reads that header as something else. A
/// column name found twice is refused (on `header_line`).
fn locate_columns(
    file: &str,
    header_line: u64,
    headers: &csv::StringRecord,
    opts: &ReadOptions,
) -> Result<[Option<usize>; COLUMNS.len()]> {
    let mut index = [None; COLUMNS.len()];
    for (k, name) in COLUMNS.iter().enumerate() {
        let map = opts.map_of(k);
        let wanted = match map {
            Some(m) => m.header.as_str(),
            None if opts.claims(name) => continue,
            None => name,
        };
        let mut found = headers.iter().enumerate().filter(|(_, h)| h.trim() == wanted).map(|(c, _)| c);
        let first = found.next();
        if let (Some(a), Some(b)) = (first, found.next()) {
            located!(file, Some(header_line), Some(b as u64 + 1);
                "column `{}` appears twice (columns {} and {})", echo(wanted), a + 1, b + 1);
        }
        if let (None, Some(m)) = (first, map) {
            located!(file, Some(header_line), None;
                "--column `{}`: the file has no column `{}` (header has: {})",
                echo(&m.option),
                echo(wanted),
                header_list(headers)
            );
        }
        index[k] = first;
    }
    Ok(index)
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
        let e = err("# rig A, 2024\ntime_s,current_A\n0,1\n");
        assert!(e.contains("rig.csv:1") && e.contains("starts with `#`"), "{e}");
        let e = err("time_s,displacement_um\n0,1\n0.001,1\n0.002,1\n");
        assert!(e.contains("drive column"), "{e}");
        let e = err("time_s,current_A,current_A\n0,1,1\n");
        assert!(e.contains("appears twice"), "{e}");
        // A header that is a column's name but for its case is named, with the mapping.
        let e = err("Time_s,current_A\n0,1\n");
        assert!(
            e.contains("`Time_s` differs from `time_s` only in case") && e.contains("--column time_s=Time_s"),
            "{e}"
        );
        let e = err("time_s,Command_v\n0,1\n");
        assert!(e.contains("`Command_v` differs from `command_V` only in case"), "{e}");
    }

    #[test]
    fn spreadsheet_exports_with_a_byte_order_mark_and_crlf_are_read() {
        let r = Recording::parse("rig.csv", b"\xEF\xBB\xBFtime_s,current_A\r\n0,1\r\n0.001,2\r\n0.002,3\r\n")
            .unwrap();
        assert_eq!(r.current_a.unwrap(), vec![1.0, 2.0, 3.0]);
    }

    fn with(text: &str, opts: &ReadOptions) -> Result<Recording> {
        Ok(Recording::from_reader_with("j.csv", text.as_bytes(), usize::MAX, opts)?.recording)
    }

    #[test]
    fn resampling_interpolates_every_channel_at_about_the_median_step() {
        // Steps of 1.03, 0.94, 1.05, 0.98, 0.99 ms; channels linear in time, so the grid values
        // are known exactly.
        let mut text = String::from("time_s,current_A,displacement_um\n");
        for t in [0.0, 0.00103, 0.00197, 0.00302, 0.004, 0.00499] {
            text += &format!("{t},{},{}\n", 1.0 + 100.0 * t, 5.0 - 1000.0 * t);
        }
        let e = format!("{:#}", with(&text, &ReadOptions::default()).unwrap_err());
        assert!(e.contains("j.csv:3:1") && e.contains("--resample linear"), "{e}");
        let opts = ReadOptions { resample: Some(Resample::Linear), ..Default::default() };
        let r = with(&text, &opts).unwrap();
        assert_eq!(r.len(), 6);
        // Five steps of the median (0.99 ms) span the file: the grid's step lands on its last
        // sample.
        for k in 0..6 {
            let t = k as f64 * 0.00499 / 5.0;
            assert!((r.time_s[k] - t).abs() < 1e-15);
            assert!((r.current_a.as_ref().unwrap()[k] - (1.0 + 100.0 * t)).abs() < 1e-12);
            assert!((r.displacement_um.as_ref().unwrap()[k] - (5.0 - 1000.0 * t)).abs() < 1e-12);
        }
        // A median (1.01 ms) above the mean step: the last sample is kept, not dropped.
        let mut text = String::from("time_s,current_A\n");
        for t in [0.0, 0.00101, 0.00202, 0.00303, 0.00398] {
            text += &format!("{t},{}\n", 1.0 + 100.0 * t);
        }
        let r = with(&text, &opts).unwrap();
        assert_eq!(r.len(), 5);
        assert!(
            (r.time_s[4] - 0.00398).abs() < 1e-15 && (r.current_a.as_ref().unwrap()[4] - 1.398).abs() < 1e-12
        );
        // A gap of more than 5 median steps is refused all the same.
        let gap = "time_s,current_A\n0,1\n0.001,2\n0.002,3\n0.008,4\n0.009,5\n";
        let e = format!("{:#}", with(gap, &opts).unwrap_err());
        assert!(e.contains("j.csv:5:1") && e.contains("gap"), "{e}");
    }

    #[test]
    fn mapped_columns_are_converted_and_the_start_trimmed() {
        let opts = ReadOptions::new(
            &["time_s=t:ms".to_string(), "current_A=I:mA".to_string(), "temperature_C=T:K".to_string()],
            None,
            Some(0.002),
        )
        .unwrap();
        let text = "t,I,T,current_A\n0,1000,300,9\n1,2000,301,9\n2,3000,302,9\n3,4000,303,9\n4,5000,304,9\n";
        let r = with(text, &opts).unwrap();
        assert_eq!(r.time_s, vec![0.002, 0.003, 0.004]);
        assert_eq!(r.current_a.unwrap(), vec![3.0, 4.0, 5.0]);
        assert!((r.temperature_c.unwrap()[0] - 28.85).abs() < 1e-12);
        let e = format!("{:#}", with("t,x\n0,1\n1,2\n2,3\n", &opts).unwrap_err());
        assert!(
            e.contains("j.csv:1: --column `current_A=I:mA`: the file has no column `I` (header has: t, x)"),
            "{e}"
        );
        let e = format!("{:#}", with("t,I,T\n0,1,1\n1,2,1\n2,x,1\n", &opts).unwrap_err());
        assert!(
            e.contains("j.csv:4:2: column `I` (read as `current_A`, mA → A): `x` is not a number"),
            "{e}"
        );
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
