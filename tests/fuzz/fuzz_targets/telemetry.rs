//! Telemetry decoding: any byte stream yields only frames whose encoding decodes back to
//! themselves, with every delimited chunk counted as a frame or as corrupt.
#![no_main]

use gma_control::telemetry::{Decoder, MAX_ENCODED};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut d = Decoder::default();
    let mut decoded = 0u64;
    for &b in data {
        if let Some(x) = d.push(b) {
            decoded += 1;
            let mut buf = [0u8; MAX_ENCODED];
            let n = x.frame.encode(&mut buf);
            let mut again = Decoder::default();
            let back: Vec<_> = buf[..n].iter().filter_map(|&b| again.push(b)).collect();
            assert_eq!(back.len(), 1);
            assert_eq!(back[0].frame.seq, x.frame.seq);
            assert_eq!(back[0].frame.faults, x.frame.faults);
        }
    }
    assert_eq!(d.frames, decoded);
    let delimiters = data.iter().filter(|&&b| b == 0).count() as u64;
    assert!(d.frames + d.corrupt <= delimiters);
});
