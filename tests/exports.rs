//! ROS, Kalibr and COLMAP exports read back as their consumers read them, for every
//! lens model, alone and as a stereo pair: projections through the exported files
//! agree with ours to 1e-6 px, the stereo rectification equals `cv2.stereoRectify`,
//! Kalibr's chain transform equals the calibrated pose, and every camera a format
//! cannot hold is left out with exactly the warning the user sees.
use crate::common;
use common::{python_has, run_tool};
use deformcal::app::calibration_json::{CalibrationJson, CameraJson};
use deformcal::app::exports::OptimizationInputs;
use deformcal::app::output::calibration_files;
use deformcal::app::output::{write_calibration, write_models, Written};
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, LensModel, Method, Pose, Request};
use nalgebra::{Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// The largest disagreement allowed between a consumer's projection and ours.
const TOLERANCE_PX: f64 = 1e-6;

/// Calibrates a small synthetic set through `models` and writes it; `fix_k3` holds
/// k3 at its initial 0 (a lens Kalibr's radtan and COLMAP's OPENCV can hold).
fn calibrated(
    preset: Preset,
    models: &[LensModel],
    fix_k3: bool,
) -> (tempfile::TempDir, CalibrationJson, Written) {
    let (mut dataset, _) = Generator::new(preset, Some(10), 3)
        .with_models(models)
        .generate();
    if fix_k3 {
        for cam in &mut dataset.cameras {
            cam.fix = vec!["k3".into()];
        }
    }
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings::default(),
        gauge: None,
    };
    let c = calibrate(&dataset, &request).expect("calibrates");
    let dir = tempfile::tempdir().unwrap();
    let written = write_calibration(dir.path(), &c).unwrap();
    let json =
        serde_json::from_str(&std::fs::read_to_string(&written.calibration).unwrap()).unwrap();
    (dir, json, written)
}

/// Points all over a camera's image, in front of it (the pinhole-based consumers
/// divide by z first), at depths from 0.5 m to 5 m.
fn points_in_view(cam: &CameraJson, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Vec::new();
    while points.len() < 200 {
        let px = Vector2::new(
            rng.gen_range(0.0..cam.width as f64 - 1.0),
            rng.gen_range(0.0..cam.height as f64 - 1.0),
        );
        let Some(ray) = cam.intrinsics.unproject(&px) else {
            continue;
        };
        if ray.z > 0.05 {
            let p = ray / ray.z * rng.gen_range(0.5..5.0);
            points.push([p.x, p.y, p.z]);
        }
    }
    points
}

/// The worst distance between a tool's projections (a JSON list of [u, v]) and ours.
fn worst(tool: &serde_json::Value, ours: &[Vector2<f64>]) -> f64 {
    let uv = tool.as_array().expect("projections");
    assert_eq!(uv.len(), ours.len());
    uv.iter()
        .zip(ours)
        .map(|(t, o)| {
            let t = Vector2::new(t[0].as_f64().unwrap(), t[1].as_f64().unwrap());
            (t - o).norm()
        })
        .fold(0.0, f64::max)
}

/// Reads the exports back with the consumers and checks each camera's projections;
/// returns the tools' answer.
fn check_projections(dir: &Path, json: &CalibrationJson) -> serde_json::Value {
    let points: serde_json::Map<String, serde_json::Value> = json
        .cameras
        .iter()
        .enumerate()
        .map(|(k, cam)| {
            (
                cam.name.clone(),
                serde_json::json!(points_in_view(cam, 11 + k as u64)),
            )
        })
        .collect();
    let request = serde_json::json!({ "points": points }).to_string();
    let tools = run_tool(
        "check_more_exports.py",
        &[dir.display().to_string()],
        &request,
    );
    for cam in &json.cameras {
        let ours: Vec<Vector2<f64>> = points[&cam.name]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                let p = Vector3::new(
                    p[0].as_f64().unwrap(),
                    p[1].as_f64().unwrap(),
                    p[2].as_f64().unwrap(),
                );
                cam.intrinsics.project(&p).unwrap()
            })
            .collect();
        let t = &tools["cameras"][&cam.name];
        let mut seen = Vec::new();
        for (format, path) in [
            ("ROS cv2", "/ros/uv"),
            ("Kalibr", "/kalibr/uv"),
            ("COLMAP reimplementation", "/colmap/reimpl"),
            ("pycolmap", "/colmap/pycolmap"),
        ] {
            if let Some(uv) = t.pointer(path) {
                let w = worst(uv, &ours);
                seen.push(format!("{format} {w:.1e} px"));
                assert!(
                    w <= TOLERANCE_PX,
                    "{} ({}): {format} off by {w} px",
                    cam.name,
                    cam.model
                );
            }
        }
        eprintln!("{} ({}): {}", cam.name, cam.model, seen.join(", "));
    }
    tools
}

/// What each format writes a camera of `model` (with k3 ≠ 0 unless `k3_zero`) as.
fn expected_formats(
    model: LensModel,
    k3_zero: bool,
) -> (
    Option<&'static str>,
    Option<&'static str>,
    Option<&'static str>,
) {
    match model {
        LensModel::Radial3 | LensModel::OpenCv5 if k3_zero => {
            (Some("plumb_bob"), Some("radtan"), Some("OPENCV"))
        }
        LensModel::Radial3 | LensModel::OpenCv5 => (Some("plumb_bob"), None, Some("FULL_OPENCV")),
        LensModel::OpenCv8 => (Some("rational_polynomial"), None, Some("FULL_OPENCV")),
        LensModel::Kb4 => (
            Some("equidistant"),
            Some("equidistant"),
            Some("OPENCV_FISHEYE"),
        ),
        LensModel::DoubleSphere => (None, Some("none"), None),
        // Every distortion coefficient 0.
        LensModel::Pinhole => (Some("plumb_bob"), Some("radtan"), Some("PINHOLE")),
    }
}

/// The warnings of one camera: every export that cannot hold it exactly.
fn expected_warnings(cam: &CameraJson) -> Vec<String> {
    let (name, model) = (&cam.name, cam.model);
    let mut w = Vec::new();
    if model == LensModel::DoubleSphere {
        w.push(format!(
            "opencv.yaml: camera `{name}` is left out: the format has no `ds` lens model"
        ));
    }
    if matches!(model, LensModel::Kb4 | LensModel::DoubleSphere) {
        w.push(format!(
            "{name}.cameramodel: not written: mrcal has no `{model}` lens model"
        ));
    }
    if model == LensModel::DoubleSphere {
        w.push(format!(
            "{name}_camera_info.yaml: not written: ROS has no `ds` lens model"
        ));
    }
    let k3 = cam.intrinsics.get("k3").unwrap_or(0.0);
    if matches!(model, LensModel::Radial3 | LensModel::OpenCv5) && k3 != 0.0 {
        w.push(format!(
            "camchain.yaml: camera `{name}` is left out: Kalibr's pinhole-radtan has no k3 and `{model}` has k3 = {k3:?}"
        ));
    }
    if model == LensModel::OpenCv8 {
        w.push(format!(
            "camchain.yaml: camera `{name}` is left out: the format has no `opencv8` lens model"
        ));
    }
    if model == LensModel::DoubleSphere {
        w.push(format!(
            "cameras.txt: camera `{name}` is left out: the format has no `ds` lens model"
        ));
    }
    w
}

/// Each camera's model in each format as the tools read it, against the table.
fn check_formats(tools: &serde_json::Value, json: &CalibrationJson, k3_zero: bool) {
    for cam in &json.cameras {
        let t = &tools["cameras"][&cam.name];
        let (ros, kalibr, colmap) = expected_formats(cam.model, k3_zero);
        assert_eq!(t["ros"]["distortion_model"].as_str(), ros, "{}", cam.model);
        assert_eq!(
            t["kalibr"]["distortion_model"].as_str(),
            kalibr,
            "{}",
            cam.model
        );
        assert_eq!(t["colmap"]["model"].as_str(), colmap, "{}", cam.model);
        if ros.is_some() {
            assert_eq!(t["ros"]["width"], cam.width);
            assert_eq!(t["ros"]["height"], cam.height);
        }
    }
}

#[test]
fn every_lens_model_alone_projects_alike_through_ros_kalibr_and_colmap() {
    if !python_has(&["cv2", "yaml"]) {
        return;
    }
    for model in LensModel::ALL {
        let (dir, json, written) = calibrated(Preset::T2, &[model], false);
        let tools = check_projections(dir.path(), &json);
        check_formats(&tools, &json, false);
        assert_eq!(
            written.warnings,
            expected_warnings(&json.cameras[0]),
            "{model}"
        );
        // A single camera is monocular in ROS: no rotation, P = [K | 0].
        if let Some(ros) = tools["cameras"]["cam0"]["ros"].as_object() {
            let k = json.cameras[0].intrinsics.camera_matrix();
            let r: Vec<f64> = ros["R"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            let p: Vec<f64> = ros["P"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(r, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
            for i in 0..3 {
                for j in 0..4 {
                    let want = if j < 3 { k[(i, j)] } else { 0.0 };
                    assert_eq!(p[i * 4 + j], want, "P[{i}][{j}]");
                }
            }
        }
        if !tools["pycolmap"].as_bool().unwrap() {
            eprintln!("pycolmap not importable: COLMAP checked by the reimplementation only");
        }
    }
}

#[test]
fn a_lens_with_k3_held_at_zero_is_kalibr_radtan_and_colmap_opencv() {
    if !python_has(&["cv2", "yaml"]) {
        return;
    }
    for model in [LensModel::Radial3, LensModel::OpenCv5] {
        let (dir, json, written) = calibrated(Preset::T2, &[model], true);
        assert_eq!(json.cameras[0].intrinsics.get("k3"), Some(0.0));
        let tools = check_projections(dir.path(), &json);
        check_formats(&tools, &json, true);
        assert_eq!(written.warnings, Vec::<String>::new(), "{model}");
    }
}

/// Compares two row-major matrices to 1e-9 relative (absolute below magnitude 1).
fn assert_close(name: &str, ours: &[f64], cv: &serde_json::Value) -> f64 {
    let cv: Vec<f64> = cv
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(ours.len(), cv.len(), "{name}");
    let mut worst = 0.0f64;
    for (a, b) in ours.iter().zip(&cv) {
        let rel = (a - b).abs() / b.abs().max(1.0);
        worst = worst.max(rel);
        assert!(rel <= 1e-9, "{name}: ours {ours:?}\n cv2 {cv:?}");
    }
    worst
}

/// The stereo pair's ROS R and P against `cv2.stereoRectify` on the same K, D, R, T.
fn check_rectification(tools: &serde_json::Value, json: &CalibrationJson) {
    let cv = &tools["stereo_rectify"];
    let mut worst = 0.0f64;
    for (k, (r, p)) in [("R1", "P1"), ("R2", "P2")].into_iter().enumerate() {
        let ros = &tools["cameras"][&json.cameras[k].name]["ros"];
        let to_vec = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        worst = worst.max(assert_close(r, &to_vec(&ros["R"]), &cv[r]));
        worst = worst.max(assert_close(p, &to_vec(&ros["P"]), &cv[p]));
    }
    eprintln!(
        "{}: stereoRectify R1 R2 P1 P2 agree to {worst:.1e} relative",
        json.cameras[0].model
    );
}

/// Kalibr's T_cn_cnm1 of camera 1 maps camera-0 points as the calibrated π_1 does.
fn check_chain(tools: &serde_json::Value, json: &CalibrationJson) {
    let t = &tools["cameras"][&json.cameras[1].name]["kalibr"]["T_cn_cnm1"];
    let m = |i: usize, j: usize| t[i][j].as_f64().unwrap();
    let pose = Pose {
        rotation: json.cameras[1].rotation,
        translation: json.cameras[1].translation,
    };
    for x in [Vector3::new(0.3, -0.2, 2.0), Vector3::new(-1.0, 0.5, 0.7)] {
        let ours = pose.transform(&x);
        for i in 0..3 {
            let kalibr = m(i, 0) * x.x + m(i, 1) * x.y + m(i, 2) * x.z + m(i, 3);
            assert!((kalibr - ours[i]).abs() < 1e-12, "T_cn_cnm1 row {i}");
        }
    }
    assert_eq!((m(3, 0), m(3, 1), m(3, 2), m(3, 3)), (0.0, 0.0, 0.0, 1.0));
}

#[test]
fn every_lens_model_as_a_stereo_pair_keeps_rectification_and_chain() {
    if !python_has(&["cv2", "yaml"]) {
        return;
    }
    for model in LensModel::ALL {
        let (dir, json, written) = calibrated(Preset::Stereo, &[model, model], false);
        let tools = check_projections(dir.path(), &json);
        check_formats(&tools, &json, false);
        let mut expected: Vec<String> = json.cameras.iter().flat_map(expected_warnings).collect();
        if model.info().pinhole_like {
            check_rectification(&tools, &json);
        } else {
            let rect = format!(
                "ROS camera_info: no stereo rectification for `cam0` ({model}) and `cam1` ({model}): OpenCV's stereoRectify needs two pinhole-like cameras of one image size; each file has R = I, P = [K | 0]"
            );
            expected.push(rect);
        }
        // The order follows the formats, not the cameras: compare as sets of lines.
        let mut got = written.warnings.clone();
        got.sort();
        expected.sort();
        assert_eq!(got, expected, "{model}");
        if tools["cameras"]["cam1"]["kalibr"].is_object() {
            assert_eq!(tools["cameras"]["cam1"]["kalibr"]["key"], "cam1");
            check_chain(&tools, &json);
        }
    }
}

#[test]
fn the_new_files_belong_to_a_calibration() {
    let owns = calibration_files();
    for name in [
        "camchain.yaml",
        "cameras.txt",
        "cam0_camera_info.yaml",
        "left_camera_info.yaml",
    ] {
        assert!(owns(name), "{name}");
    }
    assert!(!owns("notes.txt"));
}

/// A name that, written raw into a comment line, would add a Kalibr camera, a
/// COLMAP camera and an mrcal key of its own with fx = 1000.
const INJECTED: &str = "evil\ncam7:\n  intrinsics: [1000.0, 1000.0, 5.0, 5.0]\n7 PINHOLE 10 10 1000 1000 5 5\n    'intrinsics': [ 1000.0 ],";

/// The lines of `text` that are not comments.
fn data_lines(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .collect()
}

#[test]
fn a_name_with_newlines_from_calibration_json_stays_in_its_comment() {
    let (_dir, mut json, _) = calibrated(Preset::Stereo, &[LensModel::OpenCv5; 2], true);
    json.cameras[0].name = INJECTED.into();
    let out = tempfile::tempdir().unwrap();
    let inputs = OptimizationInputs::Absent(format!("camera `{INJECTED}` has no inputs"));
    let written = write_models(out.path(), &json, &inputs).unwrap();
    let chain = std::fs::read_to_string(out.path().join("camchain.yaml")).unwrap();
    let keys: Vec<&str> = data_lines(&chain)
        .into_iter()
        .filter(|l| !l.starts_with(' '))
        .collect();
    assert_eq!(keys, ["cam0:", "cam1:"], "{chain}");
    let colmap = std::fs::read_to_string(out.path().join("cameras.txt")).unwrap();
    let ids: Vec<&str> = data_lines(&colmap)
        .iter()
        .map(|l| l.split(' ').next().unwrap())
        .collect();
    assert_eq!(ids, ["1", "2"], "{colmap}");
    let model_files: Vec<_> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".cameramodel"))
        .collect();
    assert_eq!(model_files.len(), 2, "{model_files:?}");
    for f in &model_files {
        assert!(!f.contains('\n'), "{f:?}");
        let text = std::fs::read_to_string(out.path().join(f)).unwrap();
        let intrinsics = data_lines(&text)
            .iter()
            .filter(|l| l.contains("'intrinsics'"))
            .count();
        assert_eq!(intrinsics, 1, "{text}");
    }
    for w in &written.warnings {
        assert!(!w.contains('\n'), "{w:?}");
    }
}

#[test]
fn names_that_become_one_key_are_refused_at_export() {
    let (_dir, mut json, _) = calibrated(Preset::Stereo, &[LensModel::OpenCv5; 2], false);
    for (pair, what) in [
        (["a b", "a_b"], "opencv.yaml key prefix `a_b_`"),
        (["0", "cam_0"], "opencv.yaml key prefix `cam_0_`"),
        (["Left", "left"], "the file `left.cameramodel`"),
    ] {
        json.cameras[0].name = pair[0].into();
        json.cameras[1].name = pair[1].into();
        let out = tempfile::tempdir().unwrap();
        let inputs = OptimizationInputs::Absent("test".into());
        let e = write_models(out.path(), &json, &inputs).unwrap_err();
        let message = e.to_string();
        assert!(
            message.contains(&format!("`{}` and `{}`", pair[0], pair[1])) && message.contains(what),
            "{message}"
        );
        assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0);
    }
}
