//! Where a result came from: the gma version, the command line, the seed, the date (UTC) and the
//! SHA-256 of every input as it was read ([`crate::digests`]).

use std::time::{SystemTime, UNIX_EPOCH};

use serde::Serialize;

use crate::digests::{input_digests, InputDigest};

/// Where a result came from.
#[derive(Debug, Clone, Serialize)]
pub struct Provenance {
    /// `gma` version (the host-sim crate's).
    pub gma_version: &'static str,
    /// The command line, one argument per element (argument 0 included).
    pub command_line: Vec<String>,
    /// Seed of the search or of the simulated noise, when the command has one.
    pub seed: Option<u64>,
    /// When the result was made: UTC, ISO 8601 to the second.
    pub date_utc: String,
    /// Every input, in the order opened.
    pub inputs: Vec<InputDigest>,
}

impl Provenance {
    /// This process's provenance, now.
    pub fn now(seed: Option<u64>) -> Self {
        Self {
            gma_version: env!("CARGO_PKG_VERSION"),
            command_line: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
            seed,
            date_utc: iso8601_utc(SystemTime::now()),
            inputs: input_digests(),
        }
    }

    /// The command line as one line (arguments with spaces or quotes quoted, control characters
    /// escaped).
    pub fn command(&self) -> String {
        let quote = |a: &String| {
            let a = crate::files::escape_control(a);
            if !a.is_empty() && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:+,@%".contains(c)) {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        };
        self.command_line.iter().map(quote).collect::<Vec<_>>().join(" ")
    }
}

/// `t` as `YYYY-MM-DDTHH:MM:SSZ` (proleptic Gregorian calendar, UTC).
pub fn iso8601_utc(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// Year, month, day of the `days`-th day after 1970-01-01 (Howard Hinnant's civil-from-days:
/// whole 400-year eras of 146 097 days, the year starting in March so leap days fall last).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn dates_match_known_calendar_days() {
        let at = |s: u64| iso8601_utc(UNIX_EPOCH + Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        // 2000-02-29 (a leap day of a century leap year) 12:34:56.
        assert_eq!(at(951_827_696), "2000-02-29T12:34:56Z");
        // 2100-03-01: 2100 is not a leap year.
        assert_eq!(at(4_107_542_400), "2100-03-01T00:00:00Z");
    }
}
