//! The byte framing the drive's UART uses in both directions (telemetry out, commands in,
//! replies out): a CRC-16 over the raw frame, then COBS so that 0x00 only ever delimits frames.

/// CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF), one table lookup per byte.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc = (crc << 8) ^ CRC16_TABLE[((crc >> 8) as u8 ^ b) as usize];
    }
    crc
}

/// The CRC of every leading byte: the bitwise algorithm run once per table entry, at compile
/// time (512 bytes of flash instead of eight shift-and-xor steps per byte in the interrupt).
const CRC16_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// COBS: every 0 byte of `raw` replaced, a 0 delimiter appended; returns the encoded length.
/// `out` must hold `raw.len() + raw.len() / 254 + 2` bytes.
pub fn cobs_encode(raw: &[u8], out: &mut [u8]) -> usize {
    let (mut code_at, mut code, mut n) = (0, 1u8, 1);
    for &b in raw {
        if b != 0 {
            out[n] = b;
            n += 1;
            code += 1;
        }
        if b == 0 || code == 0xFF {
            out[code_at] = code;
            code_at = n;
            n += 1;
            code = 1;
        }
    }
    out[code_at] = code;
    out[n] = 0;
    n + 1
}

/// Undoes [`cobs_encode`] (without the delimiter); `None` for an invalid or too long chunk.
pub fn cobs_decode(enc: &[u8], out: &mut [u8]) -> Option<usize> {
    let (mut i, mut n) = (0, 0);
    while i < enc.len() {
        let code = enc[i] as usize;
        i += 1;
        if code == 0 || i + code - 1 > enc.len() || n + code - 1 > out.len() {
            return None;
        }
        out[n..n + code - 1].copy_from_slice(&enc[i..i + code - 1]);
        n += code - 1;
        i += code - 1;
        if code < 0xFF && i < enc.len() {
            *out.get_mut(n)? = 0;
            n += 1;
        }
    }
    Some(n)
}
