//! A calibration without a config file: `deformcal calibrate --photos … --board 9x6
//! --square 0.025 --model opencv5` equals the same calibration from a TOML config
//! (OpenCV's sample photos, and an observations CSV with a known truth), a flag
//! beats the config's key, the config.toml written beside the result reruns it to
//! the same numbers, and a bad flag value is refused with the key it sets named.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::sample_photos;

/// The binary, run in `dir` (relative paths on its command line start there).
fn deformcal_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run deformcal")
}

fn succeeds(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{stderr}");
    stderr
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Every number of two calibration.json files agrees to `tol` (relative to the
/// value, absolute below 1), except run times; returns how many were compared.
fn assert_same_numbers(a: &serde_json::Value, b: &serde_json::Value, tol: f64, at: &str) -> usize {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!((x - y).abs() <= tol * x.abs().max(1.0), "{at}: {x} vs {y}");
            1
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}: lengths");
            x.iter()
                .zip(y)
                .enumerate()
                .map(|(i, (x, y))| assert_same_numbers(x, y, tol, &format!("{at}[{i}]")))
                .sum()
        }
        (Value::Object(x), Value::Object(y)) => {
            let keys = |o: &serde_json::Map<String, Value>| -> Vec<String> {
                o.keys().filter(|k| *k != "seconds").cloned().collect()
            };
            assert_eq!(keys(x), keys(y), "{at}: keys");
            keys(x)
                .iter()
                .map(|k| assert_same_numbers(&x[k], &y[k], tol, &format!("{at}.{k}")))
                .sum()
        }
        _ => 0,
    }
}

/// OpenCV's left sample photos (9×6 inner corners, 25 mm in OpenCV's sample
/// calibration), copied into `dir/photos`; None (the test skips) without them.
fn left_photos(dir: &Path) -> Option<PathBuf> {
    sample_photos_of(dir, &["left"])
}

/// OpenCV's sample photos of the given sides (`left`, `right`) in `dir/photos`.
fn sample_photos_of(dir: &Path, sides: &[&str]) -> Option<PathBuf> {
    let system = Path::new("/usr/share/doc/opencv-doc/examples/data");
    let source = if system.join("left01.jpg").exists() {
        system.to_path_buf()
    } else {
        match sample_photos::sample_photos() {
            Ok(p) => p,
            Err(reason) => {
                eprintln!("skipped: no OpenCV sample photos: {reason}");
                return None;
            }
        }
    };
    let photos = dir.join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    for side in sides {
        for k in 1..=14 {
            let name = format!("{side}{k:02}.jpg");
            if source.join(&name).exists() {
                std::fs::copy(source.join(&name), photos.join(&name)).unwrap();
            }
        }
    }
    Some(photos)
}

#[test]
fn flags_alone_equal_the_config_and_the_written_config_reruns_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    if left_photos(d).is_none() {
        return;
    }
    let flags = deformcal_in(
        d,
        &[
            "calibrate",
            "--photos",
            "photos/left*.jpg",
            "--board",
            "9x6",
            "--square",
            "0.025",
            "--model",
            "opencv5",
            "--method",
            "dynamic",
            "--output",
            "by_flags",
        ],
    );
    let stderr = succeeds(&flags);
    assert!(
        stderr.contains("image size 640×480 px, from photos/left01.jpg"),
        "{stderr}"
    );
    std::fs::write(
        d.join("c.toml"),
        "[target]\nrows = 6\ncols = 9\nspacing = 0.025\n\n[[cameras]]\nname = \"cam0\"\n\
         width = 640\nheight = 480\nmodel = \"opencv5\"\n\n[data]\nphotos = \"photos/left*.jpg\"\n\n\
         [calibration]\nmethod = \"dynamic\"\n\n[output]\ndir = \"by_config\"\n",
    )
    .unwrap();
    succeeds(&deformcal_in(d, &["calibrate", "--config", "c.toml"]));
    let by_flags = json(&d.join("by_flags/calibration.json"));
    let by_config = json(&d.join("by_config/calibration.json"));
    assert_eq!(by_flags["method"], "dynamic");
    assert_eq!(by_flags["cameras"][0]["model"], "opencv5");
    assert_eq!(by_flags["frames"].as_array().unwrap().len(), 13);
    let compared = assert_same_numbers(&by_flags, &by_config, 1e-12, "calibration");
    assert!(compared > 200, "only {compared} numbers compared");

    // The config written beside the result names every path absolutely, so it
    // reruns from any folder, here from its own, into a third output.
    let written = std::fs::read_to_string(d.join("by_flags/config.toml")).unwrap();
    let abs_photos = format!(
        "photos = {:?}",
        d.join("photos/left*.jpg").display().to_string()
    );
    assert!(written.contains(&abs_photos), "{written}");
    assert!(
        written.contains("width = 640") && written.contains("height = 480"),
        "{written}"
    );
    let rerun_dir = d.join("by_flags");
    succeeds(&deformcal_in(
        &rerun_dir,
        &[
            "calibrate",
            "--config",
            "config.toml",
            "--output",
            "../rerun",
        ],
    ));
    let rerun = json(&d.join("rerun/calibration.json"));
    assert_same_numbers(&by_flags, &rerun, 1e-12, "calibration");
}

/// A photo map given by flags alone makes one camera per pattern, named by its
/// key and sized from its own first photo: the same calibration as the config
/// that spells both cameras out. A config file with the map and no
/// `[[cameras]]` is completed the same way, for `calibrate` and `detect` alike.
#[test]
fn a_photo_map_makes_one_camera_per_pattern() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    if sample_photos_of(d, &["left", "right"]).is_none() {
        return;
    }
    let map = r#"data.photos={ right = "photos/right*.jpg", left = "photos/left*.jpg" }"#;
    let common = [
        "--board", "9x6", "--square", "0.025", "--method", "standard",
    ];
    let mut args = vec!["calibrate", "--set", map, "--model", "opencv5"];
    args.extend(common);
    args.extend(["--output", "by_flags"]);
    let stderr = succeeds(&deformcal_in(d, &args));
    for line in [
        "image size 640×480 px for camera left, from photos/left01.jpg",
        "image size 640×480 px for camera right, from photos/right01.jpg",
    ] {
        assert!(stderr.contains(line), "{line}: {stderr}");
    }
    let by_flags = json(&d.join("by_flags/calibration.json"));
    let names: Vec<&str> = by_flags["cameras"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["left", "right"]);
    assert_eq!(by_flags["cameras"][1]["model"], "opencv5");

    let photos =
        "[data]\nphotos = { left = \"photos/left*.jpg\", right = \"photos/right*.jpg\" }\n";
    let board =
        "[target]\nrows = 6\ncols = 9\nspacing = 0.025\n[calibration]\nmethod = \"standard\"\n";
    let cameras: String = ["left", "right"]
        .iter()
        .map(|n| {
            format!("[[cameras]]\nname = \"{n}\"\nwidth = 640\nheight = 480\nmodel = \"opencv5\"\n")
        })
        .collect();
    std::fs::write(
        d.join("full.toml"),
        format!("{board}{cameras}{photos}[output]\ndir = \"by_config\"\n"),
    )
    .unwrap();
    succeeds(&deformcal_in(d, &["--config", "full.toml"]));
    let by_config = json(&d.join("by_config/calibration.json"));
    let compared = assert_same_numbers(&by_flags, &by_config, 1e-12, "calibration");
    assert!(compared > 100, "only {compared} numbers compared");

    // The map alone in a file: `detect` and `calibrate` complete it alike.
    std::fs::write(
        d.join("map.toml"),
        format!("{board}{photos}[output]\ndir = \"by_map\"\n"),
    )
    .unwrap();
    let detected = succeeds(&deformcal_in(d, &["detect", "--config", "map.toml"]));
    assert!(
        detected.contains("board found in 26 of 26 images"),
        "{detected}"
    );
    succeeds(&deformcal_in(
        d,
        &["calibrate", "--config", "map.toml", "--model", "opencv5"],
    ));
    let by_map = json(&d.join("by_map/calibration.json"));
    assert_same_numbers(&by_flags, &by_map, 1e-12, "calibration");

    // One pattern and no `[[cameras]]`: `cam0`, sized from its first photo.
    let one = "[data]\nphotos = \"photos/left*.jpg\"\n";
    let cam0 = "[[cameras]]\nname = \"cam0\"\nwidth = 640\nheight = 480\n";
    for (file, text) in [
        ("one.toml", format!("{board}{one}[output]\ndir = \"one\"\n")),
        (
            "one_full.toml",
            format!("{board}{cam0}{one}[output]\ndir = \"one_full\"\n"),
        ),
    ] {
        std::fs::write(d.join(file), text).unwrap();
        succeeds(&deformcal_in(d, &["--config", file]));
    }
    let (one, one_full) = (
        json(&d.join("one/calibration.json")),
        json(&d.join("one_full/calibration.json")),
    );
    assert_eq!(one["cameras"][0]["name"], "cam0");
    assert!(assert_same_numbers(&one, &one_full, 1e-12, "calibration") > 50);

    // A key that is no camera name is refused as the map's, in one line (the
    // sizes read on the way are said only for a config that is accepted).
    let bad = refused(
        d,
        &[
            "calibrate",
            "--set",
            r#"data.photos={ "a/b" = "photos/left*.jpg" }"#,
            "--board",
            "9x6",
            "--square",
            "0.025",
        ],
    );
    assert!(
        bad.contains("data.photos") && bad.contains("`a/b`"),
        "{bad}"
    );
}

/// A t2 observations CSV (13×13 board, 1936×1216, known truth) in `dir`.
fn t2_csv(dir: &Path) {
    succeeds(&deformcal_in(
        dir,
        &[
            "generate", "--preset", "t2", "--images", "12", "--seed", "4", "--out", "gen",
        ],
    ));
    for name in ["observations.csv", "truth.json"] {
        std::fs::rename(dir.join("gen").join(name), dir.join(name)).unwrap();
    }
}

#[test]
fn an_observations_run_equals_the_config_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    t2_csv(d);
    let common = ["--board", "13x13", "--square", "0.07", "--method", "full"];
    let mut args = vec!["calibrate", "--observations", "observations.csv"];
    args.extend(common);
    args.extend(["--image-size", "1936x1216", "--output", "a"]);
    succeeds(&deformcal_in(d, &args));
    std::fs::write(
        d.join("c.toml"),
        "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n[[cameras]]\nname = \"cam0\"\n\
         width = 1936\nheight = 1216\n[data]\nobservations = \"observations.csv\"\n\
         [calibration]\nmethod = \"full\"\n[output]\ndir = \"b\"\n",
    )
    .unwrap();
    succeeds(&deformcal_in(d, &["--config", "c.toml"]));
    let (a, b) = (
        json(&d.join("a/calibration.json")),
        json(&d.join("b/calibration.json")),
    );
    assert!(assert_same_numbers(&a, &b, 1e-12, "calibration") > 100);
    assert_eq!(a["method"], "full");
    // And it is the truth's camera: the flags described the data rightly.
    let truth = json(&d.join("truth.json"));
    let fx = a["cameras"][0]["intrinsics"]["fx"].as_f64().unwrap();
    let true_fx = truth["intrinsics"][0]["fx"].as_f64().unwrap();
    assert!((fx / true_fx - 1.0).abs() < 0.005, "{fx} vs {true_fx}");
}

#[test]
fn a_flag_beats_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("cfg")).unwrap();
    std::fs::write(
        d.join("cfg/c.toml"),
        "[data]\nsynthetic = \"t2\"\nimages = 8\n[calibration]\nmethod = \"full\"\n\
         outlier_k = 4.0\n[output]\ndir = \"from_config\"\n",
    )
    .unwrap();
    let out = deformcal_in(
        d,
        &[
            "calibrate",
            "--config",
            "cfg/c.toml",
            "--method",
            "static",
            "--set",
            "calibration.outlier_k=0",
            "--set",
            "data.images=6",
            "--model",
            "opencv5",
            "--output",
            "flagged",
        ],
    );
    succeeds(&out);
    // The output flag is relative to the working folder, not the config's.
    assert!(!d.join("cfg/from_config").exists() && !d.join("cfg/flagged").exists());
    let result = json(&d.join("flagged/calibration.json"));
    assert_eq!(result["method"], "static");
    assert_eq!(result["frames"].as_array().unwrap().len(), 6);
    assert_eq!(result["cameras"][0]["model"], "opencv5");
    let written = std::fs::read_to_string(d.join("flagged/config.toml")).unwrap();
    for line in [
        "method = \"static\"",
        "outlier_k = 0",
        "images = 6",
        "model = \"opencv5\"",
    ] {
        assert!(
            written.lines().any(|l| l.starts_with(line)),
            "{line}: {written}"
        );
    }
    // Without flags the config's own keys hold.
    succeeds(&deformcal_in(d, &["calibrate", "--config", "cfg/c.toml"]));
    let plain = json(&d.join("cfg/from_config/calibration.json"));
    assert_eq!(plain["method"], "full");
    assert_eq!(plain["frames"].as_array().unwrap().len(), 8);
}

/// Runs a calibration that must fail; its one error line.
fn refused(dir: &Path, args: &[&str]) -> String {
    let out = deformcal_in(dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.starts_with("error: "), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(!dir.join("out").exists(), "{args:?} left an output behind");
    stderr
}

#[test]
fn bad_flag_values_name_the_flag_and_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    t2_csv(d);
    let base = [
        "calibrate",
        "--observations",
        "observations.csv",
        "--board",
        "13x13",
        "--square",
        "0.07",
        "--image-size",
        "1936x1216",
        "--method",
        "standard",
    ];
    let cases: [(&[&str], &[&str]); 10] = [
        (
            &["--set", "calibration.outlier_k=x"],
            &["--set calibration.outlier_k=x", "expected f64"],
        ),
        (
            &["--set", "calibration.outlier_k=1"],
            &["calibration.outlier_k must be 0 (off) or 2 to 100"],
        ),
        (
            &["--outlier-k", "1"],
            &["--outlier-k 1: ", "calibration.outlier_k"],
        ),
        (
            &["--set", "calibration.outlir_k=3"],
            &["unknown key `outlir_k`", "did you mean `outlier_k`"],
        ),
        (
            &["--set", "calibraton.method=full"],
            &[
                "--set calibraton.method=full",
                "did you mean `[calibration]`",
            ],
        ),
        (
            &["--set", "outlier_k"],
            &["--set outlier_k", "section.key=value"],
        ),
        (&["--board", "9"], &["--board 9", "COLSxROWS"]),
        (&["--square", "-1"], &["--square -1: ", "target.spacing"]),
        (
            &["--model", "fisheye"],
            &["--model fisheye", "fisheye", "opencv5"],
        ),
        (
            &["--threads", "0"],
            &["--threads 0: ", "calibration.threads must be 1 to 256"],
        ),
    ];
    for (flags, expected) in cases {
        // A flag under test replaces the base's value of the same flag (clap
        // refuses a flag given twice).
        let mut args: Vec<&str> = Vec::new();
        let mut i = 0;
        while i < base.len() {
            if base[i].starts_with("--") && base[i] == flags[0] {
                i += 2;
                continue;
            }
            args.push(base[i]);
            i += 1;
        }
        args.extend(flags);
        let message = refused(d, &args);
        for e in expected {
            assert!(message.contains(e), "{flags:?}: `{e}` not in {message}");
        }
    }
    // A key of the file keeps its line; one the flags set names the flag.
    std::fs::write(d.join("c.toml"), "[calibration]\nloss_scale_px = 0\n").unwrap();
    let message = refused(
        d,
        &[
            "calibrate",
            "--config",
            "c.toml",
            "--synthetic",
            "t2",
            "--method",
            "standard",
        ],
    );
    assert!(
        message.contains("c.toml: line 2: calibration.loss_scale_px"),
        "{message}"
    );
    // Nothing to calibrate.
    let message = refused(d, &["calibrate", "--board", "9x6"]);
    assert!(
        message.contains("--config") && message.contains("--photos"),
        "{message}"
    );
}

#[test]
fn the_help_lists_the_flags_by_topic() {
    let out = deformcal_in(Path::new("."), &["calibrate", "--help"]);
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    for needle in [
        "--photos <GLOB>",
        "--board <COLSxROWS>",
        "--square <METRES>",
        "--image-size <WxH>",
        "--set <SECTION.KEY=VALUE>",
        "Board:",
        "Method and solver:",
        "calibration.outlier_k",
        "deformcal calibrate --config out/config.toml",
    ] {
        assert!(help.contains(needle), "`{needle}` not in:\n{help}");
    }
}
