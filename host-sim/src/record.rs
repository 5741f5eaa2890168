//! `gma record`: the drive's telemetry stream (COBS frames from the board's UART, captured to a
//! file or piped in) to measurement CSVs. Lost and corrupt frames are counted and reported; a
//! gap in the sequence numbers starts a new file, because a recording's time axis must be
//! uniform (never a silently stitched one).

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use gma_control::telemetry::{Decoder, Frame};

use crate::recording::write_atomic;

/// What a stream held.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSummary {
    /// Frames decoded.
    pub frames: u64,
    /// Frames missing from the sequence.
    pub lost: u64,
    /// Corrupt chunks.
    pub corrupt: u64,
    /// Files written (one per gap-free segment).
    pub files: Vec<PathBuf>,
}

fn segment_path(out: &Path, k: usize, segments: usize) -> PathBuf {
    if segments <= 1 {
        return out.to_path_buf();
    }
    let stem = out.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "record".into());
    out.with_file_name(format!("{stem}-{}.csv", k + 1))
}

fn csv(frames: &[Frame], tick_s: f64) -> String {
    let mut s = String::from("time_s,command_V,current_A,displacement_um,reference_um,faults\n");
    let t0 = frames.first().map(|f| f.seq).unwrap_or(0);
    for f in frames {
        let t = f.seq.wrapping_sub(t0) as f64 * tick_s;
        s.push_str(&format!(
            "{t:.7},{},{},{},{},{}\n",
            f.command_v, f.current_a, f.displacement_um, f.reference_um, f.faults
        ));
    }
    s
}

/// Decodes `bytes` and writes the segments next to `out`.
pub fn record(bytes: &[u8], out: &Path, tick_s: f64) -> Result<RecordSummary> {
    if !(tick_s.is_finite() && tick_s > 0.0) {
        bail!("--tick-s must be > 0, got {tick_s}");
    }
    let mut d = Decoder::default();
    let mut segments: Vec<Vec<Frame>> = Vec::new();
    for &b in bytes {
        if let Some(x) = d.push(b) {
            if x.gap > 0 || segments.is_empty() {
                segments.push(Vec::new());
            }
            segments.last_mut().expect("a segment").push(x.frame);
        }
    }
    segments.retain(|s| s.len() >= 3);
    if segments.is_empty() {
        bail!("no telemetry frames in the stream ({} corrupt chunks)", d.corrupt);
    }
    let mut files = Vec::new();
    for (k, seg) in segments.iter().enumerate() {
        let path = segment_path(out, k, segments.len());
        write_atomic(&path, csv(seg, tick_s).as_bytes())?;
        files.push(path);
    }
    Ok(RecordSummary { frames: d.frames, lost: d.lost, corrupt: d.corrupt, files })
}

/// Reads the stream from a file, or stdin for `-`.
pub fn read_stream(input: &Path) -> Result<Vec<u8>> {
    if input == Path::new("-") {
        let mut v = Vec::new();
        std::io::stdin().read_to_end(&mut v).context("reading stdin")?;
        Ok(v)
    } else {
        std::fs::read(input).with_context(|| format!("{}: cannot read", input.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gma_control::telemetry::MAX_ENCODED;

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
        let s = record(&bytes, &dir.path().join("rig.csv"), 1e-4).unwrap();
        assert_eq!(s.files.len(), 3, "{s:?}"); // corrupt frame and the 5-frame hole both split
        assert_eq!(s.lost, 6);
        assert_eq!(s.corrupt, 1);
        let first = crate::recording::Recording::read(&s.files[0]).unwrap();
        assert!(first.len() > 10 && (first.dt_s() - 1e-4).abs() < 1e-12);
    }
}
