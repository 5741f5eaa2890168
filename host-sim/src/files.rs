//! Inputs and outputs of the workbench, in one place so every command treats them alike.
//!
//! Inputs are opened once and read once, as streams: a file, standard input (`-`), a pipe or a
//! FIFO give the same result. Lines are bounded ([`MAX_LINE_BYTES`]), so a file without newlines
//! (`/dev/zero`, a one-row gigabyte) is refused instead of read into memory.
//!
//! Outputs are checked before any work ([`check_outputs`]): the folder exists and is writable,
//! the path is a regular file or new, and it is not one of the inputs. They are written to a
//! unique hidden temporary file beside the target and renamed into place ([`write_atomic`]), so
//! a reader, a crash or a concurrent run never sees a half-written result, and a command that
//! fails never replaces an existing output. An output path `-` is standard output
//! ([`is_stdout`]); the temporary files of killed runs are removed by the next write into their
//! folder ([`crate::partials`]).

use std::io::{BufRead, Read, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{bail, Context, Result};

use crate::error::Located;

/// Longest line accepted in any text input [bytes]: measurement rows have a handful of numbers,
/// parameter files short assignments.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// Longest cell echoed back in a message [characters]; longer ones are cut with `…`.
const MAX_ECHO_CHARS: usize = 40;

/// Whether standard input has been handed out (it can be read only once).
static STDIN_TAKEN: AtomicBool = AtomicBool::new(false);

/// What identifies an input once it has been consumed: its name and (for a regular file) its
/// device and inode, so that no output replaces it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputId {
    /// As in messages.
    pub name: String,
    /// (device, inode) of a regular file.
    pub identity: Option<(u64, u64)>,
}

/// An opened input: its name for messages and a reader that yields its bytes once.
pub struct Input {
    /// `path` as given, or `<stdin>` for `-`.
    pub name: String,
    /// The first line, already read (the format is sniffed from it), then the rest.
    head: Vec<u8>,
    rest: std::io::BufReader<LineBounded<Box<dyn Read + Send>>>,
    /// Identity of a regular file (device, inode), to refuse writing over an input.
    pub identity: Option<(u64, u64)>,
    /// The digest of its bytes as they are read.
    digest: crate::digests::Digest,
}

impl Input {
    /// Opens `path` (`-` is standard input) and reads its first line.
    pub fn open(path: &Path) -> Result<Self> {
        let (name, reader, identity): (String, Box<dyn Read + Send>, _) = if path == Path::new("-") {
            if STDIN_TAKEN.swap(true, Ordering::SeqCst) {
                bail!("`-` (standard input) is given more than once; it can be read only once");
            }
            ("<stdin>".into(), Box::new(std::io::stdin()), None)
        } else {
            let name = display(path);
            let meta = std::fs::metadata(path).map_err(|e| cannot_read(&name, &e))?;
            if meta.is_dir() {
                return Err(Located::file(&name, "is a folder, not a file").into());
            }
            let f = std::fs::File::open(path).map_err(|e| cannot_read(&name, &e))?;
            (name, Box::new(f), identity(&meta))
        };
        // Hashed as it streams (provenance), the first line (with its newline) bounded like
        // every other line.
        let hashing = crate::digests::hashing(&name, reader);
        let digest = hashing.digest();
        let reader: Box<dyn Read + Send> = Box::new(hashing);
        let mut rest = std::io::BufReader::with_capacity(1 << 16, LineBounded::new(reader));
        let mut head = Vec::new();
        rest.read_until(b'\n', &mut head).map_err(|e| read_error(&name, e))?;
        Ok(Self { name, head, rest, identity, digest })
    }

    /// Its digest, kept after the input is read (final once it has been read to its end).
    pub fn digest(&self) -> crate::digests::Digest {
        self.digest.clone()
    }

    /// Its name and identity, kept after the input is read.
    pub fn id(&self) -> InputId {
        InputId { name: self.name.clone(), identity: self.identity }
    }

    /// The first line as text (lossy; for sniffing the format).
    pub fn first_line(&self) -> String {
        let line = self.head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&self.head);
        String::from_utf8_lossy(line).trim_end_matches(['\r', '\n']).to_string()
    }

    /// The whole input as a byte stream (the first line included).
    pub fn into_reader(self) -> impl BufRead + Send {
        std::io::Cursor::new(self.head).chain(self.rest)
    }

    /// The whole input as UTF-8 text, at most `max_bytes` of it (parameter files, loop files).
    /// Each line is checked as it arrives, so a binary stream is refused at its first bad line
    /// rather than after `max_bytes` of it.
    pub fn into_text(self, max_bytes: u64) -> Result<String> {
        let name = self.name.clone();
        let mut reader = self.into_reader();
        let mut text = String::new();
        let mut line = Vec::new();
        for number in 1u64.. {
            line.clear();
            if reader.read_until(b'\n', &mut line).map_err(|e| read_error(&name, e))? == 0 {
                break;
            }
            if (text.len() + line.len()) as u64 > max_bytes {
                let what = format!("larger than {} MB; this is not a file of this kind", max_bytes >> 20);
                return Err(Located::file(&name, what).into());
            }
            let bytes = if number == 1 { line.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&line) } else { &line };
            let Ok(s) = std::str::from_utf8(bytes) else {
                return Err(Located::at(
                    &name,
                    number,
                    None,
                    "not UTF-8 text (a binary file, or a text encoding other than UTF-8?)",
                )
                .into());
            };
            text.push_str(s);
        }
        Ok(text)
    }
}

/// The (device, inode) pair of a file.
#[cfg(unix)]
fn identity(meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    meta.is_file().then(|| (meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn identity(_meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// A read error as a message naming the input (a too-long line keeps its line number).
pub fn read_error(name: &str, e: std::io::Error) -> anyhow::Error {
    match e.get_ref().and_then(|inner| inner.downcast_ref::<LineTooLong>()) {
        Some(l) => Located::at(
            name,
            l.line,
            None,
            format!(
                "line longer than {} KiB (no line breaks: a binary file, or not a text export?)",
                MAX_LINE_BYTES / 1024
            ),
        )
        .into(),
        None => cannot_read(name, &e),
    }
}

/// A file that cannot be opened or read, located at the file (`--json`'s `file`).
pub fn cannot_read(name: &str, e: &std::io::Error) -> anyhow::Error {
    Located::file(name, format!("cannot read: {e}")).into()
}

/// A line over [`MAX_LINE_BYTES`], carried inside an `io::Error`.
#[derive(Debug)]
struct LineTooLong {
    line: u64,
}

impl std::fmt::Display for LineTooLong {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {} is longer than {} bytes", self.line, MAX_LINE_BYTES)
    }
}

impl std::error::Error for LineTooLong {}

/// A reader that fails as soon as one line exceeds [`MAX_LINE_BYTES`].
struct LineBounded<R> {
    inner: R,
    line: u64,
    in_line: usize,
}

impl<R> LineBounded<R> {
    fn new(inner: R) -> Self {
        Self { inner, line: 1, in_line: 0 }
    }
}

impl<R: Read> Read for LineBounded<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        for &b in &buf[..n] {
            if b == b'\n' {
                self.line += 1;
                self.in_line = 0;
            } else {
                self.in_line += 1;
                if self.in_line > MAX_LINE_BYTES {
                    return Err(std::io::Error::new(
                        std::io::ErrorKind::InvalidData,
                        LineTooLong { line: self.line },
                    ));
                }
            }
        }
        Ok(n)
    }
}

/// Opens every path, in order.
pub fn open_all(paths: &[PathBuf]) -> Result<Vec<Input>> {
    paths.iter().map(|p| Input::open(p)).collect()
}

/// A path as messages print it (control characters escaped).
pub fn display(path: &Path) -> String {
    escape_control(&path.display().to_string())
}

/// A path as a printed command line needs it: as [`display`] prints it (control characters
/// escaped, so such a path is shown, not reproduced), in single quotes when it holds anything a
/// POSIX shell would split or expand (a space, `$`, `*`, a quote, a leading `=` or `~`, …), and
/// after `./` when it starts with `-` (else an option to the command).
pub fn shell_word(path: &Path) -> String {
    let s = display(path);
    let s = if s.starts_with('-') { format!("./{s}") } else { s };
    let plain = |c: char| c.is_alphanumeric() || "_-./:@%+=,".contains(c);
    if !s.is_empty() && !s.starts_with('=') && s.chars().all(plain) {
        s
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// `s` with control characters (ESC, BEL, CR, …; not newlines) written as escapes, so nothing
/// from an input can drive the terminal.
pub fn escape_control(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_control() && c != '\n' {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// Characters a quoted cell writes as escapes though a terminal prints them: invisible ones
/// (zero-width space, a byte-order mark, a soft hyphen) and Greek and Cyrillic letters, which look
/// like Latin ones or the micro sign µ: two names that differ only in them must not print alike
/// (`x/µm` and `x/\u{3bc}m`, Greek mu).
fn looks_like_another(c: char) -> bool {
    matches!(c, '\u{ad}' | '\u{200b}'..='\u{200f}' | '\u{2060}'..='\u{2064}' | '\u{feff}' | '\u{370}'..='\u{4ff}')
}

/// A number as a person typed it when that is short (`0.5`, `12`), else in six-digit
/// scientific form: `1e308` must not come back as 309 digits.
pub fn short_number(x: f64) -> String {
    let plain = x.to_string();
    if plain.len() <= 16 {
        plain
    } else {
        format!("{x:.6e}")
    }
}

/// A cell from an input as a message quotes it: control characters and look-alikes escaped, cut
/// to [`MAX_ECHO_CHARS`].
pub fn echo(cell: &str) -> String {
    let mut s: String = cell
        .chars()
        .take(MAX_ECHO_CHARS)
        .flat_map(|c| {
            let escaped = looks_like_another(c).then(|| c.escape_unicode().to_string());
            escaped.unwrap_or_else(|| c.to_string()).chars().collect::<Vec<_>>()
        })
        .collect();
    if cell.chars().nth(MAX_ECHO_CHARS).is_some() {
        s.push('…');
    }
    escape_control(&s)
}

/// Checks, before any work, that every output can be written and loses nothing: its folder
/// exists and takes a new file, it is new or a regular file (not a link, a device, a FIFO or a
/// folder: outputs are replaced by a rename, which would swap such a thing for a file), and it
/// is not one of `inputs`.
pub fn check_outputs(outputs: &[&Path], inputs: &[InputId]) -> Result<()> {
    let mut seen: Vec<PathBuf> = Vec::new();
    let mut stdout_named = false;
    for &path in outputs {
        if is_stdout(path) {
            if std::mem::replace(&mut stdout_named, true) {
                bail!("`-` (standard output) is named as an output twice; it can take only one");
            }
            continue;
        }
        let name = display(path);
        let dir = output_dir(path);
        if !dir.is_dir() {
            bail!("cannot write {name}: the folder {} does not exist", display(dir));
        }
        match std::fs::symlink_metadata(path) {
            Ok(meta) => {
                let kind = meta.file_type();
                if kind.is_dir() {
                    bail!("cannot write {name}: it is a folder");
                }
                if !kind.is_file() {
                    let what = if kind.is_symlink() {
                        "a symbolic link"
                    } else {
                        "not a regular file (a device, FIFO or socket)"
                    };
                    bail!(
                        "cannot write {name}: it is {what}; gma writes results as new regular files \
                         (temporary file, then rename), which would replace it — give the path of a regular file"
                    );
                }
                if let Some(id) = identity(&meta) {
                    if let Some(input) = inputs.iter().find(|i| i.identity == Some(id)) {
                        bail!(
                            "cannot write {name}: it is the input {}; choose another output path",
                            input.name
                        );
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => bail!("cannot write {name}: {e}"),
        }
        // The same output twice in one command would lose the first.
        let key = dir
            .canonicalize()
            .unwrap_or_else(|_| dir.to_path_buf())
            .join(path.file_name().unwrap_or_default());
        if seen.contains(&key) {
            bail!("{name} is named as an output twice");
        }
        seen.push(key);
        // Writable: a temporary file can be created beside it.
        drop(partial_file(dir)?);
    }
    Ok(())
}

/// What an output holds, for [`replaces_only`]: an existing file is replaced only by one of its
/// own kind, so that a measurement named as an output by mistake is never lost.
#[derive(Clone, Copy, Debug)]
pub enum OutputKind {
    /// A parameter file (`fit --params-out`): it must read as TOML.
    ParameterFile,
    /// An HTML page (`report -o`): it must start as one.
    HtmlPage,
    /// `compare --out-csv`'s table: its header starts `file,time_s,measured_`.
    ComparisonTable,
    /// A recording's CSV (`simulate -o`): the same kind as a measurement, so never replaced
    /// unless the user says so (`--overwrite`).
    Recording {
        /// The user said an existing file may go (`--overwrite`).
        overwrite: bool,
    },
}

/// Refuses to replace an existing regular file at `out` (named by the option `flag`) that is not
/// of `kind`; a new path, standard output or a file of that kind passes. Reads at most the first
/// mebibyte: a file larger than that is no parameter file, page header or table header.
pub fn replaces_only(out: &Path, kind: OutputKind, flag: &str) -> Result<()> {
    if is_stdout(out) {
        return Ok(());
    }
    let Ok(meta) = std::fs::metadata(out) else { return Ok(()) };
    if !meta.is_file() {
        return Ok(()); // `check_outputs` says what it is
    }
    let head = || -> String {
        let mut buf = Vec::new();
        let read = std::fs::File::open(out).and_then(|f| f.take(1 << 20).read_to_end(&mut buf));
        if read.is_err() {
            buf.clear();
        }
        String::from_utf8_lossy(&buf).trim_start_matches('\u{feff}').trim_start().to_string()
    };
    let (is_kind, what) = match kind {
        OutputKind::ParameterFile => (
            meta.len() <= 1 << 20 && head().parse::<toml::Table>().is_ok(),
            "a parameter file (it does not read as TOML)",
        ),
        OutputKind::HtmlPage => {
            let h = head().get(..14).unwrap_or_default().to_ascii_lowercase();
            (h.starts_with("<!doctype html") || h.starts_with("<html"), "an HTML page")
        }
        OutputKind::ComparisonTable => {
            (head().starts_with("file,time_s,measured_"), "a table `gma compare --out-csv` wrote")
        }
        OutputKind::Recording { overwrite } => {
            if overwrite {
                return Ok(());
            }
            bail!(
                "{flag} {}: the file exists, and gma cannot tell a recording it simulated from a measurement \
                 (the same columns), so it will not replace it; give --overwrite to replace it, or choose \
                 another path",
                display(out)
            );
        }
    };
    if !is_kind {
        bail!(
            "{flag} {}: the file exists and is not {what}, so gma will not replace it (a measurement named as \
             the output by mistake would be lost); remove it first or choose another path",
            display(out)
        );
    }
    Ok(())
}

/// Creates `dir` (and its parents) for outputs, and checks that it takes new files. The folders
/// it made are removed again, if still empty, unless [`OutputFolder::keep`] is called: a command
/// that fails on its second input leaves no empty folder behind.
pub fn output_folder(dir: &Path) -> Result<OutputFolder> {
    let made: Vec<PathBuf> = dir
        .ancestors()
        .take_while(|d| !d.as_os_str().is_empty() && !d.exists())
        .map(Path::to_path_buf)
        .collect();
    let folder = OutputFolder { made };
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create the folder {}", display(dir)))?;
    drop(partial_file(dir)?);
    Ok(folder)
}

/// The folders [`output_folder`] made, innermost first; removed on drop while empty.
#[must_use = "the folder is removed again when this is dropped without `keep`"]
pub struct OutputFolder {
    made: Vec<PathBuf>,
}

impl OutputFolder {
    /// The command succeeded: the folder stays.
    pub fn keep(mut self) {
        self.made.clear();
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        for d in &self.made {
            // Only an empty folder is removed; the first that is not ends the walk.
            if std::fs::remove_dir(d).is_err() {
                break;
            }
        }
    }
}

/// Whether an output path is `-`: standard output, as `-` is standard input for inputs.
pub fn is_stdout(path: &Path) -> bool {
    path == Path::new("-")
}

/// Whether `option`'s `path` is `-` (standard output); refused with `--json`, whose one object
/// stdout carries.
pub fn to_stdout(option: &str, path: &Path, json: bool) -> Result<bool> {
    if is_stdout(path) && json {
        bail!(
            "{option} -: standard output carries the --json object, and cannot take the output too; \
             give {option} a file name, or leave out --json"
        );
    }
    Ok(is_stdout(path))
}

/// Refuses `-` for an option that names `what` (a folder, a set of files): standard output takes
/// one document.
pub fn no_stdout(option: &str, path: &Path, what: &str) -> Result<()> {
    if is_stdout(path) {
        bail!("{option} -: {option} names {what}, and standard output (`-`) takes a single document");
    }
    Ok(())
}

/// An output as it is written: a temporary file beside its target, or standard output (`-`).
pub enum OutputWriter {
    /// Renamed onto the target by [`OutputWriter::finish`].
    Partial(tempfile::NamedTempFile),
    /// Written through as it comes.
    Stdout(std::io::Stdout),
}

impl OutputWriter {
    /// Starts writing `path` (`-`: standard output).
    pub fn create(path: &Path) -> Result<Self> {
        Ok(if is_stdout(path) {
            Self::Stdout(std::io::stdout())
        } else {
            Self::Partial(partial_file(output_dir(path))?)
        })
    }

    /// Puts the finished output in place: the rename, or the last bytes flushed to stdout.
    pub fn finish(self, path: &Path) -> Result<()> {
        match self {
            Self::Partial(tmp) => persist(tmp, path),
            Self::Stdout(mut out) => out.flush().map_err(stdout_error),
        }
    }
}

impl std::io::Write for OutputWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Self::Partial(tmp) => tmp.write(buf),
            Self::Stdout(out) => out.write(buf).map_err(stdout_gone),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Self::Partial(tmp) => tmp.flush(),
            Self::Stdout(out) => out.flush().map_err(stdout_gone),
        }
    }
}

/// A reader that went away (`gma … -o - | head`) ends the command quietly, as for text
/// ([`crate::cli::print_line`]); any other error is handed back.
fn stdout_gone(e: std::io::Error) -> std::io::Error {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    e
}

/// An error writing to standard output, as a message.
fn stdout_error(e: std::io::Error) -> anyhow::Error {
    anyhow::anyhow!("writing to standard output: {}", stdout_gone(e))
}

/// Writes `bytes` to `path` through a temporary file and a rename, so that readers never see a
/// half-written file; `-` writes them to standard output.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut out = OutputWriter::create(path)?;
    match out.write_all(bytes) {
        Err(e) if is_stdout(path) => Err(stdout_error(e)),
        r => r.with_context(|| format!("writing {}", display(path))),
    }?;
    out.finish(path)
}

/// The folder `path` is written into (`.` for a bare file name).
pub fn output_dir(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// A temporary file in `dir` for an output being written (`.gma-PID-START-XXXXXX.partial`, a
/// unique name: a run killed mid-write leaves one of these, never a truncated result under the
/// final name, and concurrent runs never share one). The name records the writing process, so
/// the first write into `dir` removes the partials of writers no longer running.
pub fn partial_file(dir: &Path) -> Result<tempfile::NamedTempFile> {
    partial_file_with_suffix(dir, crate::partials::SUFFIX)
}

/// As [`partial_file`], with another of the endings [`crate::partials`] knows (an encoder may
/// need the target's extension: [`crate::partials::PNG_SUFFIX`]).
pub fn partial_file_with_suffix(dir: &Path, suffix: &str) -> Result<tempfile::NamedTempFile> {
    crate::partials::remove_stale_once(dir);
    tempfile::Builder::new()
        .prefix(&crate::partials::prefix())
        .rand_bytes(crate::partials::RANDOM_CHARS)
        .suffix(suffix)
        .tempfile_in(dir)
        .with_context(|| {
            format!("cannot create a file in {} (does it exist, and may it be written?)", display(dir))
        })
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
    // The rename's own error, once (a `PersistError` prints it and names it again as its source).
    tmp.persist(path).map_err(|e| e.error).with_context(|| format!("cannot write {}", display(path)))?;
    Ok(())
}

/// File stems for per-input outputs (plots), unique even when two inputs share a name in
/// different folders (`x`, `x-2`, …), and `input` for standard input.
pub fn unique_stems(paths: &[PathBuf]) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(paths.len());
    for p in paths {
        let stem = if p == Path::new("-") {
            "stdin".to_string()
        } else {
            p.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "file".into())
        };
        let mut candidate = stem.clone();
        let mut k = 2;
        while out.contains(&candidate) {
            candidate = format!("{stem}-{k}");
            k += 1;
        }
        out.push(candidate);
    }
    out
}

/// A path list as the CLI prints it.
pub fn names(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| display(p)).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn printed_command_words_survive_a_shell() {
        assert_eq!(shell_word(Path::new("gma-demo/demo-fit1.csv")), "gma-demo/demo-fit1.csv");
        assert_eq!(shell_word(Path::new("my runs/a.csv")), "'my runs/a.csv'");
        assert_eq!(shell_word(Path::new("it's/$x.csv")), r"'it'\''s/$x.csv'");
        assert_eq!(shell_word(Path::new("")), "''");
        assert_eq!(shell_word(Path::new("-out/a.csv")), "./-out/a.csv");
        assert_eq!(shell_word(Path::new("=x")), "'=x'");
    }

    #[test]
    fn a_line_without_end_is_refused_with_its_line_number() {
        let mut r = LineBounded::new(std::io::repeat(b'7').take(10 * MAX_LINE_BYTES as u64));
        let mut sink = Vec::new();
        let e = r.read_to_end(&mut sink).unwrap_err();
        let msg = read_error("zeros", e).to_string();
        assert!(msg.starts_with("zeros:1: line longer than 64 KiB"), "{msg}");
        assert!(sink.len() <= 2 * MAX_LINE_BYTES, "read {} bytes before refusing", sink.len());
    }

    #[test]
    fn control_characters_are_escaped_and_long_cells_cut() {
        assert_eq!(escape_control("a\u{1b}[31mb\u{7}"), "a\\u{1b}[31mb\\u{7}");
        let long = "x".repeat(100);
        assert_eq!(echo(&long).chars().count(), MAX_ECHO_CHARS + 1);
    }

    #[test]
    fn standard_output_takes_one_output_and_no_file_checks() {
        let dash = Path::new("-");
        check_outputs(&[dash], &[]).unwrap();
        let e = check_outputs(&[dash, Path::new("a.csv"), dash], &[]).unwrap_err().to_string();
        assert!(e.contains("`-` (standard output) is named as an output twice"), "{e}");
    }

    #[test]
    fn stems_are_unique_per_input() {
        let p = |s: &str| PathBuf::from(s);
        let stems = unique_stems(&[p("a/x.csv"), p("b/x.csv"), p("x-2.csv"), p("-")]);
        assert_eq!(stems, ["x", "x-2", "x-2-2", "stdin"]);
    }
}
