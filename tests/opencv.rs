//! `standard` with loss `none` against OpenCV's calibrateCamera on identical observations.
mod common;
use common::*;
use deformcal::model::synthetic::Preset;
use deformcal::solver::problem::Loss;
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Method, Request};
use std::process::Command;

/// Debian's interpreter, where python3-opencv installs cv2.
const PYTHON: &str = "/usr/bin/python3";

#[test]
fn standard_matches_opencv_calibrate_camera() {
    let (mut d, _) = data(Preset::T2, 25, 17, 0.0, 0.0);
    // OpenCV works in float32: hand both tools the same, exactly representable pixels.
    for o in &mut d.observations {
        o.uv = [o.uv[0] as f32 as f64, o.uv[1] as f32 as f64];
    }
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("observations.csv");
    deformcal::app::observations_csv::write(&d, &csv).unwrap();
    let t = d.target;
    let cam = &d.cameras[0];
    let out = Command::new(PYTHON)
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/tools/opencv_calibrate.py"
        ))
        .arg(&csv)
        .args([
            t.rows.to_string(),
            t.cols.to_string(),
            t.spacing.to_string(),
        ])
        .args([cam.width.to_string(), cam.height.to_string()])
        .output()
        .expect("run /usr/bin/python3 (apt-get install python3-opencv)");
    assert!(
        out.status.success(),
        "OpenCV script failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cv: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();

    let settings = SolverSettings {
        loss: Loss::None,
        function_tolerance: 1e-15,
        parameter_tolerance: 1e-15,
        gradient_tolerance: 1e-15,
        max_iterations: 500,
        ..SolverSettings::default()
    };
    let ours = calibrate(
        &d,
        &Request {
            method: Method::Standard,
            settings,
            gauge: None,
        },
    )
    .unwrap();
    let k = ours.state.intrinsics[0];
    let get = |key: &str| cv[key].as_f64().unwrap();
    for (name, a, b, tol) in [
        ("fx", k.fx(), get("fx"), 5e-4),
        ("fy", k.fy(), get("fy"), 5e-4),
        ("cx", k.cx(), get("cx"), 5e-4),
        ("cy", k.cy(), get("cy"), 5e-4),
        ("k1", k.get("k1").unwrap(), get("k1"), 2e-6),
        ("k2", k.get("k2").unwrap(), get("k2"), 2e-5),
        ("k3", k.get("k3").unwrap(), get("k3"), 2e-4),
        ("rms", ours.rmse_px, get("rms"), 1e-6),
    ] {
        eprintln!("{name}: deformcal {a:.9} OpenCV {b:.9} diff {:.2e}", a - b);
        assert!((a - b).abs() < tol, "{name}: deformcal {a} vs OpenCV {b}");
    }
}
