//! Model specs: any text parses to a spec that prints and re-parses to itself, or to an error
//! that names the offending word (byte ranges must land on character boundaries).
#![no_main]

use host_sim::params::parse_spec;
use libfuzzer_sys::fuzz_target;
use model_core::ModelSpec;

fuzz_target!(|text: &str| {
    match parse_spec(text) {
        Ok(spec) => assert_eq!(ModelSpec::parse(&spec.to_string()), Ok(spec)),
        Err(e) => assert!(!format!("{e:#}").is_empty()),
    }
});
