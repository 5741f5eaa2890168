//! The hidden temporary files outputs are written to (`.gma-PID-START-XXXXXX.partial`), and the
//! removal of those a killed run left behind.
//!
//! A partial's name records its writer: the process id and, on Linux, the process's start time
//! (clock ticks after boot, `/proc/PID/stat`), so a pid the system has since given to another
//! process does not keep a dead writer's file alive. The first write into a folder removes the
//! partials there whose writer is no longer running. Conservative by design: only names of
//! exactly this form, only regular files, only when this system's `/proc` tells the writer is
//! gone (never elsewhere), and only files untouched for [`STALE_AFTER`] (a writer in another pid
//! namespace sharing the folder is still writing to its file).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

/// Every partial's name starts so.
const PREFIX: &str = ".gma-";
/// The ending of a partial's name.
pub const SUFFIX: &str = ".partial";
/// The ending of a PNG plot's partial (its encoder picks the format from the name).
pub const PNG_SUFFIX: &str = ".partial.png";
/// Random characters in each name (unique among one process's partials).
pub const RANDOM_CHARS: usize = 6;
/// How long a dead writer's partial must have been left untouched before it is removed.
pub const STALE_AFTER: Duration = Duration::from_secs(60);

/// The folders this process has already cleaned (once per folder, not once per file written).
static CLEANED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The start of this process's partials' names: `.gma-PID-START-` (START 0 where the system does
/// not tell it).
pub fn prefix() -> String {
    let pid = std::process::id();
    format!("{PREFIX}{pid}-{}-", start_time(pid).unwrap_or(0))
}

/// The writer (pid, start time) a partial's name records, or None for any other name.
pub fn writer_of(name: &str) -> Option<(u32, u64)> {
    let rest = name.strip_prefix(PREFIX)?;
    let (pid, rest) = rest.split_once('-')?;
    let (start, rest) = rest.split_once('-')?;
    let random = rest.get(..RANDOM_CHARS)?;
    let ending = &rest[RANDOM_CHARS..];
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let ends_right = [SUFFIX, PNG_SUFFIX].contains(&ending);
    if !(digits(pid) && digits(start) && random.bytes().all(|b| b.is_ascii_alphanumeric()) && ends_right) {
        return None;
    }
    Some((pid.parse().ok()?, start.parse().ok()?))
}

/// The start time of process `pid` [clock ticks after boot] (field 22 of `/proc/PID/stat`,
/// counted after the command name, which may hold spaces and parentheses).
fn start_time(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?.1.split_whitespace().nth(19)?.parse().ok()
}

/// Whether the writer a partial's name records has certainly ended: no process `pid`, or one
/// started at another time (the pid reused). Unknown is "running".
fn writer_ended(pid: u32, start: u64) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(e) => e.kind() == std::io::ErrorKind::NotFound,
        Ok(_) => start != 0 && start_time(pid).is_some_and(|now| now != start),
    }
}

/// Removes the partials in `dir` that killed writers left, the first time this process writes
/// there. Nothing is said when one cannot be removed: it is the next run's to try again.
pub fn remove_stale_once(dir: &Path) {
    let key = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut cleaned = CLEANED.lock().unwrap_or_else(|e| e.into_inner());
        if cleaned.contains(&key) {
            return;
        }
        cleaned.push(key);
    }
    remove_stale(dir);
}

/// Removes the partials in `dir` whose writer has ended and which have been untouched for
/// [`STALE_AFTER`]; the names removed. Only where `/proc` tells about processes (Linux): without
/// it no writer can be known to have ended.
pub fn remove_stale(dir: &Path) -> Vec<String> {
    if start_time(std::process::id()).is_none() {
        return Vec::new();
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().to_string();
        let Some((pid, start)) = writer_of(&name) else { continue };
        // symlink_metadata: a link or a folder with such a name is not a partial.
        let Ok(meta) = std::fs::symlink_metadata(entry.path()) else { continue };
        let untouched =
            meta.modified().ok().and_then(|m| m.elapsed().ok()).is_some_and(|age| age >= STALE_AFTER);
        if meta.is_file()
            && untouched
            && writer_ended(pid, start)
            && std::fs::remove_file(entry.path()).is_ok()
        {
            removed.push(name);
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_names_of_the_partial_form_name_a_writer() {
        assert_eq!(writer_of(".gma-4242-987654-aB3xY9.partial"), Some((4242, 987654)));
        assert_eq!(writer_of(".gma-4242-0-aB3xY9.partial.png"), Some((4242, 0)));
        for other in [
            ".gma-aB3xY9.partial",         // an older gma's: no writer recorded
            ".gma-4242-987654-aB3xY9.csv", // not a partial
            "gma-4242-987654-aB3xY9.partial",
            ".gma-4242-987654-aB3.partial",
            ".gma-42x2-987654-aB3xY9.partial",
            ".gma-4242-987654-aB3xY9.partial.",
            ".gma-4242-987654-aB3xY9.partial.bak", // not an ending gma writes
            ".gma-4242-987654-aB3xY9.partial.png.bak/",
            ".gma-4242-987654-aB3xY9.partialX",
        ] {
            assert_eq!(writer_of(other), None, "{other}");
        }
        let mine = format!("{}{}{SUFFIX}", prefix(), "Zz0123");
        let (pid, _) = writer_of(&mine).unwrap();
        assert_eq!(pid, std::process::id());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn this_process_is_running_and_a_reused_pid_is_not_its_writer() {
        let me = std::process::id();
        let start = start_time(me).unwrap();
        assert!(!writer_ended(me, start));
        assert!(writer_ended(me, start + 1), "the pid now names a process started at another time");
        assert!(!writer_ended(me, 0), "a writer of unknown start time on a live pid stays");
    }
}
