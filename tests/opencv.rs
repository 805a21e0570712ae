//! `standard` with loss `none` against OpenCV's own calibration on identical
//! observations, one test per lens model OpenCV has: radial3 (calibrateCamera with
//! CALIB_ZERO_TANGENT_DIST), opencv5 (default flags), opencv8 (CALIB_RATIONAL_MODEL)
//! and kb4 (cv::fisheye::calibrate with CALIB_FIX_SKEW | CALIB_RECOMPUTE_EXTRINSIC).
//! Both tools minimise the same sum of squares, so they must find the same camera.
use crate::common;
use common::*;
use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::{calibrate, Calibration, Dataset, Intrinsics, LensModel, Method, Request};

/// A rigid, perfectly printed board seen through a true lens of `model`, with pixels
/// rounded to float32 because OpenCV's calibrateCamera works in float32: both tools
/// then see exactly the same observations.
fn rigid_data(model: LensModel, images: usize, seed: u64) -> (Dataset, Truth) {
    let mut g = Generator::new(Preset::T2, Some(images), seed).with_models(&[model]);
    g.bend_scale = 0.0;
    g.print_scale = 0.0;
    let (mut d, truth) = g.generate();
    for o in &mut d.observations {
        o.uv = [o.uv[0] as f32 as f64, o.uv[1] as f32 as f64];
    }
    (d, truth)
}

/// Runs tests/tools/opencv_calibrate.py for `model` on the dataset's observations.
fn opencv_calibrate(d: &Dataset, model: LensModel) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("observations.csv");
    deformcal::app::observations_csv::write(d, &csv).unwrap();
    let t = d.target;
    let cam = &d.cameras[0];
    let args = [
        csv.to_str().unwrap().to_string(),
        t.rows.to_string(),
        t.cols.to_string(),
        t.spacing.to_string(),
        cam.width.to_string(),
        cam.height.to_string(),
        model.name().to_string(),
    ];
    run_tool("opencv_calibrate.py", &args, "")
}

fn ours(d: &Dataset) -> Calibration {
    calibrate(
        d,
        &Request {
            method: Method::Standard,
            settings: exact_settings(),
            gauge: None,
        },
    )
    .unwrap()
}

/// OpenCV's result as intrinsics of `model`, read by deformcal's parameter names.
fn opencv_intrinsics(cv: &serde_json::Value, model: LensModel) -> Intrinsics {
    let params: Vec<f64> = model
        .param_names()
        .iter()
        .map(|n| {
            cv[*n]
                .as_f64()
                .unwrap_or_else(|| panic!("OpenCV gave no `{n}`: {cv}"))
        })
        .collect();
    Intrinsics::from_params(model, &params).unwrap()
}

/// Calibrates the same observations with both tools; asserts the mapping error between
/// the two cameras is at most 0.01 px (both ways) and the RMS residuals agree.
fn agrees_with_opencv(model: LensModel, seed: u64) {
    if !python_has(&["cv2"]) {
        return;
    }
    let (d, truth) = rigid_data(model, 25, seed);
    let cv = opencv_calibrate(&d, model);
    let c = ours(&d);
    let a = c.state.intrinsics[0];
    assert_eq!(a.model(), model);
    let b = opencv_intrinsics(&cv, model);
    for (name, x) in a.named() {
        let y = b.get(name).unwrap();
        eprintln!(
            "{model} {name}: deformcal {x:.10e} OpenCV {y:.10e} diff {:.2e}",
            x - y
        );
    }
    let (w, h) = (d.cameras[0].width, d.cameras[0].height);
    let ab = mapping_error(&a, &b, w, h);
    let ba = mapping_error(&b, &a, w, h);
    let rms_cv = cv["rms"].as_f64().unwrap();
    let truth_rot = mapping_error_rot(&truth.intrinsics[0], &a, w, h);
    eprintln!(
        "{model}: mapping error deformcal→OpenCV {ab:.3e} px, OpenCV→deformcal {ba:.3e} px; \
         rms deformcal {:.12} OpenCV {rms_cv:.12}; to truth {:.3e} px ({truth_rot:.3e} px \
         rotation-compensated)",
        c.rmse_px,
        mapping_error(&truth.intrinsics[0], &a, w, h)
    );
    // Guards against both tools failing alike. The noise (0.2 px) leaves a few tenths of
    // a pixel once the virtual rotation is removed (without it, the principal point's
    // uncertainty alone can leave over a pixel); a failed calibration is far worse.
    assert!(truth_rot < 1.0, "{model}: {truth_rot} px from the truth");
    assert!(
        ab <= 0.01 && ba <= 0.01,
        "{model}: mapping error to OpenCV {ab} / {ba} px"
    );
    // The same minimum of the same sum of squares has the same RMS; a smaller RMS on
    // one side would say the other stopped early.
    assert!(
        (c.rmse_px - rms_cv).abs() < 1e-6,
        "{model}: rms deformcal {} vs OpenCV {rms_cv}",
        c.rmse_px
    );
}

#[test]
fn standard_matches_opencv_calibrate_camera() {
    if !python_has(&["cv2"]) {
        return;
    }
    let (mut d, _) = data(Preset::T2, 25, 17, 0.0, 0.0);
    // OpenCV works in float32: hand both tools the same, exactly representable pixels.
    for o in &mut d.observations {
        o.uv = [o.uv[0] as f32 as f64, o.uv[1] as f32 as f64];
    }
    let cv = opencv_calibrate(&d, LensModel::Radial3);
    let ours = ours(&d);
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

#[test]
fn opencv5_matches_calibrate_camera_default_flags() {
    agrees_with_opencv(LensModel::OpenCv5, 21);
}

#[test]
fn opencv8_matches_calibrate_camera_rational_model() {
    agrees_with_opencv(LensModel::OpenCv8, 22);
}

#[test]
fn kb4_matches_fisheye_calibrate() {
    agrees_with_opencv(LensModel::Kb4, 23);
}
