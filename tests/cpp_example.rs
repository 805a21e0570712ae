//! The C++ example links libdeformcal, reads an observations CSV, calibrates through
//! `deformcal_calibrate_ex`, and prints the same intrinsics, RMSE and per-frame
//! poses, bends and RMSEs as the command line writes to calibration.json for the
//! same CSV; a frame with too few corners comes back as unused.
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

/// The number after `key` in a line of the example's output.
fn value(line: &str, key: &str) -> f64 {
    let words: Vec<&str> = line.split_whitespace().collect();
    let i = words
        .iter()
        .position(|w| *w == key)
        .unwrap_or_else(|| panic!("no {key} in {line}"));
    words[i + 1].parse().unwrap()
}

/// The three numbers after `key`.
fn triple(line: &str, key: &str) -> [f64; 3] {
    let words: Vec<&str> = line.split_whitespace().collect();
    let i = words.iter().position(|w| *w == key).unwrap();
    [1, 2, 3].map(|k| words[i + k].parse().unwrap())
}

fn close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-8 * b.abs().max(1.0),
        "{what}: C++ {a} vs CLI {b}"
    );
}

/// Builds the shared library and compiles the example against it.
fn build_example(root: &Path, dir: &Path) -> std::path::PathBuf {
    // The shared library is a build artefact of `cargo build`, not of `cargo test`.
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(Command::new(cargo)
        .current_dir(root)
        .args(["build", "--release", "--lib", "--quiet"]));
    let lib_dir = root.join("target/release");
    let exe = dir.join("calibrate");
    run(Command::new("g++")
        .args(["-std=c++17", "-Wall", "-Wextra", "-Werror"])
        .arg(root.join("examples/cpp/calibrate.cpp"))
        .arg(format!("-I{}", root.join("include").display()))
        .arg(format!("-L{}", lib_dir.display()))
        .arg("-ldeformcal")
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .arg("-o")
        .arg(&exe));
    exe
}

/// One printed frame line against the frame of calibration.json.
fn same_frame(line: &str, f: &serde_json::Value) {
    assert!(line.contains("used 1"), "{line}");
    close(
        value(line, "rmse_px"),
        f["rmse_px"].as_f64().unwrap(),
        "frame rmse",
    );
    close(
        value(line, "observations"),
        f["observations"].as_f64().unwrap(),
        "count",
    );
    let d = &f["deformation"];
    let bend = ["a", "b", "c"].map(|k| d[k].as_f64().unwrap());
    for (name, cpp, cli) in [
        ("rotation", triple(line, "rotation"), f["rotation"].clone()),
        (
            "translation",
            triple(line, "translation"),
            f["translation"].clone(),
        ),
        ("bend", triple(line, "bend"), serde_json::json!(bend)),
    ] {
        for i in 0..3 {
            close(cpp[i], cli[i].as_f64().unwrap(), name);
        }
    }
    close(
        value(line, "max_out_of_plane_m"),
        f["max_out_of_plane_m"].as_f64().unwrap(),
        "max_out_of_plane_m",
    );
}

#[test]
fn cpp_example_reads_a_csv_and_matches_the_cli_frame_by_frame() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let exe = build_example(root, dir.path());
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let data = dir.path().join("t2");
    run(Command::new(bin)
        .args([
            "generate", "--preset", "t2", "--images", "25", "--seed", "3",
        ])
        .arg("--out")
        .arg(&data));
    // A frame of three corners: the calibration drops it.
    let csv = data.join("observations.csv");
    let mut text = std::fs::read_to_string(&csv).unwrap();
    text.push_str("cam0,999,0,900.5,600.5\ncam0,999,1,910.5,600.5\ncam0,999,13,900.5,610.5\n");
    std::fs::write(&csv, text).unwrap();
    let printed = run(Command::new(&exe)
        .arg(&csv)
        .args(["13", "13", "0.07", "1936", "1216", "full", "radial3"]));

    let config = dir.path().join("c.toml");
    std::fs::write(&config, "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n[data]\nobservations = \"t2/observations.csv\"\n[calibration]\nmethod = \"full\"\n[output]\ndir = \"out\"\n").unwrap();
    run(Command::new(bin).args(["--config", config.to_str().unwrap()]));
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    let head = printed.lines().next().unwrap();
    assert!(head.contains("converged 1"), "{printed}");
    close(
        value(head, "rmse_px"),
        json["rmse_px"].as_f64().unwrap(),
        "rmse_px",
    );
    let camera = printed
        .lines()
        .find(|l| l.starts_with("camera cam0"))
        .unwrap();
    for key in ["fx", "fy", "cx", "cy", "k1", "k2", "k3"] {
        let cli = json["cameras"][0]["intrinsics"][key].as_f64().unwrap();
        close(value(camera, key), cli, key);
    }
    let frames: Vec<&str> = printed
        .lines()
        .filter(|l| l.starts_with("frame "))
        .collect();
    let cli_frames = json["frames"].as_array().unwrap();
    assert_eq!((frames.len(), cli_frames.len()), (26, 25), "{printed}");
    for f in cli_frames {
        let id = f["frame"].as_i64().unwrap();
        let prefix = format!("frame {id} ");
        same_frame(frames.iter().find(|l| l.starts_with(&prefix)).unwrap(), f);
    }
    let dropped = frames.iter().find(|l| l.starts_with("frame 999 ")).unwrap();
    assert!(
        dropped.contains("used 0 observations 0 rmse_px nan"),
        "{dropped}"
    );
}
