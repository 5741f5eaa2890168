//! Progress of long work on stderr: a bar on a terminal; off a terminal (a log file, CI, a
//! pipe) one line every few seconds, so a long fit is never silent and never floods a log.
//! [`to_sink`] hands the same lines to a caller instead (the Python API's `progress=`).

use std::io::IsTerminal as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Seconds between log lines off a terminal.
const LINE_EVERY: Duration = Duration::from_secs(5);

/// Where the lines go while [`to_sink`] runs (none: stderr).
static SINK: Mutex<Option<Say>> = Mutex::new(None);
/// Held while a sink is installed, so that one caller's lines never reach another's.
static SINK_OWNER: Mutex<()> = Mutex::new(());

/// Runs `f` with every progress line of the work it starts with progress enabled handed to
/// `say`, as lines (no terminal bar), instead of written to stderr. Calls that want a sink run
/// one at a time.
pub fn to_sink<T>(say: Say, f: impl FnOnce() -> T) -> T {
    struct Uninstall;
    impl Drop for Uninstall {
        fn drop(&mut self) {
            *SINK.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
    }
    let _owner = SINK_OWNER.lock().unwrap_or_else(|e| e.into_inner());
    *SINK.lock().unwrap_or_else(|e| e.into_inner()) = Some(say);
    let _uninstall = Uninstall;
    f()
}

/// The installed sink, if any.
fn sink() -> Option<Say> {
    SINK.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Lines to stderr.
fn stderr_lines() -> Say {
    Arc::new(|line: &str| eprintln!("{line}"))
}

/// Where work shown as lines writes them: the installed sink, else stderr off a terminal; none on
/// a terminal (there it gets a bar).
fn line_log() -> Option<Say> {
    sink().or_else(|| (!std::io::stderr().is_terminal()).then(stderr_lines))
}

/// A counter of planned work (`len` units, e.g. model evaluations) with a label.
pub struct Progress {
    kind: Kind,
}

enum Kind {
    Hidden,
    Bar(ProgressBar),
    Lines { label: String, len: u64, pos: AtomicU64, start: Instant, last: Mutex<Instant>, say: Say },
}

impl Progress {
    /// Progress of `label`; nothing is shown unless `enabled`.
    pub fn new(label: &str, len: u64, enabled: bool) -> Self {
        let kind = if !enabled {
            Kind::Hidden
        } else if let Some(say) = line_log() {
            say(&format!("gma: {label}: about {len} evaluations planned"));
            let now = Instant::now();
            Kind::Lines {
                label: label.into(),
                len,
                pos: AtomicU64::new(0),
                start: now,
                last: Mutex::new(now),
                say,
            }
        } else {
            let b = ProgressBar::new(len);
            b.set_style(
                ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} evaluations, {elapsed}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b.set_message(label.to_string());
            Kind::Bar(b)
        };
        Self { kind }
    }

    /// One more unit done.
    pub fn inc(&self, n: u64) {
        match &self.kind {
            Kind::Hidden => {}
            Kind::Bar(b) => b.inc(n),
            Kind::Lines { label, len, pos, start, last, say } => {
                let p = pos.fetch_add(n, Ordering::Relaxed) + n;
                let Ok(mut last) = last.try_lock() else { return };
                if last.elapsed() >= LINE_EVERY {
                    *last = Instant::now();
                    say(&format!(
                        "gma: {label}: {p}/{len} evaluations, {:.0} s",
                        start.elapsed().as_secs_f64()
                    ));
                }
            }
        }
    }

    /// Done: the bar is cleared, or the log gets its last line (the caller reports the result).
    pub fn finish_and_clear(&self) {
        match &self.kind {
            Kind::Hidden => {}
            Kind::Bar(b) => b.finish_and_clear(),
            Kind::Lines { label, pos, start, say, .. } => say(&format!(
                "gma: {label}: done, {} evaluations in {:.1} s",
                pos.load(Ordering::Relaxed),
                start.elapsed().as_secs_f64()
            )),
        }
    }
}

/// A phase of long work starting or ending, as one line on stderr or to the sink (when `enabled`).
pub fn phase(enabled: bool, text: &str) {
    if enabled {
        sink().unwrap_or_else(stderr_lines)(&format!("gma: {text}"));
    }
}

/// A phase of long work that has no evaluation counter of its own (refits in parallel, the
/// uncertainty, drawing a report): off a terminal a start line, a line every [`LINE_EVERY`]
/// while it runs (steps done, time) and a done line; on a terminal a spinner. Nothing when not
/// `enabled`.
pub struct Phase {
    label: String,
    steps: u64,
    done: Arc<AtomicU64>,
    start: Instant,
    show: Show,
}

enum Show {
    Hidden,
    Bar(ProgressBar),
    /// Where lines go, and the heartbeat thread (dropping the sender stops it).
    Lines(Say, Option<(mpsc::Sender<()>, std::thread::JoinHandle<()>)>),
}

/// Where a line log goes (stderr, a [`to_sink`] caller's; a buffer in tests).
pub type Say = Arc<dyn Fn(&str) + Send + Sync>;

impl Phase {
    /// Starts `label`, a phase of `steps` steps (0: not counted).
    pub fn start(enabled: bool, label: &str, steps: u64) -> Self {
        if let Some(say) = enabled.then(line_log).flatten() {
            return Self::lines(label, steps, LINE_EVERY, say);
        }
        let show = if enabled {
            let b = if steps > 0 { ProgressBar::new(steps) } else { ProgressBar::new_spinner() };
            let template = if steps > 0 {
                "{msg} [{bar:30}] {pos}/{len}, {elapsed}"
            } else {
                "{spinner} {msg}, {elapsed}"
            };
            b.set_style(
                ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b.set_message(label.to_string());
            b.enable_steady_tick(Duration::from_millis(200));
            Show::Bar(b)
        } else {
            Show::Hidden
        };
        let (done, start) = (Arc::new(AtomicU64::new(0)), Instant::now());
        Self { label: label.into(), steps, done, start, show }
    }

    /// The line log: a start line, a line every `every` with the steps done, then (from
    /// [`Phase::finish`]) a done line, each handed to `say`.
    fn lines(label: &str, steps: u64, every: Duration, say: Say) -> Self {
        let (done, start) = (Arc::new(AtomicU64::new(0)), Instant::now());
        say(&format!("gma: {label}: started"));
        let (tx, rx) = mpsc::channel::<()>();
        let (l, d, beat_say) = (label.to_string(), done.clone(), say.clone());
        let beat = std::thread::spawn(move || {
            while let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(every) {
                let counted = if steps > 0 {
                    format!("{}/{steps} done, ", d.load(Ordering::Relaxed))
                } else {
                    String::new()
                };
                beat_say(&format!("gma: {l}: {counted}{:.0} s", start.elapsed().as_secs_f64()));
            }
        });
        Self { label: label.into(), steps, done, start, show: Show::Lines(say, Some((tx, beat))) }
    }

    /// One step done; `note` (if not empty) is said on its own line.
    pub fn step(&self, note: &str) {
        let k = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        match &self.show {
            Show::Hidden => {}
            Show::Bar(b) => {
                b.set_position(k);
                if !note.is_empty() {
                    b.println(format!("gma: {note}"));
                }
            }
            Show::Lines(say, _) => {
                if !note.is_empty() {
                    say(&format!("gma: {note}"));
                }
            }
        }
    }

    /// Done: the done line (or the spinner cleared) with the phase's time.
    pub fn finish(mut self) {
        self.stop();
        match &self.show {
            Show::Hidden => {}
            Show::Bar(b) => b.finish_and_clear(),
            Show::Lines(say, _) => {
                let counted = if self.steps > 0 {
                    format!("{}/{} ", self.done.load(Ordering::Relaxed), self.steps)
                } else {
                    String::new()
                };
                say(&format!(
                    "gma: {}: done {counted}in {:.1} s",
                    self.label,
                    self.start.elapsed().as_secs_f64()
                ));
            }
        }
    }

    /// Stops the heartbeat (and waits for it, so no line comes after the phase ended).
    fn stop(&mut self) {
        if let Show::Lines(_, beat) = &mut self.show {
            if let Some((tx, handle)) = beat.take() {
                drop(tx);
                let _ = handle.join();
            }
        }
    }
}

impl Drop for Phase {
    /// A phase left by an error stops its heartbeat too (the error says what happened).
    fn drop(&mut self) {
        self.stop();
        if let Show::Bar(b) = &self.show {
            b.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_log_has_a_start_a_heartbeat_with_the_count_and_a_done_line() {
        let log = Arc::new(Mutex::new(Vec::<String>::new()));
        let sink = log.clone();
        let say: Say = Arc::new(move |l: &str| sink.lock().unwrap().push(l.to_string()));
        let phase = Phase::lines("refits", 3, Duration::from_millis(10), say);
        phase.step("refit 1 done");
        std::thread::sleep(Duration::from_millis(200));
        phase.step("");
        phase.finish();
        let log = log.lock().unwrap().clone();
        assert_eq!(log.first().map(String::as_str), Some("gma: refits: started"), "{log:?}");
        assert!(log.contains(&"gma: refit 1 done".to_string()), "{log:?}");
        assert!(log.iter().any(|l| l.starts_with("gma: refits: 1/3 done, ")), "no heartbeat: {log:?}");
        let last = log.last().unwrap();
        assert!(last.starts_with("gma: refits: done 2/3 in "), "{log:?}");
        // Nothing after the done line: the heartbeat stopped with the phase.
        assert_eq!(log.iter().filter(|l| l.contains("done 2/3")).count(), 1);
    }

    /// While a sink is installed every kind of progress goes to it as lines, and only work
    /// started with progress enabled; after it, nothing more reaches it.
    #[test]
    fn a_sink_takes_the_lines_of_enabled_work_only_and_only_while_installed() {
        let log = Arc::new(Mutex::new(Vec::<String>::new()));
        let sink = log.clone();
        let say: Say = Arc::new(move |l: &str| sink.lock().unwrap().push(l.to_string()));
        let counted = to_sink(say, || {
            phase(true, "diagnose: fitting");
            phase(false, "not asked for");
            let bar = Progress::new("fitting ja", 10, true);
            bar.inc(10);
            bar.finish_and_clear();
            Progress::new("quiet", 10, false).finish_and_clear();
            Phase::start(true, "refits", 2).finish();
            7
        });
        assert_eq!(counted, 7);
        phase(true, "after the sink (to stderr)");
        let log = log.lock().unwrap().clone();
        // In this order (a slow machine may add a heartbeat line between them).
        let expected = [
            "gma: diagnose: fitting",
            "gma: fitting ja: about 10 evaluations planned",
            "gma: fitting ja: done, 10 evaluations in",
            "gma: refits: started",
            "gma: refits: done 0/2 in",
        ];
        let mut lines = log.iter();
        for start in expected {
            assert!(lines.any(|l| l.starts_with(start)), "no {start:?} in order: {log:?}");
        }
        for absent in ["not asked for", "quiet", "after the sink"] {
            assert!(!log.iter().any(|l| l.contains(absent)), "{absent:?} reached the sink: {log:?}");
        }
    }
}
