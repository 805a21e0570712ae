//! The command line on good and bad input: clear errors, non-zero exit, no stray files.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn deformcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .expect("run deformcal")
}

struct Case {
    dir: tempfile::TempDir,
}

const CAMERA: &str = "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n";

impl Case {
    fn new() -> Self {
        Case {
            dir: tempfile::tempdir().unwrap(),
        }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }
    /// A config reading `obs.csv` and writing to `out/`.
    fn config(&self, extra: &str) -> PathBuf {
        self.write(
            "c.toml",
            &format!(
                "{CAMERA}\n[data]\nobservations = \"obs.csv\"\n\n[output]\ndir = \"out\"\n{extra}"
            ),
        )
    }
    /// Runs a calibration that must fail; returns its single error message.
    fn fails(&self, config: &Path) -> String {
        let out = deformcal(&["--config", config.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(
            !out.status.success(),
            "expected failure, got success: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "panic: {stderr}");
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert_eq!(
            stderr.trim_end().lines().count(),
            1,
            "one message expected: {stderr}"
        );
        assert!(!self.path("out").exists(), "an output was left behind");
        stderr
    }
}

fn good_csv(case: &Case) -> PathBuf {
    let out = deformcal(&[
        "generate",
        "--preset",
        "t2",
        "--images",
        "12",
        "--seed",
        "4",
        "--out",
        case.dir.path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let p = case.path("observations.csv");
    std::fs::rename(&p, case.path("obs.csv")).unwrap();
    case.path("obs.csv")
}

#[test]
fn generated_data_calibrates_from_csv() {
    let case = Case::new();
    good_csv(&case);
    let config = case.config("[calibration]\nmethod = \"dynamic\"\n");
    let out = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("method dynamic") && stdout.contains("RMSE"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("out/calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["method"], "dynamic");
    assert_eq!(json["converged"], true);
    assert_eq!(json["frames"].as_array().unwrap().len(), 12);
    assert!(json["frames"][0]["deformation"]["a"].is_number());
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("truth.json")).unwrap()).unwrap();
    let fx = json["cameras"][0]["intrinsics"]["fx"].as_f64().unwrap();
    let true_fx = truth["intrinsics"][0]["fx"].as_f64().unwrap();
    assert!((fx / true_fx - 1.0).abs() < 0.005, "{fx} vs {true_fx}");
    // The override flag wins over the config's method.
    let out = deformcal(&[
        "--config",
        config.to_str().unwrap(),
        "--method",
        "static",
        "--output",
        case.path("o2").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("o2/calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["method"], "static");
    assert_eq!(json["static_correction"].as_array().unwrap().len(), 169);
}

#[test]
fn malformed_toml_names_file_and_line() {
    let case = Case::new();
    let c = case.write("c.toml", "[data]\nsynthetic = \"t2\n");
    let e = case.fails(&c);
    assert!(e.contains("c.toml") && e.contains("line 2"), "{e}");
}

#[test]
fn unknown_and_missing_keys_are_named() {
    let case = Case::new();
    let e = case.fails(&case.config("[calibration]\nmethod = \"full\"\nloss_scale = 2.0\n"));
    assert!(e.contains("loss_scale") && e.contains("c.toml"), "{e}");
    let e = case.fails(&case.write(
        "c.toml",
        "[target]\nrows = 13\ncols = 13\n[data]\nobservations = \"x.csv\"\n",
    ));
    assert!(e.contains("spacing"), "{e}");
    let e = case.fails(&case.config("[calibration]\nmethod = \"bendy\"\n"));
    assert!(e.contains("bendy"), "{e}");
    let e = case.fails(&case.config("[calibration]\nloss_scale_px = -1.0\n"));
    assert!(e.contains("calibration.loss_scale_px"), "{e}");
    let e = case.fails(&case.write(
        "c.toml",
        &format!(
            "{}\n[data]\nobservations = \"obs.csv\"\n",
            CAMERA.replace("spacing = 0.07", "spacing = 0.0")
        ),
    ));
    assert!(e.contains("target.spacing"), "{e}");
}

#[test]
fn missing_data_file_is_named() {
    let case = Case::new();
    let e = case.fails(&case.config(""));
    assert!(e.contains("obs.csv"), "{e}");
}

#[test]
fn bad_csv_rows_name_file_and_line() {
    let header = "camera,frame,corner,u,v\n";
    let row = "cam0,0,5,100.5,200.25\n";
    for (body, line, what) in [
        (
            "cam,frame,corner,u,v\ncam0,0,0,1,2\n".to_string(),
            ":1:",
            "bad header",
        ),
        (
            format!("{header}{row}cam0,0,6,abc,3\n"),
            ":3:",
            "not a number",
        ),
        (
            format!("{header}{row}cam0,0,6,NaN,3\n"),
            ":3:",
            "not finite",
        ),
        (
            format!("{header}{row}cam0,0,169,1,3\n"),
            ":3:",
            "outside the 13 × 13 board",
        ),
        (
            format!("{header}{row}cam9,0,6,1,3\n"),
            ":3:",
            "unknown camera `cam9`",
        ),
        (
            format!("{header}{row}{row}"),
            ":3:",
            "duplicate observation",
        ),
        (
            format!("{header}{row}cam0,0,6\n"),
            ":3:",
            "expected 5 fields",
        ),
        (
            format!("{header}cam0,x,6,1,2\n"),
            ":2:",
            "frame `x` is not an integer",
        ),
        (String::new(), ":1:", "empty"),
        ("\0\x01binary".to_string(), ":1:", "binary"),
        (header.to_string(), ":1:", "no observations"),
    ] {
        let case = Case::new();
        case.write("obs.csv", &body);
        let e = case.fails(&case.config(""));
        assert!(
            e.contains(&format!("obs.csv{line}")) && e.contains(what),
            "{what}: {e}"
        );
    }
}

#[test]
fn too_few_images_are_refused_with_the_reason() {
    let case = Case::new();
    good_csv(&case);
    let text = std::fs::read_to_string(case.path("obs.csv")).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("camera") || l.starts_with("cam0,0,") || l.starts_with("cam0,1,"))
        .collect();
    case.write("obs.csv", &(kept.join("\n") + "\n"));
    let e = case.fails(&case.config(""));
    assert!(
        e.contains("2 usable image(s)") && e.contains("at least 3"),
        "{e}"
    );
}

#[test]
fn bad_flags_are_refused() {
    let case = Case::new();
    let c = case.write(
        "c.toml",
        "[data]\nsynthetic = \"t2\"\nimages = 5\n[output]\ndir = \"out\"\n",
    );
    let out = deformcal(&["--config", c.to_str().unwrap(), "--method", "wobbly"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("wobbly"));
    assert!(!case.path("out").exists());
    let out = deformcal(&[]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--config"));
}

#[test]
fn warnings_go_to_stderr_and_results_to_stdout() {
    let case = Case::new();
    good_csv(&case);
    let text = std::fs::read_to_string(case.path("obs.csv")).unwrap();
    // One corner moved far outside the image: dropped with a warning.
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let fields: Vec<&str> = lines[5].split(',').collect();
    lines[5] = format!(
        "{},{},{},7160,{}",
        fields[0], fields[1], fields[2], fields[4]
    );
    case.write("obs.csv", &(lines.join("\n") + "\n"));
    let out = deformcal(&["--config", case.config("").to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("RMSE"), "{stdout}");
    assert!(!stdout.contains("warning"), "{stdout}");
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("warning: 1 observation(s) outside the image dropped")),
        "{stderr}"
    );
}

#[test]
fn too_few_usable_images_say_why_the_others_were_dropped() {
    let case = Case::new();
    // Three frames whose corners all lie at one pixel: no homography, no view.
    let mut text = String::from("camera,frame,corner,u,v\n");
    for frame in 0..3 {
        for corner in 0..169 {
            text += &format!("cam0,{frame},{corner},500,{}\n", 400 + frame);
        }
    }
    case.write("obs.csv", &text);
    let e = case.fails(&case.config(""));
    assert!(
        e.contains("0 usable image(s)")
            && e.contains("frame 0 skipped: its corners are collinear or degenerate")
            && e.contains("frame 2 skipped"),
        "{e}"
    );
}
