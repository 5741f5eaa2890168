//! `gma record`: the drive's telemetry stream to measurement CSVs.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;

use crate::files::{check_outputs, display, no_stdout};
use crate::record::{self, Ending};

/// Options of `gma record`.
#[derive(Args)]
pub struct RecordArgs {
    /// The captured byte stream (`-` for stdin), e.g. `cat /dev/ttyACM0 > stream.bin` after
    /// `stty -F /dev/ttyACM0 4000000 raw -echo` (a port left in its default mode rewrites and
    /// echoes bytes).
    #[arg(long, short)]
    pub input: PathBuf,
    /// Output CSV (segments after gaps get `-2`, `-3`, … suffixes; each file appears only when
    /// its segment is complete).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Replace recordings already at `--out` and its `-2`, `-3`, … segment names (refused
    /// without it: gma cannot tell an earlier recording from a measurement to keep).
    #[arg(long)]
    pub overwrite: bool,
    /// Control tick [s] (the firmware's: 1e-4 s at 10 kHz).
    #[arg(long, default_value_t = 1e-4)]
    pub tick_s: f64,
    /// Print exactly one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Runs `gma record`.
pub fn run(a: &RecordArgs) -> Result<()> {
    no_stdout("--out", &a.out, "the first of the segments' files (each gap starts a new one)")?;
    let stream = record::open_stream(&a.input)?;
    check_outputs(&[a.out.as_path()], &[])?;
    if same_file(&a.input, &a.out) {
        anyhow::bail!("cannot write {}: it is the input; choose another output path", display(&a.out));
    }
    let existing = record::existing_segments(&a.out);
    if !a.overwrite && !existing.is_empty() {
        let names: Vec<String> = existing.iter().map(|p| display(p)).collect();
        anyhow::bail!(
            "--out {}: {} already there ({}), and a recording writes `--out` and its `-2`, `-3`, … segments; \
             gma cannot tell an earlier recording from a measurement to keep, so it will not replace them: \
             give --overwrite to replace them, or choose another path",
            display(&a.out),
            if names.len() == 1 { "a file is" } else { "files are" },
            names.join(", ")
        );
    }
    let stop = record::stop_on_signals()?;
    let r = record::record(stream, &a.out, a.tick_s, stop).with_context(|| display(&a.input))?;
    let files: Vec<String> = r.files.iter().map(|p| display(p)).collect();
    if r.ending == Ending::Stopped {
        eprintln!("gma: stopped by a signal: everything received so far is written");
    }
    say!(
        a.json,
        "{} frames, {} lost (sequence gaps), {} corrupt, {} invalid, {} restarts, {} command replies skipped; wrote {}",
        r.frames,
        r.lost,
        r.corrupt,
        r.invalid,
        r.restarts,
        r.replies,
        files.join(", ")
    );
    if r.lost + r.corrupt + r.invalid + r.restarts > 0 {
        crate::warning::warn(format_args!(
            "{} frames lost, {} corrupt chunks, {} frames with non-finite or implausible values, \
             {} restarts; none of them written, and each gap starts a new file",
            r.lost, r.corrupt, r.invalid, r.restarts
        ));
    }
    if r.short > 0 {
        crate::warning::warn(format_args!(
            "{} frames in segments shorter than 3 frames were not written",
            r.short
        ));
    }
    if a.json {
        out!(
            "{}",
            json!({"frames": r.frames, "lost": r.lost, "corrupt": r.corrupt, "invalid": r.invalid,
                   "restarts": r.restarts, "replies": r.replies, "short": r.short, "files": files,
                   "stopped_by_signal": r.ending == Ending::Stopped})
        );
    }
    Ok(())
}

/// Whether two paths name the same existing file.
fn same_file(a: &std::path::Path, b: &std::path::Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}
