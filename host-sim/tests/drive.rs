//! `gma drive` against the board's own command code, no hardware: the frames `gma drive` writes
//! are fed byte by byte through gma-control's decoder into a `Controller` on the SIMULATED rig,
//! its replies are encoded as the board sends them, and `gma drive replies` decodes them.

mod common;

use common::{gma, refused};
use gma_control::command::{Decoder, Received, Reply, MAX_REPLY_ENCODED};
use gma_control::sim::{CoilActuator, Rig};
use gma_control::{ControlConfig, Controller, ResetCause};
use model_core::{ActuatorParams, ModelSpec};
use std::path::Path;

fn run_ok(args: &[&str]) {
    let o = gma(args);
    assert!(o.status.success(), "gma {args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn encoded_commands_drive_the_control_code_and_replies_decode() {
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("commands.bin");
    let params = dir.path().join("params.toml");
    std::fs::write(&params, host_sim::params::to_toml(&ActuatorParams::TERFENOL_DEMO, "# demo set").unwrap())
        .unwrap();
    let s = script.to_str().unwrap();
    run_ok(&[
        "drive",
        "load",
        "--params",
        params.to_str().unwrap(),
        "--model",
        "ja+eddy+mech",
        "--out",
        s,
        "--tag",
        "1",
    ]);
    run_ok(&[
        "drive",
        "reference",
        "--shape",
        "triangle",
        "--amplitude-um",
        "5",
        "--bias-um",
        "10",
        "--freq-hz",
        "20",
        "--out",
        s,
        "--tag",
        "2",
    ]);
    run_ok(&["drive", "arm", "--out", s, "--tag", "3"]);
    run_ok(&["drive", "clear", "--out", s, "--tag", "4"]);
    run_ok(&["drive", "arm", "--out", s, "--tag", "5"]);
    run_ok(&["drive", "ping", "--out", s, "--tag", "6"]);
    run_ok(&["drive", "disarm", "--out", s, "--tag", "7"]);

    // The board: a watchdog reset, booted through its calibration with the bridge off.
    let model = ModelSpec::parse("ja+eddy+mech").unwrap();
    let mut rig = Rig::new(CoilActuator::new(model, &ActuatorParams::TERFENOL_DEMO, 1e-4).unwrap(), 1);
    let mut ctl = Controller::new(
        ControlConfig::REFERENCE,
        model,
        &ActuatorParams::TERFENOL_DEMO,
        ResetCause::Watchdog,
    );
    for _ in 0..ControlConfig::REFERENCE.offset_calibration_ticks {
        let out = ctl.tick(&rig.sample());
        rig.apply(&out).unwrap();
    }
    let mut decoder = Decoder::default();
    let (mut answers, mut armed_seen) = (Vec::new(), Vec::new());
    for b in std::fs::read(&script).unwrap() {
        let reply: Reply = match decoder.push_command(b) {
            Some(Received::Command(tag, cmd)) => ctl.command(tag, &cmd),
            Some(Received::Refused { tag, opcode, reason }) => ctl.refusal(tag, opcode, reason),
            None => continue,
        };
        armed_seen.push(ctl.armed());
        let mut buf = [0u8; MAX_REPLY_ENCODED];
        let n = reply.encode(&mut buf);
        answers.extend_from_slice(&buf[..n]);
    }
    assert_eq!((decoder.frames, decoder.corrupt, decoder.refused), (7, 0, 0));
    assert_eq!(armed_seen, [false, false, false, false, true, true, false]);

    let replies = dir.path().join("replies.bin");
    std::fs::write(&replies, &answers).unwrap();
    let o = gma(&["drive", "replies", "--input", replies.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let list = v["replies"].as_array().unwrap();
    let acks: Vec<bool> = list.iter().map(|r| r["ack"].as_bool().unwrap()).collect();
    assert_eq!(acks, [true, true, false, true, true, true, true], "{v}");
    assert_eq!(list[2]["refused"], "fault_latched");
    assert_eq!(list[2]["faults"][0], "watchdog_reset");
    let tags: Vec<u64> = list.iter().map(|r| r["tag"].as_u64().unwrap()).collect();
    assert_eq!(tags, [1, 2, 3, 4, 5, 6, 7]);
    // Human text too.
    let o = gma(&["drive", "replies", "--input", replies.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("tag 3 arm: refused (fault_latched); faults: watchdog_reset; disarmed"), "{text}");
}

#[test]
fn bad_commands_are_refused_on_the_host_before_sending() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.bin");
    let o = out.to_str().unwrap();
    refused(
        &gma(&[
            "drive",
            "reference",
            "--shape",
            "sine",
            "--amplitude-um",
            "40",
            "--bias-um",
            "20",
            "--freq-hz",
            "100",
            "--out",
            o,
        ]),
        &["out of range: |bias| + amplitude = 60 µm is beyond the board's 50 µm"],
        "beyond the stroke",
    );
    refused(
        &gma(&["drive", "reference", "--shape", "constant", "--bias-um", "5", "--freq-hz", "10", "--out", o]),
        &["out of range: a constant has amplitude and frequency 0"],
        "a constant with a frequency",
    );
    refused(
        &gma(&["drive", "reference", "--shape", "sine", "--amplitude-um", "10", "--out", o]),
        &["--shape sine: give its frequency, --freq-hz in (0, 1666.6] Hz"],
        "a sine left at the default frequency",
    );
    // Issue 78 item 11: the bound the help and the errors say is one the board takes, and the
    // error names the condition that failed.
    let accepted = dir.path().join("accepted.bin");
    let a = accepted.to_str().unwrap();
    let sine = |amplitude_um: &str, freq_hz: &str, out: &str| {
        gma(&[
            "drive",
            "reference",
            "--shape",
            "sine",
            "--amplitude-um",
            amplitude_um,
            "--freq-hz",
            freq_hz,
            "--out",
            out,
        ])
    };
    let o_accepted = sine("5", "1666.6", a);
    assert!(
        o_accepted.status.success(),
        "1666.6 Hz refused: {}",
        String::from_utf8_lossy(&o_accepted.stderr)
    );
    refused(
        &sine("5", "1666.7", o),
        &["out of range: the frequency 1666.7 Hz is outside (0, 1666.6] Hz"],
        "above a sixth of the tick rate",
    );
    refused(&sine("-5", "10", o), &["out of range: the amplitude -5 µm is negative"], "a negative amplitude");
    refused(
        &gma(&["drive", "load", "--params", "nonexistent.toml", "--model", "ja", "--out", o]),
        &["nonexistent.toml"],
        "missing file",
    );
    refused(
        &gma(&["drive", "load", "--params", "x.toml", "--model", "ja+bogus", "--out", o]),
        &["model spec `ja+bogus`: unknown effect `bogus`"],
        "bad spec",
    );
    // A serial port that does not exist is not created as a file.
    let port = "/dev/gma-test-no-such-ttyACM9";
    refused(
        &gma(&["drive", "disarm", "-o", port]),
        &["no device /dev/gma-test-no-such-ttyACM9"],
        "mistyped port",
    );
    assert!(!Path::new(port).exists(), "a mistyped port must not become a file");
    assert!(!out.exists(), "nothing may be written for a refused command");
    // Line noise and a corrupted reply are skipped and counted, never a wrong reply.
    let noise = dir.path().join("noise.bin");
    let r = Reply { tag: 9, opcode: 2, outcome: Ok(()), faults: 0, armed: true };
    let mut buf = [0u8; MAX_REPLY_ENCODED];
    let n = r.encode(&mut buf);
    let mut bytes = vec![0x42, 0x17, 0x00];
    let mut bad = buf[..n].to_vec();
    bad[2] ^= 0x10;
    bytes.extend_from_slice(&bad);
    bytes.extend_from_slice(&buf[..n]);
    std::fs::write(&noise, &bytes).unwrap();
    let o = gma(&["drive", "replies", "--input", noise.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["replies"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["corrupt"], 2, "{v}");
}
