//! Progress of long work on stderr: a bar on a terminal; off a terminal (a log file, CI, a
//! pipe) one line every few seconds, so a long fit is never silent and never floods a log.

use std::io::IsTerminal as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Seconds between log lines off a terminal.
const LINE_EVERY: Duration = Duration::from_secs(5);

/// A counter of planned work (`len` units, e.g. model evaluations) with a label.
pub struct Progress {
    kind: Kind,
}

enum Kind {
    Hidden,
    Bar(ProgressBar),
    Lines { label: String, len: u64, pos: AtomicU64, start: Instant, last: Mutex<Instant> },
}

impl Progress {
    /// Progress of `label`; nothing is shown unless `enabled`.
    pub fn new(label: &str, len: u64, enabled: bool) -> Self {
        let kind = if !enabled {
            Kind::Hidden
        } else if std::io::stderr().is_terminal() {
            let b = ProgressBar::new(len);
            b.set_style(
                ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} evaluations, {elapsed}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b.set_message(label.to_string());
            Kind::Bar(b)
        } else {
            eprintln!("gma: {label}: up to {len} evaluations planned");
            let now = Instant::now();
            Kind::Lines {
                label: label.into(),
                len,
                pos: AtomicU64::new(0),
                start: now,
                last: Mutex::new(now),
            }
        };
        Self { kind }
    }

    /// One more unit done.
    pub fn inc(&self, n: u64) {
        match &self.kind {
            Kind::Hidden => {}
            Kind::Bar(b) => b.inc(n),
            Kind::Lines { label, len, pos, start, last } => {
                let p = pos.fetch_add(n, Ordering::Relaxed) + n;
                let Ok(mut last) = last.try_lock() else { return };
                if last.elapsed() >= LINE_EVERY {
                    *last = Instant::now();
                    eprintln!("gma: {label}: {p}/{len} evaluations, {:.0} s", start.elapsed().as_secs_f64());
                }
            }
        }
    }

    /// Done: the bar is cleared, or the log gets its last line (the caller reports the result).
    pub fn finish_and_clear(&self) {
        match &self.kind {
            Kind::Hidden => {}
            Kind::Bar(b) => b.finish_and_clear(),
            Kind::Lines { label, pos, start, .. } => eprintln!(
                "gma: {label}: done, {} evaluations in {:.1} s",
                pos.load(Ordering::Relaxed),
                start.elapsed().as_secs_f64()
            ),
        }
    }
}

/// A phase of long work starting or ending, as one line on stderr (when `enabled`).
pub fn phase(enabled: bool, text: &str) {
    if enabled {
        eprintln!("gma: {text}");
    }
}
