//! The corpus in tests/bad_inputs: every broken input gives one clear message naming
//! the file, the line and the problem (the `# expect:` parts of its config), a
//! non-zero exit, no panic, and no output left behind.
use std::path::Path;
use std::process::Command;

fn run_case(config: &Path, expect: &[String]) {
    let out_dir = tempfile::tempdir().unwrap();
    let output = out_dir.path().join("out");
    let result = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args([
            "--config",
            config.to_str().unwrap(),
            "--output",
            output.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr).to_string();
    let name = config.file_name().unwrap().to_string_lossy();
    assert!(!result.status.success(), "{name}: accepted");
    assert!(!stderr.contains("panicked"), "{name}: panic: {stderr}");
    assert!(
        stderr.starts_with("error: ") && stderr.trim_end().lines().count() == 1,
        "{name}: not one message: {stderr}"
    );
    assert!(
        stderr.len() < 600,
        "{name}: message too long ({} bytes)",
        stderr.len()
    );
    for part in expect {
        assert!(
            stderr.contains(part.as_str()),
            "{name}: `{part}` missing from: {stderr}"
        );
    }
    assert!(!output.exists(), "{name}: output left behind");
}

#[test]
fn every_broken_input_gives_its_error() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_inputs");
    let mut configs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    configs.sort();
    assert!(configs.len() >= 25, "corpus incomplete: {}", configs.len());
    for config in configs {
        let text = std::fs::read_to_string(&config).unwrap();
        let expect: Vec<String> = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# expect: "))
            .unwrap_or_else(|| panic!("{}: no `# expect:` line", config.display()))
            .split(" | ")
            .map(str::to_string)
            .collect();
        run_case(&config, &expect);
    }
}

#[test]
fn a_huge_line_is_reported_briefly() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("huge.csv");
    let mut text = String::from("camera,frame,corner,u,v\ncam0,0,1,2,3\ncam0,0,2,");
    text.push_str(&"x".repeat(8 << 20));
    text.push_str(",4\n");
    std::fs::write(&csv, text).unwrap();
    let config = dir.path().join("huge.toml");
    std::fs::write(
        &config,
        "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n[[cameras]]\nname = \"cam0\"\nwidth = 10\nheight = 10\n[data]\nobservations = \"huge.csv\"\n",
    )
    .unwrap();
    run_case(
        &config,
        &[
            "huge.csv:3:".into(),
            "u `xxxx".into(),
            "is not a number".into(),
        ],
    );
}
