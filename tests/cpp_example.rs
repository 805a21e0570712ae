//! The C++ example links libdeformcal, calibrates in memory, and prints the same
//! intrinsics as the command line on the same data.
use std::path::Path;
use std::process::Command;

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?}\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn value(text: &str, key: &str) -> f64 {
    let words: Vec<&str> = text.split_whitespace().collect();
    let i = words
        .iter()
        .position(|w| *w == key)
        .unwrap_or_else(|| panic!("no {key} in {text}"));
    words[i + 1].parse().unwrap()
}

#[test]
fn cpp_example_links_the_library_and_matches_the_cli() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The shared library is a build artefact of `cargo build`, not of `cargo test`.
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(Command::new(cargo)
        .current_dir(root)
        .args(["build", "--release", "--lib", "--quiet"]));
    let lib_dir = root.join("target/release");
    assert!(lib_dir.join("libdeformcal.so").exists());
    let dir = tempfile::tempdir().unwrap();
    let exe = dir.path().join("calibrate");
    run(Command::new("g++")
        .args(["-std=c++17", "-Wall", "-Wextra", "-Werror"])
        .arg(root.join("examples/cpp/calibrate.cpp"))
        .arg(format!("-I{}", root.join("include").display()))
        .arg(format!("-L{}", lib_dir.display()))
        .arg("-ldeformcal")
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .arg("-o")
        .arg(&exe));
    let printed = run(&mut Command::new(&exe));
    assert!(printed.contains("converged 1"), "{printed}");
    assert!(printed.contains("bad board rejected"), "{printed}");

    let config = dir.path().join("c.toml");
    std::fs::write(&config, "[data]\nsynthetic = \"t2\"\nimages = 25\nseed = 3\n[calibration]\nmethod = \"full\"\n[output]\ndir = \"out\"\n").unwrap();
    run(Command::new(env!("CARGO_BIN_EXE_deformcal")).args(["--config", config.to_str().unwrap()]));
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    let k = &json["cameras"][0]["intrinsics"];
    for key in ["fx", "fy", "cx", "cy", "k1", "k2", "k3"] {
        let (cpp, cli) = (value(&printed, key), k[key].as_f64().unwrap());
        assert!(
            (cpp - cli).abs() < 1e-8 * cli.abs().max(1.0),
            "{key}: C++ {cpp} vs CLI {cli}"
        );
    }
    assert!((value(&printed, "rmse_px") - json["rmse_px"].as_f64().unwrap()).abs() < 1e-8);
}
