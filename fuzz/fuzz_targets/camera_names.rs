#![no_main]
//! Camera names: any name in a config is refused with an error or is of the safe
//! set (docs/conventions.md, Camera names), and the accepted names of a config
//! never collide in an export (file names or opencv.yaml keys). Also feeds the
//! raw names to the export helpers, which must not panic on anything a
//! calibration.json could hold.
use deformcal::app::config::camera_name_error;
use deformcal::app::exports::{name_clash, printable};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

/// A TOML basic string holding `s` exactly.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Up to three names, separated by NUL, so collisions between them are reached.
    let names: Vec<&str> = text.split('\0').take(3).collect();
    for n in &names {
        let shown = printable(n);
        assert!(!shown.contains('\n') && !shown.contains('\r'), "{shown:?}");
    }
    let _ = name_clash(names.iter().copied());
    let mut config = String::from("[target]\nrows = 3\ncols = 4\nspacing = 0.1\n");
    for n in &names {
        config.push_str(&format!(
            "[[cameras]]\nname = {}\nwidth = 10\nheight = 10\n",
            toml_string(n)
        ));
    }
    config.push_str("[data]\nobservations = \"o.csv\"\n");
    if let Ok(c) = deformcal::Config::parse(&config, Path::new("/fuzz/config.toml")) {
        for cam in &c.cameras {
            assert!(camera_name_error(&cam.name).is_none(), "{:?}", cam.name);
            assert!(
                cam.name
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || "_-. ".contains(ch)),
                "{:?}",
                cam.name
            );
        }
        assert!(name_clash(c.cameras.iter().map(|cam| cam.name.as_str())).is_none());
    }
});
