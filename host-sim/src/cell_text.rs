//! How a measurement cell's text becomes a number, where an `f64` parse of it alone would give a
//! plausible wrong answer:
//!
//! - the decimal mark of a `;`- or tab-separated export: a comma or a point, the other one then a
//!   thousands separator where it groups three digits (`1.234,5` is 1234.5 in a German export,
//!   `1,234.5` in an English one). A file is read with one decimal mark throughout; a cell that
//!   could be read either way (`1.234`) is read by the mark the file shows elsewhere, and refused
//!   when the file shows both;
//! - time stamps with more digits than an `f64` holds (Unix-epoch seconds at 10 kHz, such as
//!   `1764633600.0001234`): read as exact decimal offsets from the first stamp, so that the step
//!   is not the difference of two rounded large numbers.

use std::borrow::Cow;

use anyhow::Result;

use crate::files::echo;
use crate::located;

/// An exact decimal number: `mantissa` × 10^`exp`, as written (trailing zeros kept: they say
/// how finely the text resolves its value).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decimal {
    mantissa: i128,
    exp: i32,
}

impl Decimal {
    /// Parses `[+-]DIGITS[.DIGITS][(e|E)[+-]DIGITS]` (or `.5`, `5.`); None for anything else, or
    /// for more digits than 38.
    pub fn parse(text: &str) -> Option<Self> {
        let (body, exp) = match text.find(['e', 'E']) {
            Some(i) => (&text[..i], text[i + 1..].parse::<i32>().ok()?),
            None => (text, 0),
        };
        let (negative, body) = match body.as_bytes().first()? {
            b'-' => (true, &body[1..]),
            b'+' => (false, &body[1..]),
            _ => (false, body),
        };
        let (int, frac) = body.split_once('.').unwrap_or((body, ""));
        if int.is_empty() && frac.is_empty() {
            return None;
        }
        let mut mantissa: i128 = 0;
        for c in int.bytes().chain(frac.bytes()) {
            if !c.is_ascii_digit() {
                return None;
            }
            mantissa = mantissa.checked_mul(10)?.checked_add(i128::from(c - b'0'))?;
        }
        let exp = exp.checked_sub(i32::try_from(frac.len()).ok()?)?;
        Some(Self { mantissa: if negative { -mantissa } else { mantissa }, exp })
    }

    /// `self − other`, exactly (None if it does not fit).
    pub fn minus(self, other: Self) -> Option<Self> {
        let exp = self.exp.min(other.exp);
        let widen = |d: Self| -> Option<i128> {
            let shift = u32::try_from(d.exp - exp).ok()?;
            d.mantissa.checked_mul(10i128.checked_pow(shift)?)
        };
        Some(Self { mantissa: widen(self)?.checked_sub(widen(other)?)?, exp })
    }

    /// × 10^`pow10` (a unit's power of ten), and negated when asked (a `--column -HEADER`).
    pub fn scaled(self, pow10: i32, negated: bool) -> Self {
        Self { mantissa: if negated { -self.mantissa } else { self.mantissa }, exp: self.exp + pow10 }
    }

    /// The nearest `f64` (one correctly rounded conversion).
    pub fn to_f64(self) -> f64 {
        format!("{}e{}", self.mantissa, self.exp).parse().unwrap_or(f64::NAN)
    }

    /// The value of one unit in its last written digit: how finely the text resolves it.
    pub fn resolution(self) -> f64 {
        10f64.powi(self.exp)
    }
}

/// How many steps from zero an `f64` time axis may start: beyond, the stamps are read as
/// offsets from the first. At 1e9 steps one stamp's rounding is 2.2e-7 of a step (a clock at
/// 1000 s sampled at 10 kHz, 1e7 steps: 2.2e-9); Unix-epoch seconds at 10 kHz are 1.8e13 steps
/// from zero. At 1e6, clocks at 101 s were rebased and what gma wrote began at 0 (issue 78).
const MAX_ORIGIN_STEPS: f64 = 1e9;

/// The time axis as it is read: each stamp's exact decimal value, and (once the second stamp
/// gives the step) whether stamps are held as offsets from the first.
#[derive(Debug, Default)]
pub struct Stamps {
    first: Option<(Option<Decimal>, f64)>,
    /// The first stamp's text.
    first_text: String,
    /// Decided at the second stamp.
    from_first: Option<bool>,
    /// The resolution of the latest stamp's text [s] (0 when not known).
    pub resolution_s: f64,
}

/// A stamp as the recording holds it.
pub struct Stamp {
    /// [s]: as parsed, or as an offset from the first stamp.
    pub t: f64,
    /// This stamp decided that stamps are offsets from the first: the first one, read before,
    /// now holds 0.
    pub rebased: bool,
}

impl Stamps {
    /// The stamp of cell text `text` (the decimal point already normalised), parsed as `t` in
    /// seconds; `pow10` and `negated` are its column's mapping (a unit in ms, a `-HEADER`).
    pub fn read(&mut self, text: &str, t: f64, pow10: i32, negated: bool) -> Stamp {
        let exact = Decimal::parse(text).map(|d| d.scaled(pow10, negated));
        self.resolution_s = exact.map_or(0.0, Decimal::resolution);
        let Some((first, first_t)) = self.first else {
            self.first = Some((exact, t));
            self.first_text = text.to_string();
            return Stamp { t, rebased: false };
        };
        let offset = first.zip(exact).and_then(|(a, b)| b.minus(a)).map(Decimal::to_f64);
        let decided = self.from_first.is_some();
        let from_first = *self.from_first.get_or_insert_with(|| {
            offset.is_some_and(|step| step > 0.0 && first_t.abs() > MAX_ORIGIN_STEPS * step)
        });
        match (from_first, offset) {
            (true, Some(offset)) => Stamp { t: offset, rebased: !decided },
            _ => Stamp { t, rebased: false },
        }
    }

    /// The first stamp as written [s], when stamps are held as offsets from it.
    pub fn origin(&self) -> Option<&str> {
        (self.from_first == Some(true)).then_some(self.first_text.as_str())
    }
}

/// A hint for a time step the stamps' text may not resolve (`resolution_s`, 0 if not known,
/// against the step `step_s`, if known): empty when they resolve it to 1 %.
pub fn resolution_hint(resolution_s: f64, step_s: Option<f64>) -> String {
    match step_s {
        _ if resolution_s <= 0.0 => String::new(),
        Some(step) if resolution_s <= 0.01 * step.abs() => String::new(),
        Some(_) => format!(
            "; the stamps are written to {resolution_s:e} s, too coarse to resolve this sample period: export \
             the time column with more decimals"
        ),
        None => format!(
            "; the stamps are written to {resolution_s:e} s: if the sample period is finer, they are too coarse \
             to resolve it: export the time column with more decimals"
        ),
    }
}

/// A decimal mark.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mark {
    Comma,
    Point,
}

impl Mark {
    fn char(self) -> char {
        match self {
            Mark::Comma => ',',
            Mark::Point => '.',
        }
    }

    fn other(self) -> Mark {
        match self {
            Mark::Comma => Mark::Point,
            Mark::Point => Mark::Comma,
        }
    }

    fn of(c: char) -> Mark {
        if c == ',' {
            Mark::Comma
        } else {
            Mark::Point
        }
    }
}

/// What one cell's text says of the decimal mark.
#[derive(Debug, PartialEq, Eq)]
enum Shows {
    /// Neither `,` nor `.`.
    Nothing,
    /// This mark is the decimal one (`0,5`, `1.234,5`, `1.23`).
    Decimal(Mark),
    /// One separator before exactly three digits (`1.234`): a decimal mark or a thousands one.
    Either(Mark),
    /// Not a number with separators.
    Neither,
}

/// Whether `int` is digits grouped by `sep` in threes (`1.234.567`; the first group 1 to 3
/// digits, not a lone `0`), with at least one `sep`.
fn grouped(int: &str, sep: char) -> bool {
    let mut groups = int.split(sep);
    let first = groups.next().unwrap_or("");
    let digits = |g: &str| g.bytes().all(|b| b.is_ascii_digit());
    int.contains(sep)
        && (1..=3).contains(&first.len())
        && digits(first)
        && first != "0"
        && groups.all(|g| g.len() == 3 && digits(g))
}

/// What `text` (a cell, trimmed) says of the decimal mark.
fn shows(text: &str) -> Shows {
    let body = text.strip_prefix(['-', '+']).unwrap_or(text);
    let (body, exponent) = match body.find(['e', 'E']) {
        Some(i) => (&body[..i], true),
        None => (body, false),
    };
    let (commas, points) = (body.matches(',').count(), body.matches('.').count());
    match (commas, points) {
        (0, 0) => Shows::Nothing,
        (_, _) if commas > 0 && points > 0 => {
            // The last one is the decimal mark; the other groups the integer part.
            let last = if body.rfind(',') > body.rfind('.') { Mark::Comma } else { Mark::Point };
            match body.rsplit_once(last.char()) {
                Some((int, _)) if grouped(int, last.other().char()) => Shows::Decimal(last),
                _ => Shows::Neither,
            }
        }
        (1, 0) | (0, 1) => {
            let sep = if commas == 1 { ',' } else { '.' };
            let (int, frac) = body.split_once(sep).unwrap_or((body, ""));
            if !exponent && frac.len() == 3 && grouped(&format!("{int}{sep}{frac}"), sep) {
                Shows::Either(Mark::of(sep))
            } else {
                Shows::Decimal(Mark::of(sep))
            }
        }
        _ => {
            // Two or more of one kind: thousands separators, the other kind the decimal mark.
            let sep = if commas > 0 { ',' } else { '.' };
            if grouped(body, sep) {
                Shows::Decimal(Mark::of(sep).other())
            } else {
                Shows::Neither
            }
        }
    }
}

/// Where a cell was and what it held, for messages.
#[derive(Debug, Clone)]
struct Seen {
    line: u64,
    col: u64,
    text: String,
}

impl Seen {
    fn at(&self) -> String {
        format!("line {}, column {} (`{}`)", self.line, self.col, echo(&self.text))
    }
}

/// The decimal mark of a `;`- or tab-separated file, as its cells show it: read cell by cell,
/// the first cell that shows it settles it for the file.
#[derive(Debug, Default)]
pub struct DecimalMark {
    known: Option<(Mark, Seen)>,
    /// The first cell read as `,` decimal and the first as `.` decimal while the mark was not
    /// known (each could have been a thousands separator).
    either: [Option<Seen>; 2],
}

impl DecimalMark {
    /// The mark as the first rows of a file show it: `rows` are the lines after the header
    /// (`first_line` its number), `columns` the fields read. Cells that show nothing or are
    /// not numbers are passed over; the first that shows a mark settles it.
    pub fn sniffed(rows: &[u8], delimiter: u8, first_line: u64, columns: &[usize]) -> Self {
        let mut mark = Self::default();
        let text = String::from_utf8_lossy(rows);
        // The last line may be cut short: only whole lines count.
        let whole = text.rfind('\n').map_or("", |end| &text[..end]);
        for (n, line) in whole.lines().enumerate() {
            let cells: Vec<&str> = line.split(char::from(delimiter)).collect();
            for &c in columns {
                let cell = cells.get(c).map_or("", |s| s.trim().trim_matches('"').trim());
                if let Shows::Decimal(m) = shows(cell) {
                    let seen =
                        Seen { line: first_line + n as u64, col: c as u64 + 1, text: cell.to_string() };
                    mark.known = Some((m, seen));
                    return mark;
                }
            }
        }
        mark
    }

    /// The cell `text` (trimmed) at `line`, `col` (1-based) as `f64` syntax: the decimal mark a
    /// point, no thousands separators. A cell whose mark contradicts the file's is refused,
    /// naming the cell that showed the file's.
    pub fn normalise<'a>(&mut self, file: &str, line: u64, col: u64, text: &'a str) -> Result<Cow<'a, str>> {
        let seen = || Seen { line, col, text: text.to_string() };
        let mark = match shows(text) {
            Shows::Nothing | Shows::Neither => return Ok(Cow::Borrowed(text)),
            Shows::Decimal(m) => {
                match &self.known {
                    Some((k, first)) if *k != m => located!(file, Some(line), Some(col);
                        "`{}` has `{}` as its decimal mark, but {} has `{}`: the file mixes decimal marks, so \
                         either may be a thousands separator; export it with one decimal mark and no thousands \
                         separators", echo(text), m.char(), first.at(), k.char()),
                    Some(_) => {}
                    None => {
                        // A cell read earlier with the other mark as its decimal one was a
                        // thousands separator after all.
                        if let Some(first) = &self.either[m.other() as usize] {
                            located!(file, Some(first.line), Some(first.col);
                                "`{}` was read with `{}` as the decimal point, but {} shows that the file's \
                                 decimal mark is `{}`, where `{}` groups thousands; export the file with one \
                                 decimal mark and no thousands separators", echo(&first.text),
                                m.other().char(), seen().at(), m.char(), m.other().char());
                        }
                        self.known = Some((m, seen()));
                    }
                }
                m
            }
            Shows::Either(c) => match &self.known {
                Some((k, _)) => *k,
                None => {
                    if let Some(first) = &self.either[c.other() as usize] {
                        located!(file, Some(line), Some(col);
                            "`{}` and {} use different separators before three digits: one of them groups \
                             thousands, and which cannot be told; export the file with one decimal mark and no \
                             thousands separators", echo(text), first.at());
                    }
                    self.either[c as usize].get_or_insert_with(seen);
                    c
                }
            },
        };
        let thousands = mark.other().char();
        Ok(Cow::Owned(text.replace(thousands, "").replace(mark.char(), ".")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_differences_are_exact() {
        let d = |s: &str| Decimal::parse(s).unwrap();
        let step = d("1764633600.0001234").minus(d("1764633600.0000234")).unwrap();
        assert_eq!(step.to_f64(), 1e-4);
        assert_eq!(d("1.5e3").minus(d("1499.9")).unwrap().to_f64(), 0.1);
        assert_eq!(d("-.5").to_f64(), -0.5);
        assert_eq!(d("12.3").scaled(-3, true).to_f64(), -0.0123);
        assert_eq!(d("1.2300").resolution(), 1e-4);
        for bad in ["", ".", "1.2.3", "1,5", "e5", "0x10", "inf"] {
            assert!(Decimal::parse(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn epoch_stamps_become_offsets_from_the_first() {
        let mut s = Stamps::default();
        let text = ["1764633600.0001234", "1764633600.0002234", "1764633600.0003234"];
        let t: Vec<f64> = text.iter().map(|x| s.read(x, x.parse().unwrap(), 0, false).t).collect();
        assert_eq!(&t[1..], &[1e-4, 2e-4]);
        assert_eq!(s.origin(), Some("1764633600.0001234"));
        // A small origin is kept as it is.
        let mut s = Stamps::default();
        let t: Vec<f64> =
            ["0.5", "0.5001"].iter().map(|x| s.read(x, x.parse().unwrap(), 0, false).t).collect();
        assert_eq!(t, [0.5, 0.5001]);
        assert_eq!(s.origin(), None);
    }

    #[test]
    fn a_point_groups_thousands_only_where_the_file_has_a_decimal_comma() {
        let read = |cells: &[&str]| -> Result<Vec<String>> {
            let mut m = DecimalMark::default();
            cells
                .iter()
                .enumerate()
                .map(|(k, c)| Ok(m.normalise("de.csv", k as u64 + 2, 3, c)?.into_owned()))
                .collect()
        };
        assert_eq!(read(&["0,5", "1.234", "-12.345,5", "7"]).unwrap(), ["0.5", "1234", "-12345.5", "7"]);
        assert_eq!(read(&["0.5", "1,234", "1,234.5"]).unwrap(), ["0.5", "1234", "1234.5"]);
        let e = |cells: &[&str]| format!("{:#}", read(cells).unwrap_err());
        // A `.` that does not group three digits in a decimal-comma file is refused, not read.
        let msg = e(&["0,5", "1.23"]);
        assert!(msg.contains("de.csv:3:3") && msg.contains("mixes decimal marks"), "{msg}");
        // A cell read before the file showed its mark is named.
        let msg = e(&["1.234", "0,5"]);
        assert!(msg.starts_with("de.csv:2:3: `1.234` was read with `.` as the decimal point"), "{msg}");
        let msg = e(&["1.234", "1,234"]);
        assert!(msg.contains("de.csv:3:3") && msg.contains("which cannot be told"), "{msg}");
        // Sniffed from the first rows, the mark holds from the first cell on.
        let mut m = DecimalMark::sniffed(b"0;1.234\n0,1;2.345\n", b';', 2, &[0, 1]);
        assert_eq!(m.normalise("de.csv", 2, 2, "1.234").unwrap(), "1234");
    }
}
