//! Telemetry frames: every tick's sample, CRC-16 protected and COBS framed (a zero byte ends
//! each frame), so a receiver resynchronises after any corruption and counts — never hides —
//! lost and corrupt frames from the sequence numbers.
//!
//! Two layouts, told apart by their length (the COBS delimiter gives it): format 1 ([`Frame`],
//! 24 bytes before COBS) and format 2 ([`TimedFrame`], 26 bytes: format 1's payload, then the
//! tick's CPU cycles as a u16, then the CRC). The board sends format 2; [`Decoder`] reads both.

use crate::command::Reply;
use crate::framing::{cobs_decode, cobs_encode, crc16};

/// One tick's record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Frame {
    /// Tick counter (wraps at 2³²).
    pub seq: u32,
    /// Displacement reference [µm] (relative to the rest position).
    pub reference_um: f32,
    /// Coil voltage commanded [V].
    pub command_v: f32,
    /// Measured coil current [A].
    pub current_a: f32,
    /// Measured displacement [µm] (relative to the rest position).
    pub displacement_um: f32,
    /// Latched fault bits.
    pub faults: u16,
}

/// A frame as the board sends it (format 2): the tick's record and the CPU cycles its interrupt
/// took (DWT CYCCNT from handler entry to the queueing of this frame; saturates at 65 535 =
/// 385 µs at 170 MHz, far past the 100 µs tick).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TimedFrame {
    /// The tick's record.
    pub frame: Frame,
    /// CPU cycles of the tick's interrupt [cycles].
    pub tick_cycles: u16,
}

/// Payload bytes of format 1: seq, four f32, faults.
pub const PAYLOAD_BYTES: usize = 4 + 4 * 4 + 2;
/// Format 1 payload plus CRC.
const RAW_BYTES: usize = PAYLOAD_BYTES + 2;
/// Payload bytes of format 2: format 1's, then the tick's cycles (u16).
pub const TIMED_PAYLOAD_BYTES: usize = PAYLOAD_BYTES + 2;
/// Format 2 payload plus CRC.
const TIMED_RAW_BYTES: usize = TIMED_PAYLOAD_BYTES + 2;
/// Largest encoded frame of either format: COBS adds one byte per 254, plus the delimiter.
pub const MAX_ENCODED: usize = TIMED_RAW_BYTES + 2;

impl Frame {
    fn write_payload(&self, b: &mut [u8]) {
        b[0..4].copy_from_slice(&self.seq.to_le_bytes());
        b[4..8].copy_from_slice(&self.reference_um.to_le_bytes());
        b[8..12].copy_from_slice(&self.command_v.to_le_bytes());
        b[12..16].copy_from_slice(&self.current_a.to_le_bytes());
        b[16..20].copy_from_slice(&self.displacement_um.to_le_bytes());
        b[20..22].copy_from_slice(&self.faults.to_le_bytes());
    }

    fn read_payload(b: &[u8]) -> Frame {
        let f32_at = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Frame {
            seq: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            reference_um: f32_at(4),
            command_v: f32_at(8),
            current_a: f32_at(12),
            displacement_um: f32_at(16),
            faults: u16::from_le_bytes([b[20], b[21]]),
        }
    }

    /// COBS-encodes the frame (format 1) with its CRC into `out`, ending with the 0 delimiter;
    /// returns the length.
    pub fn encode(&self, out: &mut [u8; MAX_ENCODED]) -> usize {
        let mut b = [0u8; RAW_BYTES];
        self.write_payload(&mut b);
        let crc = crc16(&b[..PAYLOAD_BYTES]);
        b[PAYLOAD_BYTES..].copy_from_slice(&crc.to_le_bytes());
        cobs_encode(&b, out)
    }
}

impl TimedFrame {
    /// COBS-encodes the frame (format 2) with its CRC into `out`, ending with the 0 delimiter;
    /// returns the length.
    pub fn encode(&self, out: &mut [u8; MAX_ENCODED]) -> usize {
        let mut b = [0u8; TIMED_RAW_BYTES];
        self.frame.write_payload(&mut b);
        b[PAYLOAD_BYTES..TIMED_PAYLOAD_BYTES].copy_from_slice(&self.tick_cycles.to_le_bytes());
        let crc = crc16(&b[..TIMED_PAYLOAD_BYTES]);
        b[TIMED_PAYLOAD_BYTES..].copy_from_slice(&crc.to_le_bytes());
        cobs_encode(&b, out)
    }

    /// Reads a frame of either format (COBS removed); format 1 has no cycle count.
    fn from_bytes(b: &[u8]) -> Option<(Frame, Option<u16>)> {
        let payload = match b.len() {
            RAW_BYTES => PAYLOAD_BYTES,
            TIMED_RAW_BYTES => TIMED_PAYLOAD_BYTES,
            _ => return None,
        };
        if crc16(&b[..payload]) != u16::from_le_bytes([b[payload], b[payload + 1]]) {
            return None;
        }
        let cycles = (payload == TIMED_PAYLOAD_BYTES).then(|| u16::from_le_bytes([b[22], b[23]]));
        Some((Frame::read_payload(b), cycles))
    }
}

/// Stream decoder with loss accounting.
#[derive(Debug, Clone)]
pub struct Decoder {
    buf: [u8; MAX_ENCODED],
    len: usize,
    overflow: bool,
    last_seq: Option<u32>,
    /// Frames decoded.
    pub frames: u64,
    /// Frames missing from the sequence (gaps between decoded sequence numbers).
    pub lost: u64,
    /// Delimited chunks that failed COBS, length or CRC checks.
    pub corrupt: u64,
    /// Intact command replies ([`Reply`]) seen between the frames.
    pub replies: u64,
}

impl Default for Decoder {
    fn default() -> Self {
        Self {
            buf: [0; MAX_ENCODED],
            len: 0,
            overflow: false,
            last_seq: None,
            frames: 0,
            lost: 0,
            corrupt: 0,
            replies: 0,
        }
    }
}

/// What a decoded frame says about the stream before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    /// The frame.
    pub frame: Frame,
    /// CPU cycles of the tick's interrupt (format 2 frames; `None` for format 1).
    pub tick_cycles: Option<u16>,
    /// Frames missing just before this one (0 when contiguous or after a restart).
    pub gap: u32,
    /// The sequence went backwards or repeated: the sender restarted (a new time axis).
    pub restart: bool,
}

impl Decoder {
    /// Feeds one byte; returns a frame when a valid one completes.
    pub fn push(&mut self, byte: u8) -> Option<Decoded> {
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
        let mut raw = [0u8; MAX_ENCODED];
        let n = if overflow { None } else { cobs_decode(&self.buf[..len], &mut raw) };
        let Some((frame, tick_cycles)) = n.and_then(|n| TimedFrame::from_bytes(&raw[..n])) else {
            // The board's command replies share the line: intact ones are not corruption.
            match n.and_then(|n| Reply::from_frame(&raw[..n])) {
                Some(_) => self.replies += 1,
                None => self.corrupt += 1,
            }
            return None;
        };
        let ahead = match self.last_seq {
            Some(prev) => frame.seq.wrapping_sub(prev),
            None => 1,
        };
        // More than half the counter range ahead means behind: a reset, not 2³¹ lost frames.
        let restart = ahead == 0 || ahead > u32::MAX / 2;
        let gap = if restart { 0 } else { ahead - 1 };
        self.lost += gap as u64;
        self.last_seq = Some(frame.seq);
        self.frames += 1;
        Some(Decoded { frame, tick_cycles, gap, restart })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame(seq: u32) -> Frame {
        Frame { seq, reference_um: 1.5, command_v: -3.0, current_a: 0.0, displacement_um: 12.25, faults: 0 }
    }

    fn stream(frames: impl Iterator<Item = Frame>) -> Vec<u8> {
        let mut out = Vec::new();
        for f in frames {
            let mut buf = [0u8; MAX_ENCODED];
            let n = f.encode(&mut buf);
            out.extend_from_slice(&buf[..n]);
        }
        out
    }

    #[test]
    fn round_trip_including_zero_bytes() {
        let s = stream((0..100).map(frame));
        let mut d = Decoder::default();
        let got: Vec<Frame> = s.iter().filter_map(|&b| d.push(b)).map(|x| x.frame).collect();
        assert_eq!(got.len(), 100);
        assert_eq!(got[37], frame(37));
        assert_eq!((d.lost, d.corrupt), (0, 0));
    }

    #[test]
    fn lost_frames_are_counted() {
        let s = stream((0..50).filter(|k| k % 10 != 3).map(frame));
        let mut d = Decoder::default();
        let gaps: Vec<u32> = s.iter().filter_map(|&b| d.push(b)).map(|x| x.gap).filter(|&g| g > 0).collect();
        assert_eq!(gaps, vec![1; 5]);
        assert_eq!(d.lost, 5);
    }

    /// The board's command replies share the telemetry line: intact ones are counted as replies,
    /// not corruption, and do not break the frame sequence; a damaged one is corruption.
    #[test]
    fn replies_between_frames_are_not_corruption() {
        use crate::command::{Reply, MAX_REPLY_ENCODED};
        let reply = Reply { tag: 7, opcode: 0x02, outcome: Ok(()), faults: 0, armed: true };
        let mut r = [0u8; MAX_REPLY_ENCODED];
        let n = reply.encode(&mut r);
        let mut s = Vec::new();
        for seq in 0..10 {
            s.extend(stream(core::iter::once(frame(seq))));
            s.extend_from_slice(&r[..n]);
        }
        let mut damaged = r;
        damaged[3] ^= 0x01;
        s.extend_from_slice(&damaged[..n]);
        let mut d = Decoder::default();
        let decoded = s.iter().filter_map(|&b| d.push(b)).count();
        assert_eq!((decoded, d.replies, d.corrupt, d.lost), (10, 10, 1, 0));
    }

    /// The published check value of CRC-16/CCITT-FALSE (CRC catalogue: "123456789" → 0x29B1),
    /// and every single byte against the bitwise definition the table replaces.
    #[test]
    fn table_crc_matches_the_standard_and_the_bitwise_definition() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
        let bitwise = |data: &[u8]| {
            let mut crc: u16 = 0xFFFF;
            for &b in data {
                crc ^= (b as u16) << 8;
                for _ in 0..8 {
                    crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
                }
            }
            crc
        };
        for b in 0..=255u8 {
            assert_eq!(crc16(&[b, 0x5A, b]), bitwise(&[b, 0x5A, b]), "byte {b:#04x}");
        }
    }

    /// Format 1 is unchanged on the wire: the encoded frame, COBS removed, is the little-endian
    /// fields in order followed by the CRC, laid out here by hand.
    #[test]
    fn format_1_layout_is_unchanged() {
        let f = Frame {
            seq: 0x0102_0304,
            reference_um: 1.5,
            command_v: -3.0,
            current_a: 0.0,
            displacement_um: 12.25,
            faults: 0x0081,
        };
        let mut raw = Vec::new();
        raw.extend_from_slice(&[0x04, 0x03, 0x02, 0x01]);
        for v in [1.5f32, -3.0, 0.0, 12.25] {
            raw.extend_from_slice(&v.to_bits().to_le_bytes());
        }
        raw.extend_from_slice(&[0x81, 0x00]);
        let crc = crc16(&raw);
        raw.extend_from_slice(&crc.to_le_bytes());
        let mut buf = [0u8; MAX_ENCODED];
        let n = f.encode(&mut buf);
        assert_eq!(n, raw.len() + 2);
        let mut decoded = [0u8; MAX_ENCODED];
        let len = cobs_decode(&buf[..n - 1], &mut decoded).expect("valid COBS");
        assert_eq!(&decoded[..len], &raw[..]);
    }

    /// A stream mixing both formats decodes in order; format 2 carries the cycle count, and its
    /// sequence numbers count gaps like format 1's.
    #[test]
    fn both_formats_decode_from_one_stream() {
        let mut s = Vec::new();
        for seq in 0..20u32 {
            let mut buf = [0u8; MAX_ENCODED];
            let n = if seq % 2 == 0 {
                frame(seq).encode(&mut buf)
            } else {
                TimedFrame { frame: frame(seq), tick_cycles: 4000 + seq as u16 }.encode(&mut buf)
            };
            s.extend_from_slice(&buf[..n]);
        }
        let mut d = Decoder::default();
        let got: Vec<Decoded> = s.iter().filter_map(|&b| d.push(b)).collect();
        assert_eq!(got.len(), 20);
        assert_eq!(got[7].frame, frame(7));
        assert_eq!(got[7].tick_cycles, Some(4007));
        assert_eq!(got[8].tick_cycles, None);
        assert_eq!((d.lost, d.corrupt), (0, 0));
    }

    proptest! {
        /// Random bit flips: every damaged frame is caught (CRC/COBS) and counted, the decoder
        /// resynchronises at the next delimiter, and no wrong frame gets through.
        #[test]
        fn corruption_is_detected_and_counted(flips in proptest::collection::vec((0usize..2600, 0u8..8), 1..20)) {
            let mut s = stream((0..100).map(frame));
            for (pos, bit) in &flips {
                s[*pos] ^= 1 << bit;
            }
            let mut d = Decoder::default();
            let got: Vec<Decoded> = s.iter().filter_map(|&b| d.push(b)).collect();
            for g in &got {
                prop_assert_eq!(g.frame, frame(g.frame.seq));
            }
            prop_assert!(d.frames + d.corrupt + d.lost >= 100 - flips.len() as u64);
            prop_assert!(d.frames >= 100 - 2 * flips.len() as u64);
            // Every frame not delivered is accounted for as lost (seen as a gap).
            let last = got.last().map(|g| g.frame.seq).unwrap_or(0) as u64;
            let first = got.first().map(|g| g.frame.seq).unwrap_or(0) as u64;
            prop_assert_eq!(d.frames + d.lost, last - first + 1);
        }
    }
}
