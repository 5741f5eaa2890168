//! The `gma` command line: this file parses the arguments, dispatches to one file per
//! subcommand and reports errors — as `gma: error: …` on stderr, and with `--json` also as one
//! `{"error": {…}}` object on stdout, so a script always gets exactly one JSON object.

use std::process::ExitCode;

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use serde_json::json;

use crate::error::Located;
use crate::files::escape_control;
use crate::provenance::Provenance;

/// A line on stdout. A reader that goes away (`gma … | head`) ends the command quietly instead
/// of a panic on the broken pipe.
macro_rules! out {
    ($($t:tt)*) => {
        $crate::cli::print_line(format_args!($($t)*))
    };
}

/// Human text goes to stdout, or to stderr in `--json` mode (stdout then holds only the JSON).
macro_rules! say {
    ($json:expr, $($t:tt)*) => {
        if $json { eprintln!($($t)*) } else { out!($($t)*) }
    };
}

mod compare;
mod demo;
mod diagnose;
mod drive;
mod effects;
pub(crate) mod fit;
mod mechanics;
mod record;
mod report;
pub mod simulate;

pub use crate::api::inputs::ReadArgs;

/// Exit status of a command that failed (bad input, a model that cannot follow the data, …).
const EXIT_FAILURE: u8 = 1;
/// Exit status of a command line that cannot be parsed (clap's usage code).
const EXIT_USAGE: u8 = 2;

#[derive(Parser)]
#[command(name = "gma", version, about = "Model workbench for giant-magnetostrictive (Terfenol-D) actuators")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on SIMULATED data, in under a minute: a rig with hidden effects, a diagnosis
    /// from a baseline model, the named effects added one by one, the error falling, an HTML report.
    #[command(allow_negative_numbers = true)]
    Demo(demo::DemoArgs),
    /// Identify a model's parameters from one or more recordings jointly.
    #[command(allow_negative_numbers = true)]
    Fit(fit::FitArgs),
    /// Per-file error and plots (loops, time series, residuals) of a model against recordings.
    #[command(allow_negative_numbers = true)]
    Compare(compare::CompareArgs),
    /// Fit a model, analyse what it leaves unexplained and name the missing effect.
    #[command(allow_negative_numbers = true)]
    Diagnose(diagnose::DiagnoseArgs),
    /// Climb the model ladder (diagnose, add the named effect, refit, repeat) and write one
    /// self-contained HTML page.
    #[command(allow_negative_numbers = true)]
    Report(report::ReportArgs),
    /// Turn the drive's telemetry stream (COBS frames captured from its UART) into measurement
    /// CSVs; lost and corrupt frames are counted, and every gap starts a new file. Ctrl-C (or
    /// SIGTERM) ends a live recording with its files and summary complete.
    #[command(allow_negative_numbers = true)]
    Record(record::RecordArgs),
    /// Simulate a rig (plant simulator) and write a measurement CSV, or run a parameter set on a
    /// measured drive (`--drive FILE`). SIMULATED data, for tests, demos and model checks.
    #[command(allow_negative_numbers = true)]
    Simulate(crate::api::simulate::SimulateArgs),
    /// The physical effects a model spec can name: what each adds, where it acts, and the
    /// parameters a fit identifies for it (units, ranges, defaults).
    Effects(effects::EffectsArgs),
    /// Natural frequency, damping ratio and step response of the actuator mechanics
    /// (m ÿ + c ẏ + k y = F; paper 001 eq. 14–15, cited in docs/references.md), discretised
    /// exactly at the loop rate.
    #[command(allow_negative_numbers = true)]
    Mechanics(mechanics::MechanicsArgs),
    /// The drive's command channel: encode a command (arm, disarm, clear, ping, reference,
    /// load) for its UART, or decode its replies.
    Drive(drive::DriveArgs),
}

impl Command {
    /// Whether the command was asked for JSON output.
    fn json(&self) -> bool {
        match self {
            Command::Fit(a) => a.mf.json,
            Command::Diagnose(a) => a.mf.json,
            Command::Report(a) => a.mf.json,
            Command::Compare(a) => a.json,
            Command::Record(a) => a.json,
            Command::Effects(a) => a.json,
            Command::Demo(a) => a.json,
            Command::Simulate(a) => a.json,
            Command::Mechanics(a) => a.json,
            Command::Drive(a) => a.json(),
        }
    }
}

/// `gma --help`'s description, with the effect names from the registry.
fn long_about() -> String {
    format!(
        "Model workbench for giant-magnetostrictive (Terfenol-D) actuators: compare a model with \
         measurements, see where it fails, learn which physical effect is missing, add it and watch \
         the error fall.\n\nMeasurement CSV columns (by name): time_s [s], command_V, current_A, \
         displacement_um, force_N, temperature_C (the coil's: scored, with coil heating in the model), \
         flux_density_T (a search coil on the rod: a third scored channel) (other names or units: `--column`, see `gma fit --help`). Model specs are \
         `+`-joined effects: {} (`gma effects` \
         describes each). File formats, model specs and the JSON output: docs/formats.md and \
         docs/cli.md in the source repository.",
        effects::help_words()
    )
}

/// Runs `gma` with the process's arguments; the exit status says how it went.
pub fn main() -> ExitCode {
    let json_asked = std::env::args_os().any(|a| a == "--json");
    let parsed =
        Cli::command().long_about(long_about()).try_get_matches().and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version are not errors; with --json they answer in one object too.
            if !e.use_stderr() {
                if json_asked {
                    let j = match e.kind() {
                        clap::error::ErrorKind::DisplayVersion => {
                            json!({"version": env!("CARGO_PKG_VERSION")})
                        }
                        _ => json!({"help": e.render().to_string()}),
                    };
                    out!("{j}");
                } else {
                    let _ = e.print();
                }
                return ExitCode::SUCCESS;
            }
            // A value an option refuses exits as gma's own refusals do (`--format jpg` as
            // `--resample cubic`); a command line that cannot be parsed is a usage error.
            let code = match e.kind() {
                clap::error::ErrorKind::InvalidValue | clap::error::ErrorKind::ValueValidation => {
                    EXIT_FAILURE
                }
                _ => EXIT_USAGE,
            };
            if json_asked {
                print_json_error(&usage_error_message(&e.to_string()), None, code);
            }
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    let json = cli.command.json();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let message = escape_control(&format!("{e:#}"));
            eprintln!("gma: error: {message}");
            if json {
                // A whole recording's fault points at its file (the demo's are named after the files it writes).
                let at = e.chain().find_map(|c| {
                    c.downcast_ref::<Located>().cloned().or_else(|| {
                        c.downcast_ref::<crate::error::InRecording>()
                            .map(|r| Located::file(&r.recording, r.message.clone()))
                    })
                });
                print_json_error(&message, at.as_ref(), EXIT_FAILURE);
            }
            ExitCode::from(EXIT_FAILURE)
        }
    }
}

/// A usage error as clap renders it, on one line for `--json`: its lines (the missing
/// arguments, a tip) joined, without the usage line and the pointer to `--help` that follow.
fn usage_error_message(rendered: &str) -> String {
    let mut message = String::new();
    for line in rendered.lines().map(str::trim) {
        if line.starts_with("Usage:") || line.starts_with("For more information") {
            break;
        }
        if line.is_empty() {
            continue;
        }
        if !message.is_empty() {
            message.push_str(if message.ends_with(':') { " " } else { "; " });
        }
        message.push_str(line.strip_prefix("error: ").unwrap_or(line));
    }
    message
}

/// `base` and `extra` (both serialising to JSON objects) as one JSON object: a command's result
/// with the fields every command adds (parameter source, provenance).
fn merged_json(base: &impl serde::Serialize, extra: &impl serde::Serialize) -> Result<serde_json::Value> {
    let mut v = serde_json::to_value(base)?;
    if let (Some(o), serde_json::Value::Object(e)) = (v.as_object_mut(), serde_json::to_value(extra)?) {
        o.extend(e);
    }
    Ok(v)
}

/// The fields every command that reads inputs adds to its JSON: where its parameters came from
/// (`parameters_source`, `parameters_defaulted`) and its `provenance` (version, command line,
/// seed, date, the SHA-256 of every input; the caller takes it once the inputs have been read).
fn context_json(source: &crate::params::ParamSource, provenance: &Provenance) -> serde_json::Value {
    json!({
        "parameters_source": source.parameters_source,
        "parameters_defaulted": source.parameters_defaulted,
        "provenance": provenance,
    })
}

/// Writes one line to stdout; exits at once (status 0) when the reader has closed the pipe.
pub fn print_line(line: std::fmt::Arguments) {
    use std::io::Write as _;
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(line).and_then(|()| stdout.write_all(b"\n")) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("gma: error: writing to standard output: {e}");
        std::process::exit(EXIT_FAILURE as i32);
    }
}

/// The `--json` error object: the message as printed on stderr, where it points, the exit status.
fn print_json_error(message: &str, at: Option<&Located>, exit_code: u8) {
    out!(
        "{}",
        json!({"error": {
            "message": message,
            "file": at.map(|l| escape_control(&l.file)),
            "line": at.and_then(|l| l.line),
            "column": at.and_then(|l| l.column),
            "exit_code": exit_code,
        }})
    );
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Demo(a) => demo::run(&a),
        Command::Fit(a) => fit::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Diagnose(a) => diagnose::run(&a),
        Command::Report(a) => report::run(&a),
        Command::Record(a) => record::run(&a),
        Command::Simulate(a) => simulate::run(&a),
        Command::Effects(a) => effects::run(&a),
        Command::Mechanics(a) => mechanics::run(&a),
        Command::Drive(a) => drive::run(&a),
    }
}
