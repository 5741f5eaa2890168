//! How a measurement file is read when its columns are not as the workbench writes them
//! (docs/formats.md, "Columns as users have them"): `--column CANONICAL=HEADER[:UNIT]` maps a
//! column of another name or unit onto a recognised one, `--resample linear` puts jittered time
//! stamps onto a uniform grid, `--trim-start SECONDS` drops a start-up transient. Nothing here is
//! ever guessed: without these options a file is read exactly as before.

use anyhow::{bail, Result};

/// The recognised columns, in the order the workbench writes them.
pub const COLUMNS: [&str; 7] =
    ["time_s", "command_V", "current_A", "displacement_um", "force_N", "temperature_C", "flux_density_T"];

/// A unit a column may be given in, and how it converts to the column's canonical unit:
/// value × 10^`pow10` × `ratio` + `offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unit {
    /// The unit's name as written in `--column` (case-sensitive).
    pub name: &'static str,
    /// Decimal exponent of the scale factor (mm → µm: 3).
    pub pow10: i32,
    /// Offset added after scaling (K → °C: −273.15).
    pub offset: f64,
    /// A factor that is not a power of ten (°F → °C: 5/9), 1 for the others.
    pub ratio: f64,
}

const fn unit(name: &'static str, pow10: i32) -> Unit {
    Unit { name, pow10, offset: 0.0, ratio: 1.0 }
}

/// The units accepted per canonical column (same order as [`COLUMNS`]); the first is the
/// canonical unit itself, assumed when `--column` names none.
pub const UNITS: [&[Unit]; COLUMNS.len()] = [
    &[unit("s", 0), unit("ms", -3), unit("us", -6), unit("µs", -6)],
    &[unit("V", 0), unit("mV", -3)],
    &[unit("A", 0), unit("mA", -3), unit("uA", -6), unit("µA", -6)],
    &[unit("um", 0), unit("µm", 0), unit("m", 6), unit("mm", 3), unit("nm", -3)],
    &[unit("N", 0), unit("kN", 3)],
    &[
        unit("°C", 0),
        unit("C", 0),
        Unit { name: "K", pow10: 0, offset: -273.15, ratio: 1.0 },
        FAHRENHEIT,
        Unit { name: "F", ..FAHRENHEIT },
    ],
    &[unit("T", 0), unit("mT", -3), unit("G", -4)],
];

/// °F → °C: (v − 32) × 5/9.
const FAHRENHEIT: Unit = Unit { name: "°F", pow10: 0, offset: -32.0 * 5.0 / 9.0, ratio: 5.0 / 9.0 };

/// The canonical unit of each column, as messages print it.
const CANONICAL_UNIT: [&str; COLUMNS.len()] = ["s", "V", "A", "µm", "N", "°C", "T"];

impl Unit {
    /// Whether this unit is the column's canonical unit (no conversion).
    pub fn is_identity(&self) -> bool {
        self.pow10 == 0 && self.offset == 0.0 && self.ratio == 1.0
    }

    /// Converts a cell: `raw` is its text, `v` the number it parsed to. A power of ten shifts the
    /// cell's decimal exponent before one correctly rounded parse, so `0.5` in mm gives exactly
    /// the number `500` in µm would (no second rounding from a multiplication).
    pub fn convert(&self, raw: &str, v: f64) -> f64 {
        if self.pow10 == 0 {
            return v * self.ratio + self.offset;
        }
        let (mantissa, exp) = match raw.find(['e', 'E']) {
            Some(i) => (&raw[..i], raw[i + 1..].parse::<i64>().ok()),
            None => (raw, Some(0)),
        };
        let shifted = exp
            .and_then(|e| e.checked_add(self.pow10 as i64))
            .and_then(|e| format!("{mantissa}e{e}").parse::<f64>().ok());
        shifted.unwrap_or_else(|| v * 10f64.powi(self.pow10)) + self.offset
    }
}

/// One `--column CANONICAL=[-]HEADER[:UNIT]`: the file's column `header`, read as canonical
/// column `canonical` (index into [`COLUMNS`]) after converting from `unit`, and negated after a
/// `-` (a probe wired the other way round).
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    /// Index of the canonical column in [`COLUMNS`].
    pub canonical: usize,
    /// The header in the file (matched exactly, spaces around it ignored).
    pub header: String,
    /// The unit of the file's column.
    pub unit: Unit,
    /// `-HEADER`: the values are read with their sign changed.
    pub negated: bool,
    /// The option as given, for messages.
    pub option: String,
}

impl ColumnMap {
    /// Parses `CANONICAL=HEADER[:UNIT]`; the error names the option and what is accepted.
    pub fn parse(option: &str) -> Result<Self> {
        let shown = crate::files::echo(option);
        let Some((canonical, rest)) = option.split_once('=') else {
            bail!(
                "--column `{shown}`: expected CANONICAL=HEADER[:UNIT], e.g. `--column time_s=time_ms:ms` \
                 or `--column displacement_um=x_mm:mm`"
            );
        };
        let canonical = canonical.trim();
        let Some(k) = COLUMNS.iter().position(|c| *c == canonical) else {
            bail!(
                "--column `{shown}`: unknown column `{}`; the recognised columns are {}",
                crate::files::echo(canonical),
                COLUMNS.join(", ")
            );
        };
        let (header, unit) = match rest.rsplit_once(':') {
            Some((h, u)) => (h.trim(), Some(u.trim())),
            None => (rest.trim(), None),
        };
        let (negated, header) = match header.strip_prefix('-') {
            Some(h) => (true, h.trim()),
            None => (false, header),
        };
        if header.is_empty() {
            bail!("--column `{shown}`: no HEADER after `=` (expected CANONICAL=HEADER[:UNIT])");
        }
        let unit = match unit {
            // A header that names another unit is not read as the canonical one unsaid.
            None => match named_unit(header, k) {
                Some(u) => bail!(
                    "--column `{shown}`: the header `{}` names {u}, but no unit is given, so it would be read as {}; give it (`{canonical}={}:{u}` converts it) or, if the values are {} despite the name, `:{}`",
                    crate::files::echo(header),
                    CANONICAL_UNIT[k],
                    crate::files::echo(header),
                    CANONICAL_UNIT[k],
                    UNITS[k][0].name
                ),
                None => UNITS[k][0],
            },
            Some(u) => match UNITS[k].iter().find(|x| x.name == u) {
                Some(x) => *x,
                None => bail!(
                    "--column `{shown}`: unknown unit `{}` for `{canonical}`; accepted: {} (a header \
                     that contains `:` needs its unit named: HEADER:UNIT)",
                    crate::files::echo(u),
                    unit_names(k)
                ),
            },
        };
        Ok(Self { canonical: k, header: header.to_string(), unit, negated, option: option.to_string() })
    }

    /// Whether a cell is read as it is (canonical unit, not negated).
    pub fn is_identity(&self) -> bool {
        self.unit.is_identity() && !self.negated
    }

    /// A cell converted to the canonical unit (and negated), as [`Unit::convert`].
    pub fn convert(&self, raw: &str, v: f64) -> f64 {
        let v = self.unit.convert(raw, v);
        if self.negated {
            -v
        } else {
            v
        }
    }

    /// The canonical column's unit, as messages print it.
    pub fn unit_canonical(&self) -> &'static str {
        CANONICAL_UNIT[self.canonical]
    }

    /// How messages name the column: `` `x_mm` (read as `displacement_um`, mm → µm) ``.
    pub fn label(&self) -> String {
        let name = COLUMNS[self.canonical];
        let header = crate::files::echo(&self.header);
        let negated = if self.negated { ", negated" } else { "" };
        if self.unit.is_identity() {
            format!("`{header}` (read as `{name}`{negated})")
        } else {
            format!(
                "`{header}` (read as `{name}`, {} → {}{negated})",
                self.unit.name, CANONICAL_UNIT[self.canonical]
            )
        }
    }
}

/// A converting unit of column `k` that `header` names at its end (`x_mm`, `x [mm]`, `x (mm)`,
/// `x/mm`, `x mm`), if any.
fn named_unit(header: &str, k: usize) -> Option<&'static str> {
    UNITS[k].iter().filter(|u| !u.is_identity()).map(|u| u.name).find(|u| {
        ["_", " ", "/"].iter().any(|sep| header.ends_with(&format!("{sep}{u}")))
            || header.ends_with(&format!("[{u}]"))
            || header.ends_with(&format!("({u})"))
    })
}

/// The accepted unit names of canonical column `k`, for messages and docs.
pub fn unit_names(k: usize) -> String {
    UNITS[k].iter().map(|u| u.name).collect::<Vec<_>>().join(", ")
}

/// How irregular time stamps are put onto a uniform grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Resample {
    /// Every channel linearly interpolated at the median time step, from the first sample to the
    /// last.
    Linear,
}

impl Resample {
    /// Parses a `--resample` value.
    pub fn parse(method: &str) -> Result<Self> {
        match method.trim() {
            "linear" => Ok(Resample::Linear),
            other => bail!(
                "--resample `{}`: unknown method; the only method is `linear` (linear interpolation of \
                 every channel at the median time step)",
                crate::files::echo(other)
            ),
        }
    }
}

/// Largest time step [median steps] that `--resample` interpolates across; a longer one is a
/// gap (lost samples), refused even when resampling.
pub const MAX_GAP_STEPS: f64 = 5.0;

/// How measurement files are read: column mapping, resampling, trimming. The default reads a
/// file exactly as docs/formats.md describes without these options.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// `--column` mappings, at most one per canonical column.
    pub columns: Vec<ColumnMap>,
    /// `--resample`.
    pub resample: Option<Resample>,
    /// `--trim-start` [s]: samples before t0 + this are dropped.
    pub trim_start_s: Option<f64>,
    /// `--skip-rows`: lines before the header (a logger's preamble) passed over unread.
    pub skip_rows: usize,
}

impl ReadOptions {
    /// Parses and checks the options (each message names its option).
    pub fn new(columns: &[String], resample: Option<&str>, trim_start_s: Option<f64>) -> Result<Self> {
        let mut maps: Vec<ColumnMap> = Vec::new();
        for c in columns {
            let m = ColumnMap::parse(c)?;
            if let Some(first) = maps.iter().find(|x| x.canonical == m.canonical) {
                bail!(
                    "--column `{}`: `{}` is already mapped by --column `{}` (one column per canonical name)",
                    crate::files::echo(c),
                    COLUMNS[m.canonical],
                    crate::files::echo(&first.option)
                );
            }
            if let Some(first) = maps.iter().find(|x| x.header == m.header) {
                bail!(
                    "--column `{}`: column `{}` is already read by --column `{}`",
                    crate::files::echo(c),
                    crate::files::echo(&m.header),
                    crate::files::echo(&first.option)
                );
            }
            maps.push(m);
        }
        if let Some(t) = trim_start_s {
            if !(t.is_finite() && t >= 0.0) {
                bail!(
                    "--trim-start must be a finite number of seconds ≥ 0, got {}",
                    crate::files::short_number(t)
                );
            }
        }
        Ok(Self {
            columns: maps,
            resample: resample.map(Resample::parse).transpose()?,
            trim_start_s,
            skip_rows: 0,
        })
    }

    /// These options passing over the first `rows` lines of each file (`--skip-rows`).
    pub fn skipping(self, rows: usize) -> Self {
        Self { skip_rows: rows, ..self }
    }

    /// Whether no option is set (files are read as they are).
    pub fn is_default(&self) -> bool {
        self.columns.is_empty()
            && self.resample.is_none()
            && self.trim_start_s.is_none()
            && self.skip_rows == 0
    }

    /// These options with each canonical column a file's `headers` lack by name, and no option
    /// maps, read from the one header that names its quantity and unit ([`named_quantity`]), and
    /// what was mapped (the mappings, to be said).
    pub fn with_named_units(&self, headers: &[&str]) -> (ReadOptions, Vec<ColumnMap>) {
        let mut opts = self.clone();
        let mut mapped = Vec::new();
        for (k, name) in COLUMNS.iter().enumerate() {
            if self.map_of(k).is_some() || headers.iter().any(|h| h.trim() == *name) {
                continue;
            }
            let mut named = headers
                .iter()
                .filter(|h| !self.claims(h.trim()))
                .filter_map(|h| named_quantity(h).filter(|(c, _)| *c == k).map(|(_, u)| (h.trim(), u)));
            if let (Some((header, unit)), None) = (named.next(), named.next()) {
                let m = ColumnMap {
                    canonical: k,
                    header: header.to_string(),
                    unit,
                    negated: false,
                    option: format!("{name}={header}:{}", unit.name),
                };
                opts.columns.push(m.clone());
                mapped.push(m);
            }
        }
        (opts, mapped)
    }

    /// The mapping of canonical column `k`, if any.
    pub fn map_of(&self, k: usize) -> Option<&ColumnMap> {
        self.columns.iter().find(|m| m.canonical == k)
    }

    /// Whether `header` is claimed by a mapping (and so not read under its own name).
    pub fn claims(&self, header: &str) -> bool {
        self.columns.iter().any(|m| m.header == header)
    }
}

/// The separator a loop file's first line uses: a tab, a comma, or (refused by `loops::parse` with a
/// hint, but still a loop file) a semicolon when the line has no comma.
pub(crate) fn loop_separator(first: &str) -> char {
    if first.contains('\t') {
        '\t'
    } else if first.contains(';') && !first.contains(',') {
        ';'
    } else {
        ','
    }
}

/// Whether `text` looks like a loop file (named loop columns, or two columns with an H/B header
/// or none; separated by a semicolon too, so that such a file is told what is wrong with it).
pub fn looks_like_loop(text: &str) -> bool {
    let first = text.lines().next().unwrap_or("").to_ascii_lowercase();
    // A recording may log the field too: its displacement makes it a recording.
    if first.contains("displacement_um") {
        return false;
    }
    if first.contains("field_a_per_m") {
        return true;
    }
    if first.contains("time_s") {
        return false;
    }
    let sep = loop_separator(&first);
    let fields: Vec<&str> = first.split(sep).collect();
    fields.len() == 2
        && (fields.iter().all(|f| f.trim().parse::<f64>().is_ok()) || first.trim_start().starts_with('h'))
}

/// Whether a file whose first line is `first` is a magnetization-loop file rather than a
/// recording, decided on its header as the recording reader maps it (`--column`, and headers
/// that name their quantity and unit such as `Displacement (um)`): a time axis, a drive and a
/// displacement make a recording, whatever loop columns it logs beside them. A header with loop
/// columns, a time axis and a drive whose only displacement is a column of another name
/// (`x_um`) could be either, and is refused naming both readings.
pub fn is_loop_file(name: &str, first: &str, opts: &ReadOptions) -> Result<bool> {
    if !looks_like_loop(first) {
        return Ok(false);
    }
    let sep = if !first.contains(',') && first.contains(';') {
        ';'
    } else if !first.contains(',') && first.contains('\t') {
        '\t'
    } else {
        ','
    };
    let headers: Vec<&str> = first.split(sep).map(|h| h.trim().trim_matches('"').trim()).collect();
    if headers.iter().any(|h| opts.claims(h)) {
        return Ok(false);
    }
    let (named, _) = opts.with_named_units(&headers);
    let has = |k: usize| match named.map_of(k) {
        Some(m) => headers.contains(&m.header.as_str()),
        None => headers.contains(&COLUMNS[k]) && !named.claims(COLUMNS[k]),
    };
    let (time, drive, displacement) = (has(0), has(1) || has(2), has(3));
    if time && drive && displacement {
        return Ok(false);
    }
    let named_like_displacement = headers.iter().find(|h| !named.claims(h) && suggested(h) == Some(3));
    if let (true, true, Some(x)) = (time, drive, named_like_displacement) {
        let loop_columns: Vec<String> = headers
            .iter()
            .filter(|h| ["field_A_per_m", "flux_density_T", "magnetization_A_per_m"].contains(h))
            .map(|h| format!("`{h}`"))
            .collect();
        crate::located!(name, Some(1), None;
            "the header reads two ways: as a magnetization loop ({}), or as a recording with a time axis and a              drive whose displacement is `{}`; to read it as the recording, give `--column {}`; to fit its loop,              write the loop columns to a file of their own",
            loop_columns.join(", "),
            crate::files::echo(x),
            column_option(3, x)
        );
    }
    Ok(true)
}

/// Words a header may name each canonical column by (ignoring case, same order as
/// [`COLUMNS`]) before its unit in brackets or parentheses: `Time [s]`, `I (mA)`.
const QUANTITIES: [&[&str]; COLUMNS.len()] = [
    &["time", "t"],
    &["command", "voltage", "u", "v"],
    &["current", "i"],
    // Not `x`: a coordinate as often as the probe's reading (its header gets the `--column` hint).
    &["displacement", "disp"],
    &["force", "f"],
    &["temperature", "temp"],
    &["flux density", "flux_density", "b"],
];

/// The canonical column and unit a header names as `QUANTITY [UNIT]` or `QUANTITY (UNIT)`, when
/// both are clear: a word of [`QUANTITIES`] or the column's own name, and a unit that column
/// accepts.
fn named_quantity(header: &str) -> Option<(usize, Unit)> {
    let h = header.trim();
    let open = match h.chars().last()? {
        ']' => '[',
        ')' => '(',
        _ => return None,
    };
    let (quantity, unit) = h[..h.len() - 1].rsplit_once(open)?;
    let quantity = quantity.trim().to_lowercase();
    // The canonical name itself with a unit after it (`current_A (A)`): the bracket's unit says
    // what the values are.
    let k = QUANTITIES
        .iter()
        .position(|words| words.contains(&quantity.as_str()))
        .or_else(|| COLUMNS.iter().position(|c| c.to_lowercase() == quantity))?;
    UNITS[k].iter().find(|u| u.name == unit.trim()).map(|u| (k, *u))
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_with_and_without_unit() {
        let m = ColumnMap::parse("time_s=time_ms:ms").unwrap();
        assert_eq!((m.canonical, m.header.as_str(), m.unit.name), (0, "time_ms", "ms"));
        let m = ColumnMap::parse("current_A=I").unwrap();
        assert_eq!((m.canonical, m.header.as_str(), m.unit.name), (2, "I", "A"));
        let m = ColumnMap::parse("displacement_um = x [mm] : mm").unwrap();
        assert_eq!((m.header.as_str(), m.unit.pow10), ("x [mm]", 3));
        let m = ColumnMap::parse("temperature_C=T:K").unwrap();
        assert!((m.unit.convert("300", 300.0) - 26.85).abs() < 1e-12);
    }

    #[test]
    fn bad_options_name_themselves() {
        let e = |s: &str| format!("{}", ColumnMap::parse(s).unwrap_err());
        assert!(e("time_ms").contains("expected CANONICAL=HEADER[:UNIT]"));
        assert!(e("time=t:ms").contains("unknown column `time`"));
        assert!(e("time_s=t:h").contains("unknown unit `h` for `time_s`; accepted: s, ms, us, µs"));
        assert!(e("current_A=I:mm").contains("accepted: A, mA"));
        assert!(e("time_s=:ms").contains("no HEADER"));
        let dup =
            ReadOptions::new(&["time_s=a:ms".to_string(), "time_s=b".to_string()], None, None).unwrap_err();
        assert!(dup.to_string().contains("already mapped"), "{dup}");
        assert!(ReadOptions::new(&[], Some("cubic"), None).unwrap_err().to_string().contains("--resample"));
        assert!(ReadOptions::new(&[], None, Some(-1.0)).unwrap_err().to_string().contains("--trim-start"));
    }

    #[test]
    fn powers_of_ten_convert_exactly() {
        for (raw, unit, canonical) in [
            ("0.1234", unit("ms", -3), "0.0001234"),
            ("0.0007938876", unit("mm", 3), "0.7938876"),
            ("-7.5e-4", unit("mm", 3), "-0.75"),
            ("+12E2", unit("nm", -3), "1.2"),
            ("1.1", unit("m", 6), "1100000"),
        ] {
            let v: f64 = raw.parse().unwrap();
            assert_eq!(unit.convert(raw, v), canonical.parse::<f64>().unwrap(), "{raw} {}", unit.name);
        }
    }
}
