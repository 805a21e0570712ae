#![no_main]
//! The config parser never panics: any text is a config or an error.
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = deformcal::Config::parse(text, Path::new("/fuzz/config.toml"));
    }
});
