//! What ended the previous run, kept across the reset that follows it.
//!
//! A panic or a HardFault turns the bridge off and leaves the watchdog to reset the board; the
//! next boot sees only "watchdog" in the reset flags. So the handler first writes a
//! [`CrashRecord`] into eight words that survive a system reset (on the board: the TAMP backup
//! registers, which only a power cycle or a backup-domain reset clears), and every boot reads
//! them back, says what they hold and counts itself in them. A record is believed only when its
//! tag and checksum agree: backup registers after a power cycle read 0, and a half-written record
//! (a reset in the middle of the write) fails the checksum.

use core::fmt;

/// How many 32-bit words a record takes.
pub const CRASH_WORDS: usize = 8;

/// "GMAC" in ASCII: the first word of every record.
const TAG: u32 = 0x474D_4143;
const KIND_PANIC: u32 = 1;
const KIND_HARD_FAULT: u32 = 2;
/// Bytes of the panic's source path kept: its end, where the file's name is.
pub const FILE_TAIL: usize = 12;
/// The boot count saturates here (it shares its word with the kind).
pub const MAX_BOOTS: u32 = 0x00FF_FFFF;

/// What stopped the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Crash {
    /// A Rust panic: where in the source it was raised.
    Panic {
        /// The last [`FILE_TAIL`] bytes of the source path (fewer when the path is shorter),
        /// zero-padded.
        file_tail: [u8; FILE_TAIL],
        /// Line in that file.
        line: u32,
        /// Column in that line.
        column: u32,
    },
    /// A HardFault: the fault status registers (ARMv7-M SCB CFSR, HFSR, BFAR).
    HardFault {
        /// Configurable fault status.
        cfsr: u32,
        /// HardFault status.
        hfsr: u32,
        /// The bus fault's address, when CFSR.BFARVALID says it holds one.
        bus_fault_address: Option<u32>,
        /// The handler judged it a stack overflow (a bus fault just below the stack).
        stack_overflow: bool,
    },
}

impl Crash {
    /// A panic at `file`:`line`:`column`, keeping the end of the path.
    pub fn panic_at(file: &str, line: u32, column: u32) -> Self {
        let bytes = file.as_bytes();
        let tail = &bytes[bytes.len().saturating_sub(FILE_TAIL)..];
        let mut file_tail = [0; FILE_TAIL];
        file_tail[..tail.len()].copy_from_slice(tail);
        Self::Panic { file_tail, line, column }
    }
}

/// A crash and the boots since it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CrashRecord {
    /// What stopped the run.
    pub crash: Crash,
    /// Boots that have read this record before the current one: 0 on the first boot after the
    /// crash (the run just before this one ended in it).
    pub boots_since: u32,
}

impl CrashRecord {
    /// The words to store for a crash that just happened.
    pub fn encode_new(crash: Crash) -> [u32; CRASH_WORDS] {
        Self { crash, boots_since: 0 }.encode()
    }

    /// The words of this record.
    pub fn encode(&self) -> [u32; CRASH_WORDS] {
        let mut w = [0; CRASH_WORDS];
        w[0] = TAG;
        let kind = match self.crash {
            Crash::Panic { file_tail, line, column } => {
                w[2] = line;
                w[3] = column;
                for (word, bytes) in w[4..7].iter_mut().zip(file_tail.chunks_exact(4)) {
                    *word = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
                }
                KIND_PANIC
            }
            Crash::HardFault { cfsr, hfsr, bus_fault_address, stack_overflow } => {
                w[2] = cfsr;
                w[3] = hfsr;
                w[4] = bus_fault_address.unwrap_or(0);
                w[5] = u32::from(bus_fault_address.is_some()) | u32::from(stack_overflow) << 1;
                KIND_HARD_FAULT
            }
        };
        w[1] = kind | self.boots_since.min(MAX_BOOTS) << 8;
        w[7] = checksum(&w[..7]);
        w
    }

    /// The record the words hold, or `None` when they hold none (after a power cycle, a
    /// half-finished write, or anything else whose tag or checksum does not agree).
    pub fn decode(w: &[u32; CRASH_WORDS]) -> Option<Self> {
        if w[0] != TAG || w[7] != checksum(&w[..7]) {
            return None;
        }
        let boots_since = w[1] >> 8;
        let crash = match w[1] & 0xFF {
            KIND_PANIC => {
                let mut file_tail = [0; FILE_TAIL];
                for (bytes, word) in file_tail.chunks_exact_mut(4).zip(&w[4..7]) {
                    bytes.copy_from_slice(&word.to_le_bytes());
                }
                Crash::Panic { file_tail, line: w[2], column: w[3] }
            }
            KIND_HARD_FAULT => Crash::HardFault {
                cfsr: w[2],
                hfsr: w[3],
                bus_fault_address: (w[5] & 1 != 0).then_some(w[4]),
                stack_overflow: w[5] & 2 != 0,
            },
            _ => return None,
        };
        Some(Self { crash, boots_since })
    }

    /// The words after one more boot has read the record.
    pub fn aged(&self) -> [u32; CRASH_WORDS] {
        Self { boots_since: self.boots_since.saturating_add(1).min(MAX_BOOTS), ..*self }.encode()
    }
}

/// FNV-1a over the words' bytes: any one flipped bit, and a record cut short, changes it.
fn checksum(words: &[u32]) -> u32 {
    let mut h: u32 = 0x811C_9DC5;
    for byte in words.iter().flat_map(|w| w.to_le_bytes()) {
        h = (h ^ u32::from(byte)).wrapping_mul(0x0100_0193);
    }
    h
}

impl fmt::Display for Crash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Crash::Panic { file_tail, line, column } => {
                let end = file_tail.iter().position(|&b| b == 0).unwrap_or(FILE_TAIL);
                // The tail may start inside a multi-byte character: skip its continuation bytes.
                let start = file_tail[..end].iter().position(|&b| b & 0xC0 != 0x80).unwrap_or(end);
                let file = core::str::from_utf8(&file_tail[start..end]).unwrap_or("?");
                write!(f, "panic at …{file}:{line}:{column}")
            }
            Crash::HardFault { cfsr, hfsr, bus_fault_address, stack_overflow } => {
                write!(f, "HardFault (CFSR {cfsr:#010x}, HFSR {hfsr:#010x}")?;
                if let Some(a) = bus_fault_address {
                    write!(f, ", bus fault at {a:#010x}")?;
                }
                f.write_str(")")?;
                if stack_overflow {
                    f.write_str(": stack overflow")?;
                }
                Ok(())
            }
        }
    }
}

impl fmt::Display for CrashRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.boots_since {
            0 => write!(f, "the run before this boot ended in a {}", self.crash),
            n => {
                write!(f, "the run {} runs before this one ended in a {} (no crash since)", n + 1, self.crash)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault() -> Crash {
        Crash::HardFault {
            cfsr: 0x0000_8200,
            hfsr: 0x4000_0000,
            bus_fault_address: Some(0x1FFF_FFF8),
            stack_overflow: true,
        }
    }

    #[test]
    fn a_record_reads_back_as_written() {
        for crash in
            [Crash::panic_at("firmware/src/drive.rs", 123, 9), Crash::panic_at("a.rs", 1, 2), fault()]
        {
            let words = CrashRecord::encode_new(crash);
            assert_eq!(CrashRecord::decode(&words), Some(CrashRecord { crash, boots_since: 0 }));
        }
    }

    /// Backup registers after a power cycle (all zero), erased flash-like words (all ones) and
    /// every single flipped bit of a valid record read as no record.
    #[test]
    fn only_a_whole_record_is_believed() {
        assert_eq!(CrashRecord::decode(&[0; CRASH_WORDS]), None);
        assert_eq!(CrashRecord::decode(&[u32::MAX; CRASH_WORDS]), None);
        let words = CrashRecord::encode_new(fault());
        for i in 0..CRASH_WORDS {
            for bit in 0..32 {
                let mut w = words;
                w[i] ^= 1 << bit;
                assert_eq!(CrashRecord::decode(&w), None, "word {i} bit {bit}");
            }
        }
        // A write cut short: the first words new, the rest still the old (zero) ones.
        for k in 1..CRASH_WORDS {
            let mut w = [0; CRASH_WORDS];
            w[..k].copy_from_slice(&words[..k]);
            assert_eq!(CrashRecord::decode(&w), None, "{k} words written");
        }
    }

    #[test]
    fn each_boot_counts_itself_and_the_count_saturates() {
        let mut words = CrashRecord::encode_new(Crash::panic_at("x.rs", 7, 1));
        for n in 0..3 {
            let r = CrashRecord::decode(&words).unwrap();
            assert_eq!(r.boots_since, n);
            words = r.aged();
        }
        let old = CrashRecord { crash: fault(), boots_since: MAX_BOOTS };
        assert_eq!(CrashRecord::decode(&old.aged()).unwrap().boots_since, MAX_BOOTS);
    }

    #[test]
    fn the_record_says_where_and_when() {
        let words = CrashRecord::encode_new(Crash::panic_at("/home/me/gma/firmware/src/drive.rs", 123, 9));
        let r = CrashRecord::decode(&words).unwrap();
        assert_eq!(r.to_string(), "the run before this boot ended in a panic at …src/drive.rs:123:9");
        let r = CrashRecord::decode(&r.aged()).unwrap();
        assert_eq!(
            r.to_string(),
            "the run 2 runs before this one ended in a panic at …src/drive.rs:123:9 (no crash since)"
        );
        assert_eq!(
            fault().to_string(),
            "HardFault (CFSR 0x00008200, HFSR 0x40000000, bus fault at 0x1ffffff8): stack overflow"
        );
        // A path cut inside a multi-byte character shows the characters that are whole.
        let s = Crash::panic_at("src/ä_äääää.rs", 1, 1).to_string();
        assert!(s.ends_with("ääää.rs:1:1"), "{s}");
    }
}
