//! The operator's command channel (UART, host → board) and its replies (board → host), framed
//! like telemetry: a raw frame is `version, tag, opcode, payload…, CRC-16/CCITT-FALSE (LE)`,
//! COBS-encoded and ended by a 0 byte, so the receiver resynchronises at the next delimiter
//! after any corruption. The `tag` is the host's choice and comes back in the reply, so a reply
//! cannot be mistaken for an older command's.
//!
//! | opcode | command | payload |
//! |---|---|---|
//! | 0x01 | ping / keep-alive | — |
//! | 0x02 | arm | — |
//! | 0x03 | disarm | — |
//! | 0x04 | clear faults | — |
//! | 0x05 | set reference | shape u8 (0 sine, 1 square, 2 triangle, 3 constant), amplitude µm f32, bias µm f32, frequency Hz f32 |
//! | 0x06 | load parameters | spec length u8, spec text (UTF-8), the parameter set (postcard, fields in declaration order) |
//!
//! A reply is `version, tag, 0x80 | opcode, status (0 = ack, else a [`Refusal`]), latched faults
//! u16 LE, armed u8`, framed the same way. A frame whose COBS or CRC is broken gets no reply
//! (its tag cannot be trusted); it is counted. Numbers are little-endian.

use model_core::{ActuatorParams, ModelSpec};

use crate::framing::{cobs_decode, cobs_encode, crc16};
use crate::reference::Waveform;

/// The protocol version this code speaks (byte 0 of every frame).
/// 2: in load-parameters `delay_samples` is an f32 (was a u16), and the Preisach parameters carry
/// the optional interaction spread.
/// 3: the Preisach parameters carry the optional reversible fraction and field.
/// 4: the thermal parameters carry the rod's lag behind the coil (`rod_tau_s`, f32).
pub const PROTOCOL_VERSION: u8 = 4;
/// Longest spec text in a load command [bytes].
pub const MAX_SPEC_BYTES: usize = 96;
/// Longest raw frame (header, payload, CRC) [bytes]: room for a parameter set.
pub const MAX_RAW: usize = 3 + 1 + MAX_SPEC_BYTES + 400 + 2;
/// Longest encoded frame: COBS adds one byte per 254, plus the delimiter.
pub const MAX_ENCODED: usize = MAX_RAW + MAX_RAW / 254 + 2;
/// Reply frame bytes before encoding.
const REPLY_RAW: usize = 3 + 1 + 2 + 1 + 2;
/// Longest encoded reply.
pub const MAX_REPLY_ENCODED: usize = REPLY_RAW + 2;

/// The reference waveform a command may set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// bias + amplitude · sin(2π f t).
    Sine = 0,
    /// bias ± amplitude, period 1/f.
    Square = 1,
    /// bias ± amplitude, linear ramps, period 1/f.
    Triangle = 2,
    /// bias (amplitude and frequency must be 0).
    Constant = 3,
}

/// A displacement reference as commanded [µm, Hz].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceCommand {
    /// Waveform.
    pub shape: Shape,
    /// Amplitude [µm] (≥ 0).
    pub amplitude_um: f32,
    /// DC level [µm, from rest].
    pub bias_um: f32,
    /// Frequency [Hz].
    pub freq_hz: f32,
}

impl ReferenceCommand {
    /// Validates the reference: finite, amplitude ≥ 0, |bias| + amplitude ≤ `max_um`, frequency
    /// in (0, `max_hz`] (0 for a constant, whose amplitude must be 0 too).
    pub fn waveform(&self, max_um: f32, max_hz: f32) -> Result<Waveform, Refusal> {
        let (a, b, f) = (self.amplitude_um, self.bias_um, self.freq_hz);
        let finite = a.is_finite() && b.is_finite() && f.is_finite();
        if !finite || a < 0.0 || b.abs() + a > max_um {
            return Err(Refusal::ReferenceOutOfRange);
        }
        let periodic_ok = f > 0.0 && f <= max_hz;
        match self.shape {
            Shape::Constant if a == 0.0 && f == 0.0 => Ok(Waveform::Constant { bias: b }),
            Shape::Sine if periodic_ok => Ok(Waveform::Sine { freq_hz: f, amplitude: a, bias: b }),
            Shape::Square if periodic_ok => Ok(Waveform::Steps { freq_hz: f, amplitude: a, bias: b }),
            Shape::Triangle if periodic_ok => Ok(Waveform::Triangle { freq_hz: f, amplitude: a, bias: b }),
            _ => Err(Refusal::ReferenceOutOfRange),
        }
    }
}

/// A command from the operator.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Keep-alive; the reply carries the status.
    Ping,
    /// Enable the bridge (refused while a fault is latched, before calibration, bus unhealthy).
    Arm,
    /// Bridge off.
    Disarm,
    /// Clear the latched faults whose cause is gone.
    ClearFaults,
    /// A new displacement reference (takes effect at once; the loops keep their state).
    SetReference(ReferenceCommand),
    /// A new identified parameter set for the compensator (disarmed only).
    LoadParameters {
        /// The model structure.
        spec: ModelSpec,
        /// Its parameters.
        params: ActuatorParams,
    },
}

const PING: u8 = 0x01;
const ARM: u8 = 0x02;
const DISARM: u8 = 0x03;
const CLEAR: u8 = 0x04;
const SET_REFERENCE: u8 = 0x05;
pub(crate) const LOAD_PARAMETERS: u8 = 0x06;
const REPLY_BIT: u8 = 0x80;

impl Command {
    /// The command's opcode byte.
    pub fn opcode(&self) -> u8 {
        match self {
            Command::Ping => PING,
            Command::Arm => ARM,
            Command::Disarm => DISARM,
            Command::ClearFaults => CLEAR,
            Command::SetReference(_) => SET_REFERENCE,
            Command::LoadParameters { .. } => LOAD_PARAMETERS,
        }
    }

    /// COBS-encodes the command with `tag` into `out` (with the 0 delimiter); returns the length.
    /// Fails only for a parameter set or spec text too long for a frame.
    pub fn encode(&self, tag: u8, out: &mut [u8; MAX_ENCODED]) -> Result<usize, Refusal> {
        let mut raw = [0u8; MAX_RAW];
        raw[..3].copy_from_slice(&[PROTOCOL_VERSION, tag, self.opcode()]);
        let mut n = 3;
        match self {
            Command::SetReference(r) => {
                raw[3] = r.shape as u8;
                raw[4..8].copy_from_slice(&r.amplitude_um.to_le_bytes());
                raw[8..12].copy_from_slice(&r.bias_um.to_le_bytes());
                raw[12..16].copy_from_slice(&r.freq_hz.to_le_bytes());
                n = 16;
            }
            Command::LoadParameters { spec, params } => {
                let mut text = heapless::String::<MAX_SPEC_BYTES>::new();
                core::fmt::Write::write_fmt(&mut text, format_args!("{spec}"))
                    .map_err(|_| Refusal::Malformed)?;
                raw[3] = text.len() as u8;
                raw[4..4 + text.len()].copy_from_slice(text.as_bytes());
                n = 4 + text.len();
                let end = MAX_RAW - 2;
                n += postcard::to_slice(params, &mut raw[n..end]).map_err(|_| Refusal::Malformed)?.len();
            }
            _ => {}
        }
        let crc = crc16(&raw[..n]);
        raw[n..n + 2].copy_from_slice(&crc.to_le_bytes());
        Ok(cobs_encode(&raw[..n + 2], out))
    }

    fn parse(opcode: u8, p: &[u8]) -> Result<Command, Refusal> {
        let f32_at = |i: usize| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
        let empty = |c: Command| if p.is_empty() { Ok(c) } else { Err(Refusal::Malformed) };
        match opcode {
            PING => empty(Command::Ping),
            ARM => empty(Command::Arm),
            DISARM => empty(Command::Disarm),
            CLEAR => empty(Command::ClearFaults),
            SET_REFERENCE if p.len() == 13 => {
                let shape = match p[0] {
                    0 => Shape::Sine,
                    1 => Shape::Square,
                    2 => Shape::Triangle,
                    3 => Shape::Constant,
                    _ => return Err(Refusal::Malformed),
                };
                Ok(Command::SetReference(ReferenceCommand {
                    shape,
                    amplitude_um: f32_at(1),
                    bias_um: f32_at(5),
                    freq_hz: f32_at(9),
                }))
            }
            LOAD_PARAMETERS if !p.is_empty() && p.len() > 1 + p[0] as usize => {
                let (text, rest) = p[1..].split_at(p[0] as usize);
                let spec = core::str::from_utf8(text)
                    .ok()
                    .and_then(|t| ModelSpec::parse(t).ok())
                    .ok_or(Refusal::InvalidParameters)?;
                let (params, tail) = postcard::take_from_bytes::<ActuatorParams>(rest)
                    .map_err(|_| Refusal::InvalidParameters)?;
                if !tail.is_empty() {
                    return Err(Refusal::Malformed);
                }
                Ok(Command::LoadParameters { spec, params })
            }
            SET_REFERENCE | LOAD_PARAMETERS => Err(Refusal::Malformed),
            _ => Err(Refusal::UnknownCommand),
        }
    }
}

/// Why a command was refused (the reply's status byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Refusal {
    /// A fault is latched: clear it first.
    FaultLatched = 1,
    /// No bridge-off calibration window (current zero, rest position) has completed since the
    /// bridge was last on.
    NotCalibrated = 2,
    /// The bus voltage is outside its limits (with hysteresis).
    BusOutOfRange = 3,
    /// Not while the bridge is armed.
    Armed = 4,
    /// The reference is not finite, beyond the stroke or the frequency range.
    ReferenceOutOfRange = 5,
    /// The parameter set does not decode or validate (model-core's checks, as at boot).
    InvalidParameters = 6,
    /// Some faults are still present and stay latched.
    FaultStillPresent = 7,
    /// The frame's protocol version is not [`PROTOCOL_VERSION`].
    UnsupportedVersion = 8,
    /// The payload does not have the command's layout.
    Malformed = 9,
    /// The opcode is not a command.
    UnknownCommand = 10,
}

impl Refusal {
    /// The reason from its status byte.
    pub fn from_code(c: u8) -> Option<Refusal> {
        use Refusal::*;
        [
            FaultLatched,
            NotCalibrated,
            BusOutOfRange,
            Armed,
            ReferenceOutOfRange,
            InvalidParameters,
            FaultStillPresent,
            UnsupportedVersion,
            Malformed,
            UnknownCommand,
        ]
        .into_iter()
        .find(|r| *r as u8 == c)
    }

    /// A short name for logs and the host tool.
    pub fn name(self) -> &'static str {
        match self {
            Refusal::FaultLatched => "fault_latched",
            Refusal::NotCalibrated => "not_calibrated",
            Refusal::BusOutOfRange => "bus_out_of_range",
            Refusal::Armed => "armed",
            Refusal::ReferenceOutOfRange => "reference_out_of_range",
            Refusal::InvalidParameters => "invalid_parameters",
            Refusal::FaultStillPresent => "fault_still_present",
            Refusal::UnsupportedVersion => "unsupported_version",
            Refusal::Malformed => "malformed",
            Refusal::UnknownCommand => "unknown_command",
        }
    }
}

/// The board's answer to one command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply {
    /// The command's tag.
    pub tag: u8,
    /// The command's opcode.
    pub opcode: u8,
    /// `Ok` (ack) or why not.
    pub outcome: Result<(), Refusal>,
    /// Faults latched after the command.
    pub faults: u16,
    /// Whether the bridge is armed after the command.
    pub armed: bool,
}

impl Reply {
    /// COBS-encodes the reply (with the delimiter); returns the length.
    pub fn encode(&self, out: &mut [u8; MAX_REPLY_ENCODED]) -> usize {
        let mut raw = [0u8; REPLY_RAW];
        let status = match self.outcome {
            Ok(()) => 0,
            Err(r) => r as u8,
        };
        raw[..4].copy_from_slice(&[PROTOCOL_VERSION, self.tag, REPLY_BIT | self.opcode, status]);
        raw[4..6].copy_from_slice(&self.faults.to_le_bytes());
        raw[6] = self.armed as u8;
        let crc = crc16(&raw[..7]);
        raw[7..9].copy_from_slice(&crc.to_le_bytes());
        let mut buf = [0u8; MAX_ENCODED];
        let n = cobs_encode(&raw, &mut buf);
        out[..n].copy_from_slice(&buf[..n]);
        n
    }

    /// A whole decoded frame (CRC included) if it is an intact reply.
    pub fn from_frame(raw: &[u8]) -> Option<Reply> {
        let n = raw.len().checked_sub(2)?;
        (crc16(&raw[..n]) == u16::from_le_bytes([raw[n], raw[n + 1]])).then(|| Reply::parse(&raw[..n]))?
    }

    fn parse(raw: &[u8]) -> Option<Reply> {
        if raw.len() != REPLY_RAW - 2 || raw[0] != PROTOCOL_VERSION || raw[2] & REPLY_BIT == 0 {
            return None;
        }
        let outcome = match raw[3] {
            0 => Ok(()),
            c => Err(Refusal::from_code(c)?),
        };
        Some(Reply {
            tag: raw[1],
            opcode: raw[2] & !REPLY_BIT,
            outcome,
            faults: u16::from_le_bytes([raw[4], raw[5]]),
            armed: raw[6] == 1,
        })
    }
}

/// What one complete frame turned out to be.
// A load command carries its parameter set by value (about 210 bytes): there is no heap on the
// board to box it, and one `Received` lives at a time.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Received {
    /// A valid command and its tag.
    Command(u8, Command),
    /// An intact frame (CRC good) that is refused: answer with this reply.
    Refused {
        /// Tag.
        tag: u8,
        /// Opcode.
        opcode: u8,
        /// Why.
        reason: Refusal,
    },
}

/// Stream decoder for either direction, with counters of what it threw away.
#[derive(Debug, Clone)]
pub struct Decoder {
    buf: [u8; MAX_ENCODED],
    len: usize,
    overflow: bool,
    /// Intact frames.
    pub frames: u32,
    /// Delimited chunks that failed COBS, length or CRC checks (no reply possible).
    pub corrupt: u32,
    /// Intact frames refused (version, opcode, payload).
    pub refused: u32,
}

impl Default for Decoder {
    fn default() -> Self {
        Self { buf: [0; MAX_ENCODED], len: 0, overflow: false, frames: 0, corrupt: 0, refused: 0 }
    }
}

impl Decoder {
    /// Feeds one byte; at a delimiter returns the intact raw frame without its CRC.
    fn frame(&mut self, byte: u8, raw: &mut [u8; MAX_RAW]) -> Option<usize> {
        if byte != 0 {
            if self.len < MAX_ENCODED {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if len == 0 {
            return None; // idle delimiters
        }
        let n = if overflow { None } else { cobs_decode(&self.buf[..len], raw) };
        match n {
            Some(n) if n >= 5 && crc16(&raw[..n - 2]) == u16::from_le_bytes([raw[n - 2], raw[n - 1]]) => {
                self.frames += 1;
                Some(n - 2)
            }
            _ => {
                self.corrupt += 1;
                None
            }
        }
    }

    /// Board side: feeds one byte; returns a command (or a refusal to answer) when a frame ends.
    pub fn push_command(&mut self, byte: u8) -> Option<Received> {
        let mut raw = [0u8; MAX_RAW];
        let n = self.frame(byte, &mut raw)?;
        let (tag, opcode) = (raw[1], raw[2]);
        let parsed = if raw[0] != PROTOCOL_VERSION {
            Err(Refusal::UnsupportedVersion)
        } else {
            Command::parse(opcode, &raw[3..n])
        };
        match parsed {
            Ok(c) => Some(Received::Command(tag, c)),
            Err(reason) => {
                self.refused += 1;
                Some(Received::Refused { tag, opcode, reason })
            }
        }
    }

    /// Host side: feeds one byte of the board's output; returns a reply when one ends.
    pub fn push_reply(&mut self, byte: u8) -> Option<Reply> {
        let mut raw = [0u8; MAX_RAW];
        let n = self.frame(byte, &mut raw)?;
        let reply = Reply::parse(&raw[..n]);
        if reply.is_none() {
            self.refused += 1;
        }
        reply
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn encoded(c: &Command, tag: u8) -> Vec<u8> {
        let mut buf = [0u8; MAX_ENCODED];
        let n = c.encode(tag, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn decode_all(bytes: &[u8]) -> (Vec<Received>, Decoder) {
        let mut d = Decoder::default();
        let got = bytes.iter().filter_map(|&b| d.push_command(b)).collect();
        (got, d)
    }

    /// The demo set with the Preisach optional fields all given (`Some`) or all absent.
    fn preisach_set(rho: Option<f32>) -> ActuatorParams {
        let mut p = ActuatorParams::TERFENOL_DEMO;
        p.preisach.interaction_spread_a_per_m = rho.map(|_| 12_000.0);
        p.preisach.reversible_fraction = rho;
        p.preisach.reversible_field_a_per_m = rho.map(|_| 30_000.0);
        p
    }

    #[test]
    fn every_command_round_trips() {
        let cmds = [
            Command::Ping,
            Command::Arm,
            Command::Disarm,
            Command::ClearFaults,
            Command::SetReference(ReferenceCommand {
                shape: Shape::Triangle,
                amplitude_um: 5.0,
                bias_um: 10.0,
                freq_hz: 20.0,
            }),
            Command::LoadParameters {
                spec: ModelSpec::parse("ja+eddy+mech").unwrap(),
                params: ActuatorParams::TERFENOL_DEMO,
            },
            // Every optional field present, then every one absent (postcard has no field
            // names: an absent field must still take its place).
            Command::LoadParameters {
                spec: ModelSpec::parse("preisach+mech").unwrap(),
                params: preisach_set(Some(0.1)),
            },
            Command::LoadParameters {
                spec: ModelSpec::parse("preisach+mech").unwrap(),
                params: preisach_set(None),
            },
        ];
        for (tag, c) in cmds.iter().enumerate() {
            let (got, d) = decode_all(&encoded(c, tag as u8));
            assert_eq!(got, vec![Received::Command(tag as u8, c.clone())]);
            assert_eq!((d.frames, d.corrupt, d.refused), (1, 0, 0));
        }
    }

    #[test]
    fn long_runs_without_zeros_survive_cobs() {
        let raw: Vec<u8> = (0..600).map(|k| (k % 255) as u8 + 1).collect();
        let mut enc = vec![0u8; raw.len() + raw.len() / 254 + 2];
        let n = cobs_encode(&raw, &mut enc);
        assert!(enc[..n - 1].iter().all(|&b| b != 0));
        let mut back = [0u8; 700];
        assert_eq!(cobs_decode(&enc[..n - 1], &mut back), Some(raw.len()));
        assert_eq!(&back[..raw.len()], &raw[..]);
    }

    #[test]
    fn a_wrong_version_or_opcode_is_refused_with_its_tag() {
        let mut raw = vec![PROTOCOL_VERSION + 1, 7, ARM];
        let crc = crc16(&raw);
        raw.extend_from_slice(&crc.to_le_bytes());
        let mut enc = vec![0u8; 16];
        let n = cobs_encode(&raw, &mut enc);
        let (got, d) = decode_all(&enc[..n]);
        assert_eq!(got, vec![Received::Refused { tag: 7, opcode: ARM, reason: Refusal::UnsupportedVersion }]);
        assert_eq!(d.refused, 1);
        let mut raw = vec![PROTOCOL_VERSION, 8, 0x42];
        let crc = crc16(&raw);
        raw.extend_from_slice(&crc.to_le_bytes());
        let n = cobs_encode(&raw, &mut enc);
        let (got, _) = decode_all(&enc[..n]);
        assert_eq!(got, vec![Received::Refused { tag: 8, opcode: 0x42, reason: Refusal::UnknownCommand }]);
    }

    #[test]
    fn replies_round_trip() {
        let r =
            Reply { tag: 3, opcode: ARM, outcome: Err(Refusal::BusOutOfRange), faults: 0x40, armed: false };
        let mut buf = [0u8; MAX_REPLY_ENCODED];
        let n = r.encode(&mut buf);
        let mut d = Decoder::default();
        let got: Vec<Reply> = buf[..n].iter().filter_map(|&b| d.push_reply(b)).collect();
        assert_eq!(got, vec![r]);
    }

    proptest! {
        /// Arbitrary bytes never panic the decoder; every delimited chunk is either decoded,
        /// refused or counted corrupt.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
            let mut d = Decoder::default();
            let mut out = 0u32;
            for &b in &bytes {
                if d.push_command(b).is_some() {
                    out += 1;
                }
            }
            prop_assert_eq!(out, d.frames);
            prop_assert!(d.refused <= d.frames);
        }

        /// Bit flips in a stream of valid commands: no altered command gets through (each one
        /// decoded equals what was sent), damaged frames are counted.
        #[test]
        fn corrupt_frames_are_refused_and_counted(flips in proptest::collection::vec((0usize..10_000, 0u8..8), 1..10)) {
            let sent: Vec<Command> = (0..40).map(|k| match k % 4 {
                0 => Command::Ping,
                1 => Command::Arm,
                2 => Command::SetReference(ReferenceCommand { shape: Shape::Sine, amplitude_um: k as f32, bias_um: 1.0, freq_hz: 50.0 }),
                _ => Command::Disarm,
            }).collect();
            let mut stream: Vec<u8> = sent.iter().enumerate().flat_map(|(k, c)| encoded(c, k as u8)).collect();
            let len = stream.len();
            for (pos, bit) in &flips {
                stream[pos % len] ^= 1 << bit;
            }
            // The line goes on: a later delimiter ends a last frame whose own delimiter was hit.
            stream.push(0);
            let (got, d) = decode_all(&stream);
            for r in &got {
                if let Received::Command(tag, c) = r {
                    prop_assert_eq!(c, &sent[*tag as usize]);
                }
            }
            // A flipped delimiter merges two frames into one corrupt chunk.
            prop_assert!(d.frames as usize + (d.corrupt as usize) >= 40 - 2 * flips.len());
            prop_assert!(d.corrupt >= 1 || got.len() == 40);
        }
    }
}
