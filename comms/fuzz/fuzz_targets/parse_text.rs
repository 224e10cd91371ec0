//! The text parsers a user or a file feeds: config files, value literals, keys and
//! patterns. Must never panic; a literal that parses must print back to a literal that
//! parses to the same value.
#![no_main]

use std::path::Path;

use comms::{parse_config, parse_literal, Key, Pattern};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = parse_config(Path::new("fuzz.dat"), text);
    let _ = Key::parse(text);
    let _ = Pattern::parse(text);
    if let Ok(value) = parse_literal(text) {
        let printed = value.to_string();
        let again = parse_literal(&printed).expect("a printed literal parses");
        assert_eq!(again.to_string(), printed, "printing is stable");
    }
});
