//! `gma drive`: the host side of the drive's command channel. Encodes one command as the board
//! decodes it (gma-control's `command` module: COBS + CRC-16, protocol version byte, a tag the
//! reply echoes) and writes it to a serial device, a file or stdout; `gma drive replies` decodes
//! what the board answered.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use gma_control::command::{self, Command, Decoder, ReferenceCommand, Refusal, Shape};
use gma_control::faults::FaultCode;
use serde_json::json;

use crate::files::display;
use crate::params::ParamSource;

/// Options of `gma drive`.
#[derive(Args)]
pub struct DriveArgs {
    #[command(subcommand)]
    pub action: Action,
}

/// Where an encoded command goes.
#[derive(Args)]
pub struct Target {
    /// Where the frame goes: a serial device already set up with `stty` (the board's port:
    /// `stty -F /dev/ttyACM0 4000000 raw -echo`, 4 Mbaud 8N1), a file (appended to, so a sequence of commands builds a script), or `-`
    /// for stdout.
    #[arg(long, short, default_value = "-")]
    pub out: PathBuf,
    /// The tag the board echoes in its reply (0–255), to match replies to commands.
    #[arg(long, default_value_t = 0)]
    pub tag: u8,
    /// Print one JSON object on stdout saying what was sent (command, tag, bytes, where, the
    /// frame in hex); needs `--out` to be a file or device, as stdout then carries the JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `gma drive` does.
#[derive(Subcommand)]
pub enum Action {
    /// Keep-alive: the board disarms when nothing valid arrives for 200 ms while armed.
    Ping(Target),
    /// Enable the bridge (refused while a fault is latched, before the boot calibration, or
    /// with the bus outside its limits).
    Arm(Target),
    /// Switch the bridge off.
    Disarm(Target),
    /// Clear the latched faults whose cause is gone (does not arm; after three overcurrent,
    /// bridge-break, stuck-probe or missed-deadline trips within a minute only a reset clears them).
    Clear(Target),
    /// Set the displacement reference [µm from rest]; validated on the board too.
    #[command(allow_negative_numbers = true)]
    Reference(ReferenceArgs),
    /// Load an identified parameter set (a `gma fit` parameter file) for the board's
    /// compensator; the board validates it as at boot and refuses it while armed.
    Load(LoadArgs),
    /// Decode the board's replies from a capture (`-` for stdin).
    Replies(RepliesArgs),
}

/// The reference waveforms the board generates.
#[derive(Clone, Copy, ValueEnum)]
pub enum WaveShape {
    /// bias + amplitude · sin(2π f t).
    Sine,
    /// bias ± amplitude.
    Square,
    /// bias ± amplitude, linear ramps.
    Triangle,
    /// bias only (amplitude and frequency 0).
    Constant,
}

/// Options of `gma drive reference`.
#[derive(Args)]
pub struct ReferenceArgs {
    /// Waveform.
    #[arg(long, value_enum)]
    pub shape: WaveShape,
    /// Amplitude [µm] (≥ 0; |bias| + amplitude ≤ 50 µm on the reference board).
    #[arg(long, default_value_t = 0.0)]
    pub amplitude_um: f32,
    /// DC level [µm from rest].
    #[arg(long, default_value_t = 0.0)]
    pub bias_um: f32,
    /// Frequency [Hz] (0 < f ≤ 1666.6 Hz, below a sixth of the 10 kHz tick; 0 for a constant).
    #[arg(long, default_value_t = 0.0)]
    pub freq_hz: f32,
    #[command(flatten)]
    pub target: Target,
}

/// Options of `gma drive load`.
#[derive(Args)]
pub struct LoadArgs {
    /// The parameter file (TOML, as `gma fit` writes it).
    #[arg(long)]
    pub params: PathBuf,
    /// The model spec the parameters belong to (e.g. `ja+eddy+mech`).
    #[arg(long)]
    pub model: String,
    /// Load a file that leaves out tables the model uses (the board then runs the built-in demo
    /// set's values for them); without it such a file is refused.
    #[arg(long)]
    pub allow_defaulted: bool,
    #[command(flatten)]
    pub target: Target,
}

/// Options of `gma drive replies`.
#[derive(Args)]
pub struct RepliesArgs {
    /// The captured bytes from the board (`-` for stdin).
    #[arg(long, short)]
    pub input: PathBuf,
    /// Print exactly one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

impl DriveArgs {
    /// Whether JSON output was asked for.
    pub fn json(&self) -> bool {
        match &self.action {
            Action::Ping(t) | Action::Arm(t) | Action::Disarm(t) | Action::Clear(t) => t.json,
            Action::Reference(r) => r.target.json,
            Action::Load(l) => l.target.json,
            Action::Replies(r) => r.json,
        }
    }
}

/// Runs `gma drive`.
pub fn run(a: &DriveArgs) -> Result<()> {
    // Only `load` has a parameter set, whose source its JSON names.
    let mut source = None;
    let (cmd, target) = match &a.action {
        Action::Ping(t) => (Command::Ping, t),
        Action::Arm(t) => (Command::Arm, t),
        Action::Disarm(t) => (Command::Disarm, t),
        Action::Clear(t) => (Command::ClearFaults, t),
        Action::Reference(r) => (reference(r)?, &r.target),
        Action::Load(l) => {
            let (cmd, from) = load(l)?;
            source = Some(from);
            (cmd, &l.target)
        }
        Action::Replies(r) => return replies(r),
    };
    if target.json && target.out == Path::new("-") {
        bail!("--json with --out - (the default): stdout would carry both the frame and the JSON; give --out FILE or a device");
    }
    let mut frame = [0u8; command::MAX_ENCODED];
    let n = cmd.encode(target.tag, &mut frame).map_err(|r| anyhow::anyhow!("cannot encode: {}", r.name()))?;
    send(&target.out, &frame[..n])?;
    if target.json {
        let hex: String = frame[..n].iter().map(|b| format!("{b:02x}")).collect();
        let mut j = json!({"command": opcode_name(cmd.opcode()), "tag": target.tag, "bytes": n, "out": display(&target.out), "frame_hex": hex});
        if let (Some(o), Some(source)) = (j.as_object_mut(), source) {
            o.insert("parameters_source".into(), source.parameters_source.into());
            o.insert("parameters_defaulted".into(), source.parameters_defaulted.into());
        }
        out!("{j}");
    }
    Ok(())
}

fn reference(r: &ReferenceArgs) -> Result<Command> {
    let shape = match r.shape {
        WaveShape::Sine => Shape::Sine,
        WaveShape::Square => Shape::Square,
        WaveShape::Triangle => Shape::Triangle,
        WaveShape::Constant => Shape::Constant,
    };
    let cmd =
        ReferenceCommand { shape, amplitude_um: r.amplitude_um, bias_um: r.bias_um, freq_hz: r.freq_hz };
    // The board's own check with the reference board's limits, so that a typo fails here.
    let cfg = gma_control::ControlConfig::REFERENCE;
    let max_hz = 1.0 / (6.0 * cfg.current_loop.tick_s);
    // The bound as a person types it: rounded down, so the figure said is one the board takes
    // (1666.6 Hz; 1666.7 is above a sixth of the 10 kHz tick).
    let max_hz_said = (max_hz * 10.0).floor() / 10.0;
    // The one slip the range list below hides: a waveform left at the default frequency, 0.
    if !matches!(r.shape, WaveShape::Constant) && r.freq_hz == 0.0 {
        bail!(
            "reference --shape {}: give its frequency, --freq-hz in (0, {max_hz_said:.1}] Hz (the default, 0, is for `constant` only)",
            shape_name(r.shape)
        );
    }
    if cmd.waveform(cfg.max_reference_um, max_hz).is_err() {
        let (a, b, f) = (r.amplitude_um, r.bias_um, r.freq_hz);
        let why = if !(a.is_finite() && b.is_finite() && f.is_finite()) {
            "a value is not a finite number".to_string()
        } else if a < 0.0 {
            format!("the amplitude {a} µm is negative (a waveform's sign is its phase)")
        } else if b.abs() + a > cfg.max_reference_um {
            format!(
                "|bias| + amplitude = {} µm is beyond the board's {} µm",
                b.abs() + a,
                cfg.max_reference_um
            )
        } else if matches!(r.shape, WaveShape::Constant) {
            "a constant has amplitude and frequency 0 (use --bias-um for its level)".to_string()
        } else {
            format!("the frequency {f} Hz is outside (0, {max_hz_said:.1}] Hz, a sixth of the tick rate")
        };
        bail!(
            "reference --shape {} --amplitude-um {a} --bias-um {b} --freq-hz {f}: out of range: {why}",
            shape_name(r.shape)
        );
    }
    Ok(Command::SetReference(cmd))
}

fn shape_name(s: WaveShape) -> &'static str {
    match s {
        WaveShape::Sine => "sine",
        WaveShape::Square => "square",
        WaveShape::Triangle => "triangle",
        WaveShape::Constant => "constant",
    }
}

fn load(l: &LoadArgs) -> Result<(Command, ParamSource)> {
    let spec = crate::params::parse_spec(&l.model)?;
    let (params, source, text) = crate::params::load_with_text(&l.params, spec)?;
    let file = source.parameters_source.clone();
    // The board must not run physics nobody gave it: the demo set is a simulated rod.
    if !source.parameters_defaulted.is_empty() && !l.allow_defaulted {
        let tables =
            source.parameters_defaulted.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", ");
        return Err(crate::error::Located::file(
            &file,
            format!(
                "has no {tables} for `{spec}`: the board would run the built-in demo set's values for them (a \
                 simulated rod, not this actuator); give a parameter file with them (`gma fit --params-out` \
                 writes every table), or pass --allow-defaulted to load the demo values anyway"
            ),
        )
        .into());
    }
    if let Some(warning) = crate::params::written_for_another_model(&file, &text, spec) {
        crate::warning::warn(warning);
    }
    // The board's validation, before anything is sent.
    gma_control::compensator_model(spec, &params, gma_control::ControlConfig::REFERENCE.current_loop.tick_s)
        .map_err(|e| {
            crate::params::located_parameter(
                &file,
                &text,
                e.name(),
                format!("the board would refuse this parameter set: {e}"),
            )
        })?;
    Ok((Command::LoadParameters { spec, params }, source))
}

/// Writes one frame: appended to a file or written to a device, or to stdout.
fn send(out: &Path, frame: &[u8]) -> Result<()> {
    if out == Path::new("-") {
        let mut stdout = std::io::stdout().lock();
        return stdout.write_all(frame).and_then(|()| stdout.flush()).context("writing to standard output");
    }
    let name = display(out);
    if out.is_dir() {
        bail!("cannot write {name}: it is a folder");
    }
    // Under /dev nothing is created: a mistyped serial port would otherwise become a new file,
    // and the command "succeed" without reaching the board (a keep-alive loop would never stop).
    let device = out.starts_with("/dev");
    if !device {
        frames_only(out)?;
    }
    let mut f = match std::fs::OpenOptions::new().append(true).create(!device).open(out) {
        Ok(f) => f,
        Err(e) if device && e.kind() == std::io::ErrorKind::NotFound => bail!(
            "no device {name}: a serial port must exist before a command is sent to it (is the board \
             plugged in, and is it ttyACM0 or ttyUSB0? `ls /dev/tty*`); to write frames to a file, \
             name one outside /dev"
        ),
        Err(e) => return Err(e).with_context(|| format!("cannot open {name}")),
    };
    f.write_all(frame).and_then(|()| f.flush()).with_context(|| format!("writing {name}"))
}

/// Refuses to append frames to an existing file that holds something else: every frame ends
/// with the COBS delimiter 0x00, which a text file (a measurement, a parameter file) never has.
fn frames_only(out: &Path) -> Result<()> {
    use std::io::Read;
    let Ok(meta) = std::fs::metadata(out) else { return Ok(()) };
    if !meta.is_file() || meta.len() == 0 {
        return Ok(());
    }
    let mut head = Vec::new();
    std::fs::File::open(out)
        .and_then(|f| f.take(1 << 16).read_to_end(&mut head))
        .with_context(|| format!("cannot read {}", display(out)))?;
    if !head.contains(&0) {
        bail!(
            "{}: the file exists and holds no command frames (no 0x00 frame ends in its first bytes): \
             appending frames would spoil it (a measurement, a parameter file); name a new file or the \
             board's serial port",
            display(out)
        );
    }
    Ok(())
}

fn opcode_name(op: u8) -> &'static str {
    match op {
        0x01 => "ping",
        0x02 => "arm",
        0x03 => "disarm",
        0x04 => "clear",
        0x05 => "reference",
        0x06 => "load",
        _ => "unknown",
    }
}

fn replies(r: &RepliesArgs) -> Result<()> {
    let mut bytes = Vec::new();
    let name = display(&r.input);
    crate::record::open_stream(&r.input)?
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading {name}"))?;
    let mut d = Decoder::default();
    let mut list = Vec::new();
    for &b in &bytes {
        let Some(reply) = d.push_reply(b) else { continue };
        let faults: Vec<&str> = FaultCode(reply.faults).names().collect();
        let outcome = match reply.outcome {
            Ok(()) => "ack".to_string(),
            Err(reason) => format!("refused ({})", reason.name()),
        };
        say!(
            r.json,
            "tag {} {}: {outcome}; faults: {}; {}",
            reply.tag,
            opcode_name(reply.opcode),
            if faults.is_empty() { "none".into() } else { faults.join("+") },
            if reply.armed { "armed" } else { "disarmed" }
        );
        list.push(json!({
            "tag": reply.tag,
            "command": opcode_name(reply.opcode),
            "ack": reply.outcome.is_ok(),
            "refused": reply.outcome.err().map(Refusal::name),
            "faults": faults,
            "armed": reply.armed,
        }));
    }
    // A capture of the board's line holds its telemetry too: skipping those frames is normal.
    if d.refused > 0 {
        crate::warning::note(format_args!(
            "{name}: {} frames that are not replies (telemetry) skipped",
            d.refused
        ));
    }
    if d.corrupt > 0 {
        crate::warning::warn(format_args!(
            "{name}: {} corrupt chunks skipped (COBS, length or CRC failures: a noisy line, or a port not set raw)",
            d.corrupt
        ));
    }
    if r.json {
        out!("{}", json!({"replies": list, "corrupt": d.corrupt, "not_replies": d.refused}));
    }
    Ok(())
}
