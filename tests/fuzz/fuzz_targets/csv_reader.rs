//! Measurement CSVs and magnetization-loop files: any bytes give a recording that keeps the
//! reader's promises, or an error; never a panic.
#![no_main]

use host_sim::{loops, recording::Recording};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = Recording::parse("fuzz.csv", data) {
        assert!(r.len() >= 3);
        assert!(r.time_s.windows(2).all(|w| w[1] > w[0]), "time must increase");
        let channels = [&r.command_v, &r.current_a, &r.displacement_um, &r.force_n, &r.temperature_c];
        for c in channels.into_iter().flatten() {
            assert_eq!(c.len(), r.len(), "every column has every row");
            assert!(c.iter().all(|v| v.is_finite()));
        }
        assert!(r.command_v.is_some() || r.current_a.is_some(), "a drive column is required");
        assert!(r.dt_s() > 0.0);
    }
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(f) = loops::parse("fuzz.txt", text) {
            assert!(f.h.len() >= 5 && f.h.len() == f.value.len());
            assert!(f.h.iter().chain(&f.value).all(|v| v.is_finite()));
        }
    }
});
