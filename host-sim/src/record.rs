//! `gma record`: the drive's telemetry stream (COBS frames from the board's UART, captured to a
//! file or piped in) to measurement CSVs. Lost and corrupt frames are counted and reported; a
//! gap in the sequence numbers starts a new file, because a recording's time axis must be
//! uniform (never a silently stitched one).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use gma_control::telemetry::Decoder;

/// What a stream held.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RecordSummary {
    /// Frames decoded (CRC valid).
    pub frames: u64,
    /// Frames missing from the sequence.
    pub lost: u64,
    /// Chunks that failed the COBS, length or CRC check (never written).
    pub corrupt: u64,
    /// The drive's command replies, which share its telemetry line (skipped, not errors).
    pub replies: u64,
    /// CRC-valid frames carrying a non-finite value (never written; they end a segment).
    pub invalid: u64,
    /// Times the sequence restarted (the board was reset).
    pub restarts: u64,
    /// Frames in segments too short to be a recording (fewer than 3), counted, not written.
    pub short: u64,
    /// Files written (one per gap-free segment).
    pub files: Vec<PathBuf>,
    /// Why the recording ended.
    pub ending: Ending,
}

/// The recordings a run writing `out` would replace: `out` itself and every `stem-N.csv` beside
/// it (the segments after gaps, [`segment_path`]), that exist now.
pub fn existing_segments(out: &Path) -> Vec<PathBuf> {
    let stem = out.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "record".into());
    let dir = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<PathBuf> = out.exists().then(|| out.to_path_buf()).into_iter().collect();
    let later = std::fs::read_dir(&dir).into_iter().flatten().flatten().filter(|e| {
        let name = e.file_name().to_string_lossy().to_string();
        name.strip_prefix(&format!("{stem}-"))
            .and_then(|rest| rest.strip_suffix(".csv"))
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    });
    found.extend(later.map(|e| out.with_file_name(e.file_name())));
    found.sort();
    found
}

/// The `k`-th segment's file (0-based): `out` itself, then `stem-2.csv`, `stem-3.csv`, …
fn segment_path(out: &Path, k: usize) -> PathBuf {
    if k == 0 {
        return out.to_path_buf();
    }
    let stem = out.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "record".into());
    out.with_file_name(format!("{stem}-{}.csv", k + 1))
}

/// The segment being written: a temporary file renamed into place when the segment ends, so an
/// interrupted run never leaves a half-written CSV under the final name.
struct Segment {
    file: std::io::BufWriter<tempfile::NamedTempFile>,
    first_seq: u32,
    frames: u64,
}

/// Why a recording ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Ending {
    /// The stream ended.
    #[default]
    EndOfStream,
    /// SIGINT or SIGTERM: what was received is written, files and summary complete.
    Stopped,
}

/// Streams `input` (COBS frames), writing gap-free segments next to `out`, until the input ends
/// or `stop` is set (a signal handler sets it; the stream is read on its own thread so a quiet
/// serial line cannot keep the command from finishing). Memory is bounded (a few read buffers
/// and one write buffer), so hours of telemetry need no more RAM than seconds.
pub fn record(
    input: Box<dyn Read + Send>,
    out: &Path,
    tick_s: f64,
    stop: Arc<AtomicBool>,
) -> Result<RecordSummary> {
    // Checked, and shown, as model-core states its range (f32).
    let (lo, hi) = (model_core::DT_MIN_S, model_core::DT_MAX_S);
    if !(tick_s.is_finite() && (lo..=hi).contains(&(tick_s as f32))) {
        bail!("--tick-s must be in [{lo:e}, {hi:e}] s, got {tick_s}");
    }
    let decimals = crate::recording::time_decimals(tick_s);
    let dir = crate::files::output_dir(out);
    let mut d = Decoder::default();
    let mut sum = RecordSummary::default();
    let mut seg: Option<Segment> = None;
    let finish = |seg: Option<Segment>, sum: &mut RecordSummary| -> Result<()> {
        let Some(seg) = seg else { return Ok(()) };
        if seg.frames < 3 {
            sum.short += seg.frames;
            return Ok(());
        }
        let path = segment_path(out, sum.files.len());
        let tmp = seg
            .file
            .into_inner()
            .map_err(|e| anyhow::anyhow!("writing {}: {}", crate::files::display(&path), e.error()))?;
        crate::files::persist(tmp, &path)?;
        sum.files.push(path);
        Ok(())
    };
    let chunks = read_on_a_thread(input);
    loop {
        if stop.load(Ordering::SeqCst) {
            sum.ending = Ending::Stopped;
            break;
        }
        let chunk = match chunks.recv_timeout(Duration::from_millis(50)) {
            Ok(Ok(c)) => c,
            Ok(Err(e)) => return Err(e).context("reading the telemetry stream"),
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        for &b in &chunk {
            let Some(x) = d.push(b) else { continue };
            let f = x.frame;
            // A CRC-valid frame can still carry a value no file may hold (a firmware fault):
            // it is counted as invalid and ends the segment, like a gap.
            let valid = [(1, f.command_v), (2, f.current_a), (3, f.displacement_um), (3, f.reference_um)]
                .iter()
                .all(|&(k, v)| crate::recording::plausible(k, v as f64).is_ok());
            if x.gap > 0 || x.restart || !valid {
                finish(seg.take(), &mut sum)?;
                sum.restarts += x.restart as u64;
            }
            if !valid {
                sum.invalid += 1;
                continue;
            }
            let s = match &mut seg {
                Some(s) => s,
                None => {
                    let tmp = crate::files::partial_file(dir)?;
                    let mut file = std::io::BufWriter::new(tmp);
                    file.write_all(b"time_s,command_V,current_A,displacement_um,reference_um,faults\n")?;
                    seg.insert(Segment { file, first_seq: f.seq, frames: 0 })
                }
            };
            let t = f.seq.wrapping_sub(s.first_seq) as f64 * tick_s;
            writeln!(
                s.file,
                "{t:.decimals$},{:?},{:?},{:?},{:?},{}",
                f.command_v, f.current_a, f.displacement_um, f.reference_um, f.faults
            )?;
            s.frames += 1;
        }
    }
    finish(seg.take(), &mut sum)?;
    (sum.frames, sum.lost, sum.corrupt, sum.replies) = (d.frames, d.lost, d.corrupt, d.replies);
    if sum.files.is_empty() {
        bail!(
            "no recording in the stream: no run of 3 or more consecutive telemetry frames ({} valid frames, {} of \
             them in runs too short, {} lost from the sequence, {} replies, {} invalid frames, {} corrupt chunks){}; \
             is it the drive's UART capture, taken with the port raw (`stty -F PORT 4000000 raw -echo`)?",
            d.frames,
            sum.short,
            d.lost,
            d.replies,
            sum.invalid,
            d.corrupt,
            if sum.ending == Ending::Stopped { ", stopped by a signal" } else { "" }
        );
    }
    Ok(sum)
}

/// Reads `input` in chunks on a detached thread (a blocked read must not hold up a stop).
fn read_on_a_thread(mut input: Box<dyn Read + Send>) -> Receiver<std::io::Result<Vec<u8>>> {
    let (tx, rx) = sync_channel(8);
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 1 << 16];
        loop {
            match input.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    if tx.send(Ok(buf[..n].to_vec())).is_err() {
                        break;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    let _ = tx.send(Err(e));
                    break;
                }
            }
        }
    });
    rx
}

/// Opens the stream: a file, or stdin for `-`.
pub fn open_stream(input: &Path) -> Result<Box<dyn Read + Send>> {
    if input == Path::new("-") {
        Ok(Box::new(std::io::stdin()))
    } else {
        let name = crate::files::display(input);
        if input.is_dir() {
            return Err(crate::error::Located::file(&name, "is a folder, not a telemetry capture").into());
        }
        let f = std::fs::File::open(input).map_err(|e| crate::files::cannot_read(&name, &e))?;
        Ok(Box::new(f))
    }
}

/// A flag that SIGINT and SIGTERM set (instead of killing the process), so a live recording
/// can be ended with Ctrl-C and still write its last file and summary.
pub fn stop_on_signals() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop)).context("installing the signal handler")?;
    }
    Ok(stop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gma_control::telemetry::{Frame, MAX_ENCODED};

    #[test]
    fn gaps_split_files_and_are_counted() {
        let mut bytes = Vec::new();
        for seq in (0..200u32).filter(|s| !(100..105).contains(s)) {
            let f = Frame {
                seq,
                reference_um: 1.0,
                command_v: 2.0,
                current_a: 0.5,
                displacement_um: 3.0,
                faults: 0,
            };
            let mut buf = [0u8; MAX_ENCODED];
            let n = f.encode(&mut buf);
            bytes.extend_from_slice(&buf[..n]);
        }
        bytes[500] ^= 0x10; // one corrupt frame in the first segment
        let dir = tempfile::tempdir().unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let s =
            record(Box::new(std::io::Cursor::new(bytes)), &dir.path().join("rig.csv"), 1e-4, stop).unwrap();
        assert_eq!(s.ending, Ending::EndOfStream);
        assert_eq!(s.files.len(), 3, "{s:?}"); // corrupt frame and the 5-frame hole both split
        assert_eq!(s.lost, 6);
        assert_eq!(s.corrupt, 1);
        let first = crate::recording::Recording::read(&s.files[0]).unwrap();
        assert!(first.len() > 10 && (first.dt_s() - 1e-4).abs() < 1e-12);
    }
}
