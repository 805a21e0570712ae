//! `deformcal compare`: the mapping error between two calibrations beside the
//! difference their uncertainties predict. Two independent calibrations of the
//! same rigid-board camera differ by about what the noise explains; `standard`
//! against `dynamic` on bending boards differs by far more.
use crate::common;
use common::*;
use deformcal::app::calibration_json::CalibrationJson;
use deformcal::app::compare::{compare, REAL_DIFFERENCE_FACTOR};
use deformcal::model::synthetic::Preset;
use deformcal::solver::problem::Loss;
use deformcal::Method;
use std::process::Command;

fn json(preset: Preset, seed: u64, bend: f64, method: Method) -> CalibrationJson {
    let (d, _) = data(preset, 30, seed, bend, 0.0);
    let mut c = run(&d, method, Loss::Cauchy);
    c.detector_noise_px = Some(0.15);
    // The figures the files report, at that noise.
    c.assess();
    CalibrationJson::from(&c)
}

#[test]
fn independent_calibrations_differ_by_their_noise_and_a_bias_by_more() {
    // Four pairs of independent rigid-board calibrations: on average their
    // difference is what the two uncertainties predict.
    let ratios: Vec<f64> = (0..4)
        .map(|i| {
            let a = json(Preset::T2, 20 + 2 * i, 0.0, Method::Standard);
            let b = json(Preset::T2, 21 + 2 * i, 0.0, Method::Standard);
            let d = &compare(&a, &b).unwrap()[0];
            eprintln!(
                "rigid pair {i}: {:.4} px rot., {}",
                d.mapping_error_rot_px,
                d.verdict()
            );
            d.ratio().expect("both files carry their uncertainty")
        })
        .collect();
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    assert!((0.5..=REAL_DIFFERENCE_FACTOR).contains(&mean), "{ratios:?}");
    // On T3's strongly bending boards `standard` is biased: far more than noise
    // from `dynamic` (on the same data, so their own noise mostly cancels).
    let a = json(Preset::T3, 30, 1.0, Method::Standard);
    let b = json(Preset::T3, 30, 1.0, Method::Dynamic);
    let d = &compare(&a, &b).unwrap()[0];
    eprintln!(
        "standard vs dynamic: {:.4} px rot., {}",
        d.mapping_error_rot_px,
        d.verdict()
    );
    assert!(d.ratio().unwrap() > 3.0 * REAL_DIFFERENCE_FACTOR, "{d:?}");
    assert!(
        d.verdict().starts_with("a real difference"),
        "{}",
        d.verdict()
    );
}

#[test]
fn compare_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let a = json(Preset::T3, 31, 1.0, Method::Standard);
    let b = json(Preset::T3, 31, 1.0, Method::Dynamic);
    let (pa, pb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    std::fs::write(&pa, serde_json::to_string(&a).unwrap()).unwrap();
    std::fs::write(&pb, serde_json::to_string(&b).unwrap()).unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &pb])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d = &compare(&a, &b).unwrap()[0];
    assert!(
        text.contains(&format!("{:.3} px", d.mapping_error_px)),
        "{text}"
    );
    assert!(text.contains("a real difference"), "{text}");
    // A calibration against itself: no difference at all.
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &pa])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("     0.000 px     0.000 px"), "{text}");
    // A file that is not a calibration names itself.
    std::fs::write(dir.path().join("x.json"), "{\"x\": 1}").unwrap();
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &dir.path().join("x.json")])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("x.json:1: not a deformcal calibration.json: missing field `method`"),
        "{err}"
    );
}

/// Runs `deformcal compare a b`, killed after `limit`: (exit code, stdout, stderr).
fn compare_cli(
    a: &std::path::Path,
    b: &std::path::Path,
    limit: std::time::Duration,
) -> (Option<i32>, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .arg("compare")
        .args([a, b])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("compare still running after {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

#[test]
fn a_huge_image_is_compared_on_a_bounded_grid_and_an_absurd_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut a = serde_json::to_value(json(Preset::T2, 32, 0.0, Method::Standard)).unwrap();
    // 4 000 000 000 pixels: the 20 px grid of docs/conventions.md §3 would be ten million points.
    a["cameras"][0]["width"] = 80_000.into();
    a["cameras"][0]["height"] = 50_000.into();
    let mut b = a.clone();
    let fx = a["cameras"][0]["intrinsics"]["fx"].as_f64().unwrap();
    b["cameras"][0]["intrinsics"]["fx"] = (fx * 1.01).into();
    let (pa, pb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    std::fs::write(&pa, a.to_string()).unwrap();
    std::fs::write(&pb, b.to_string()).unwrap();
    let limit = std::time::Duration::from_secs(20);
    let (code, text, err) = compare_cli(&pa, &pa, limit);
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("     0.000 px     0.000 px"), "{text}");
    // 80 000 × 50 000 needs a 640 px step to stay within 10 000 points.
    assert!(text.contains("(640 px grid)"), "{text}");
    let (code, text, err) = compare_cli(&pa, &pb, limit);
    assert_eq!(code, Some(0), "{err}");
    assert!(!text.contains(" inf px") && !text.contains("NaN"), "{text}");
    // Beyond any sensor: refused, the file and the key named.
    a["cameras"][0]["width"] = 10_000_000.into();
    std::fs::write(&pa, a.to_string()).unwrap();
    let (code, _, err) = compare_cli(&pa, &pb, limit);
    assert_eq!(code, Some(1));
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("a.json: cameras[0] `cam0`: width must be 1 to 100000 pixels (got 10000000)"),
        "{err}"
    );
}

/// A file name, how to spoil a good calibration.json, and the message expected.
type Edit = (&'static str, fn(&mut serde_json::Value), &'static str);

#[test]
fn unusable_calibrations_are_refused_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let good = serde_json::to_value(json(Preset::T2, 33, 0.0, Method::Standard)).unwrap();
    let pa = dir.path().join("good.json");
    std::fs::write(&pa, good.to_string()).unwrap();
    let limit = std::time::Duration::from_secs(60);
    let edits: [Edit; 4] = [
        (
            "negative_fx.json",
            |v| v["cameras"][0]["intrinsics"]["fx"] = (-800.0).into(),
            "intrinsics.fx must be positive (got -800)",
        ),
        (
            "zero_fy.json",
            |v| v["cameras"][0]["intrinsics"]["fy"] = 0.0.into(),
            "intrinsics.fy must be positive (got 0)",
        ),
        (
            "zero_height.json",
            |v| v["cameras"][0]["height"] = 0.into(),
            "height must be 1 to 100000 pixels (got 0)",
        ),
        (
            "FAILED-calibration.json",
            |v| v["failure"] = serde_json::json!({"reasons": ["the RMSE is 9 px"], "hints": []}),
            "this calibration FAILED its guard rails (the RMSE is 9 px)",
        ),
    ];
    for (name, edit, message) in edits {
        let mut bad = good.clone();
        edit(&mut bad);
        let pb = dir.path().join(name);
        std::fs::write(&pb, bad.to_string()).unwrap();
        let (code, _, err) = compare_cli(&pa, &pb, limit);
        assert_eq!(code, Some(1), "{name}: {err}");
        assert_eq!(err.lines().count(), 1, "{name}: {err}");
        assert!(
            err.contains(&format!("{name}: ")) && err.contains(message),
            "{name}: {err}"
        );
    }
    // JSON has no NaN, but the library's callers may hand one over.
    let mut a: CalibrationJson = serde_json::from_value(good).unwrap();
    let b = a.clone();
    a.cameras[0].intrinsics.set("k1", f64::NAN);
    let err = compare(&a, &b).unwrap_err().to_string();
    assert!(
        err.contains("the first calibration: cameras[0] `cam0`: intrinsics.k1 is not finite"),
        "{err}"
    );
}
