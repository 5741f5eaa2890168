//! `gma record`: the drive's telemetry stream (COBS frames from the board's UART, captured to a
//! file or piped in) to measurement CSVs. Lost and corrupt frames are counted and reported; a
//! gap in the sequence numbers starts a new file, because a recording's time axis must be
//! uniform (never a silently stitched one).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

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
    /// CRC-valid frames carrying a non-finite value (never written; they end a segment).
    pub invalid: u64,
    /// Times the sequence restarted (the board was reset).
    pub restarts: u64,
    /// Frames in segments too short to be a recording (fewer than 3), counted, not written.
    pub short: u64,
    /// Files written (one per gap-free segment).
    pub files: Vec<PathBuf>,
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

/// Streams `input` (COBS frames), writing gap-free segments next to `out`. Memory is bounded
/// (one frame and one write buffer), so hours of telemetry need no more RAM than seconds.
pub fn record<R: Read>(mut input: R, out: &Path, tick_s: f64) -> Result<RecordSummary> {
    if !(tick_s.is_finite() && tick_s > 0.0) {
        bail!("--tick-s must be > 0, got {tick_s}");
    }
    let dir = crate::recording::output_dir(out);
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
            .map_err(|e| anyhow::anyhow!("writing {}: {}", path.display(), e.error()))?;
        crate::recording::persist(tmp, &path)?;
        sum.files.push(path);
        Ok(())
    };
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match input.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).context("reading the telemetry stream"),
        };
        for &b in &buf[..n] {
            let Some(x) = d.push(b) else { continue };
            let f = x.frame;
            let finite =
                [f.reference_um, f.command_v, f.current_a, f.displacement_um].iter().all(|v| v.is_finite());
            if x.gap > 0 || x.restart || !finite {
                finish(seg.take(), &mut sum)?;
                sum.restarts += x.restart as u64;
            }
            if !finite {
                sum.invalid += 1;
                continue;
            }
            let s = match &mut seg {
                Some(s) => s,
                None => {
                    let tmp = crate::recording::partial_file(dir)?;
                    let mut file = std::io::BufWriter::new(tmp);
                    file.write_all(b"time_s,command_V,current_A,displacement_um,reference_um,faults\n")?;
                    seg.insert(Segment { file, first_seq: f.seq, frames: 0 })
                }
            };
            let t = f.seq.wrapping_sub(s.first_seq) as f64 * tick_s;
            writeln!(
                s.file,
                "{t:.7},{},{},{},{},{}",
                f.command_v, f.current_a, f.displacement_um, f.reference_um, f.faults
            )?;
            s.frames += 1;
        }
    }
    finish(seg.take(), &mut sum)?;
    (sum.frames, sum.lost, sum.corrupt) = (d.frames, d.lost, d.corrupt);
    if sum.files.is_empty() {
        bail!(
            "no telemetry frames in the stream ({} frames, {} corrupt chunks, {} invalid frames); is it the drive's UART capture?",
            d.frames,
            d.corrupt,
            sum.invalid
        );
    }
    Ok(sum)
}

/// Opens the stream: a file, or stdin for `-`.
pub fn open_stream(input: &Path) -> Result<Box<dyn Read>> {
    if input == Path::new("-") {
        Ok(Box::new(std::io::stdin().lock()))
    } else {
        let f = std::fs::File::open(input).with_context(|| format!("{}: cannot read", input.display()))?;
        Ok(Box::new(f))
    }
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
        let s = record(&bytes[..], &dir.path().join("rig.csv"), 1e-4).unwrap();
        assert_eq!(s.files.len(), 3, "{s:?}"); // corrupt frame and the 5-frame hole both split
        assert_eq!(s.lost, 6);
        assert_eq!(s.corrupt, 1);
        let first = crate::recording::Recording::read(&s.files[0]).unwrap();
        assert!(first.len() > 10 && (first.dt_s() - 1e-4).abs() < 1e-12);
    }
}
