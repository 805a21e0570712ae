//! Interchange: exports read back by the real OpenCV and mrcal (for every lens model,
//! and a rig), mrcal's own projection against ours, corners.vnl in, and corners found
//! by the real mrgingham on rendered images.
use crate::common;
use common::{exact_settings, python_has, run_tool};
use deformcal::app::calibration_json::CalibrationJson;
use deformcal::app::corners_vnl::write_corners_vnl;
use deformcal::app::output::write_calibration;
use deformcal::model::synthetic::Generator;
use deformcal::model::synthetic::Preset;
use deformcal::{calibrate, LensModel, Method, Request};
use deformcal::{Intrinsics, Pose};
use nalgebra::Vector2;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::process::Command;

fn deformcal(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn read_json(path: &Path) -> CalibrationJson {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn opencv_and_mrcal_read_our_models_and_project_like_us() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(&config, "[data]\nsynthetic = \"stereo\"\nimages = 15\n[calibration]\nmethod = \"full\"\n[output]\ndir = \"out\"\n").unwrap();
    deformcal(&["--config", config.to_str().unwrap()]);
    let out = dir.path().join("out");
    let json = read_json(&out.join("calibration.json"));
    // Points all over the field of view, some far out in the corners.
    let points: Vec<[f64; 3]> = (0..60)
        .map(|i| {
            let a = i as f64 * 0.618_033_988_75 * std::f64::consts::TAU;
            let r = 0.36 * ((i % 10) as f64 + 0.5) / 10.0;
            [r * a.cos(), 0.65 * r * a.sin(), 1.0 + (i % 7) as f64]
        })
        .collect();
    let payload = serde_json::json!({ "points": points }).to_string();
    let args = [
        out.to_str().unwrap().to_string(),
        "cam0".into(),
        "cam1".into(),
    ];
    let tools = run_tool("check_exports.py", &args, &payload);
    for (k, cam) in json.cameras.iter().enumerate() {
        let t = &tools[&cam.name];
        let ours: Vec<[f64; 2]> = points
            .iter()
            .map(|p| {
                let uv = cam.intrinsics.project(&Vector3::from(*p)).unwrap();
                [uv.x, uv.y]
            })
            .collect();
        for tool in ["opencv", "mrcal"] {
            for (i, o) in ours.iter().enumerate() {
                let (u, v) = (
                    t[tool][i][0].as_f64().unwrap(),
                    t[tool][i][1].as_f64().unwrap(),
                );
                assert!(
                    (u - o[0]).abs() < 1e-6 && (v - o[1]).abs() < 1e-6,
                    "{} {tool} point {i}: ({u}, {v}) vs {o:?}",
                    cam.name
                );
            }
        }
        assert_eq!(t["width"].as_f64().unwrap(), cam.width as f64);
        assert_eq!(t["imagersize"][1].as_u64().unwrap(), cam.height as u64);
        assert!((t["rms"].as_f64().unwrap() - cam.rmse_px.unwrap()).abs() < 1e-12);
        let rt: Vec<f64> = t["rt_cam_ref"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let pose = Pose {
            rotation: cam.rotation,
            translation: cam.translation,
        };
        for (a, b) in rt.iter().zip(pose.to_array()) {
            assert!((a - b).abs() < 1e-12, "{}: rt_cam_ref {rt:?}", cam.name);
        }
        // OpenCV's R, T: x_k = R x_0 + T.
        let r = pose.rotation_matrix();
        for i in 0..3 {
            for j in 0..3 {
                assert!((t["R"][i][j].as_f64().unwrap() - r[(i, j)]).abs() < 1e-12);
            }
            assert!((t["T"][i].as_f64().unwrap() - cam.translation[i]).abs() < 1e-12);
        }
        assert!(k < 2);
    }
}

#[test]
fn corners_vnl_with_missing_corners_and_empty_images_calibrates() {
    let (mut d, truth) = Generator::new(Preset::T2, Some(20), 6)
        .with_cameras(2)
        .generate();
    // Drop every 7th corner as if the detector missed it.
    d.observations.retain(|o| (o.corner + o.frame) % 7 != 0);
    let mut vnl = write_corners_vnl(&d);
    vnl.push_str("cam0-999998.png - - -\ncam1-999999.png - - -\n");
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("corners.vnl"), vnl).unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n\
         [[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n\
         [[cameras]]\nname = \"cam1\"\nwidth = 1936\nheight = 1216\n\
         [data]\ncorners_vnl = \"corners.vnl\"\ncamera_patterns = { cam0 = \"cam0-*.png\", cam1 = \"cam1-*.png\" }\n\
         [calibration]\nmethod = \"dynamic\"\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    deformcal(&["--config", config.to_str().unwrap()]);
    let json = read_json(&dir.path().join("out/calibration.json"));
    assert_eq!(json.frames.len(), 20);
    assert_eq!(
        json.observations + json.rejected_observations,
        d.observations.len()
    );
    assert!(
        json.rejected_observations < 5,
        "{}",
        json.rejected_observations
    );
    for (k, cam) in json.cameras.iter().enumerate() {
        assert!(
            (cam.intrinsics.fx() / truth.intrinsics[k].fx() - 1.0).abs() < 2e-3,
            "{}",
            cam.intrinsics.fx()
        );
    }
    // import writes the same observations as a CSV.
    let csv = dir.path().join("obs.csv");
    deformcal(&[
        "import",
        "--config",
        config.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ]);
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 1 + d.observations.len());
}

/// Renders a chessboard of `n × n` inner corners seen through a pinhole camera, with
/// 3×3 supersampling and a Gaussian blur, as an 8-bit PGM.
fn render(path: &Path, k: &Intrinsics, pose: &Pose, n: usize, spacing: f64, size: (usize, usize)) {
    let (w, h) = size;
    let r = pose.rotation_matrix();
    let t = pose.translation_vector();
    // Board plane in camera coordinates: points X with nᵀ(X − t) = 0, n = R e_z.
    let normal = r * Vector3::z();
    let half = (n as f64 + 1.0) / 2.0 * spacing; // edge of the outer squares
    let mut img = vec![0.0f64; w * h];
    for v in 0..h {
        for u in 0..w {
            let mut sum = 0.0;
            for sv in [-1.0 / 3.0, 0.0, 1.0 / 3.0] {
                for su in [-1.0 / 3.0, 0.0, 1.0 / 3.0] {
                    let ray = Vector3::new(
                        (u as f64 + su - k.cx()) / k.fx(),
                        (v as f64 + sv - k.cy()) / k.fy(),
                        1.0,
                    );
                    let s = normal.dot(&t) / normal.dot(&ray);
                    let b = r.inverse() * (ray * s - t);
                    let white = if b.x.abs() > half || b.y.abs() > half {
                        true // the white margin around the squares
                    } else {
                        let (i, j) = (
                            ((b.x + half) / spacing).floor() as i64,
                            ((b.y + half) / spacing).floor() as i64,
                        );
                        (i + j) % 2 == 1
                    };
                    sum += if white { 230.0 } else { 25.0 };
                }
            }
            img[v * w + u] = sum / 9.0;
        }
    }
    // Separable Gaussian blur, σ = 0.8 px.
    let kernel: Vec<f64> = (-3..=3)
        .map(|i: i32| (-(i * i) as f64 / (2.0 * 0.64)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let blur = |src: &[f64], horizontal: bool| -> Vec<f64> {
        let mut out = vec![0.0; w * h];
        for v in 0..h {
            for u in 0..w {
                let mut acc = 0.0;
                for (o, kv) in kernel.iter().enumerate() {
                    let d = o as i64 - 3;
                    let (uu, vv) = if horizontal {
                        ((u as i64 + d).clamp(0, w as i64 - 1), v as i64)
                    } else {
                        (u as i64, (v as i64 + d).clamp(0, h as i64 - 1))
                    };
                    acc += kv * src[vv as usize * w + uu as usize];
                }
                out[v * w + u] = acc / norm;
            }
        }
        out
    };
    let img = blur(&blur(&img, true), false);
    let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
    bytes.extend(img.iter().map(|&p| p.round().clamp(0.0, 255.0) as u8));
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn real_mrgingham_corners_calibrate() {
    let dir = tempfile::tempdir().unwrap();
    let k = Intrinsics::pinhole(900.0, 900.0, 511.5, 383.5);
    let (n, spacing) = (10usize, 0.03);
    let deg = std::f64::consts::PI / 180.0;
    for i in 0..12 {
        let f = i as f64;
        let tilt_x = ((f * 37.0) % 50.0 - 25.0) * deg;
        let tilt_y = ((f * 23.0) % 50.0 - 25.0) * deg;
        let roll = ((f * 11.0) % 20.0 - 10.0) * deg;
        let r = nalgebra::Rotation3::from_euler_angles(tilt_x, tilt_y, roll);
        let t = Vector3::new(
            ((f * 0.31) % 0.2) - 0.1,
            ((f * 0.17) % 0.14) - 0.07,
            0.6 + (f * 0.07) % 0.3,
        );
        render(
            &dir.path().join(format!("view{i:02}.pgm")),
            &k,
            &Pose::from_parts(&r, &t),
            n,
            spacing,
            (1024, 768),
        );
    }
    let glob = dir.path().join("view*.pgm");
    let out = Command::new("mrgingham")
        .args(["--gridn", "10", "--jobs", "2"])
        .arg(glob.to_str().unwrap())
        .output()
        .expect("run mrgingham (apt-get install mrgingham)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let vnl = String::from_utf8(out.stdout).unwrap();
    let found = vnl
        .lines()
        .filter(|l| !l.starts_with('#') && !l.contains(" - "))
        .count();
    assert!(
        found >= 8 * 100,
        "mrgingham found only {found} corners:\n{vnl}"
    );
    std::fs::write(dir.path().join("corners.vnl"), &vnl).unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        "[target]\nrows = 10\ncols = 10\nspacing = 0.03\n[[cameras]]\nname = \"cam0\"\nwidth = 1024\nheight = 768\n\
         [data]\ncorners_vnl = \"corners.vnl\"\n[calibration]\nmethod = \"standard\"\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    deformcal(&["--config", config.to_str().unwrap()]);
    let json = read_json(&dir.path().join("out/calibration.json"));
    let got = json.cameras[0].intrinsics;
    // mrgingham on 8-bit renders is good to a few tenths of a pixel.
    assert!(json.rmse_px < 0.5, "rmse {}", json.rmse_px);
    assert!(
        (got.fx() / k.fx() - 1.0).abs() < 0.005 && (got.fy() / k.fy() - 1.0).abs() < 0.005,
        "{got:?}"
    );
    assert!(
        (got.cx() - k.cx()).abs() < 2.0 && (got.cy() - k.cy()).abs() < 2.0,
        "{got:?}"
    );
}

/// Camera-frame points for checking a lens model's projection: for pinhole-like models
/// rays through random pixels of the image (by our unprojection: only our projection is
/// under test), for fisheye models random directions up to 85° off axis (OpenCV's
/// fisheye takes atan(r/z), so nothing at or behind 90°), plus the optical axis; each
/// at a random depth.
fn probe_points(k: &deformcal::Intrinsics, width: u32, height: u32, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = vec![[0.0, 0.0, 2.0]];
    while points.len() < 200 {
        let ray = if k.model().info().pinhole_like {
            let px = Vector2::new(
                rng.gen_range(0.0..width as f64 - 1.0),
                rng.gen_range(0.0..height as f64 - 1.0),
            );
            match k.unproject(&px) {
                Some(r) => r,
                None => continue,
            }
        } else {
            let theta = rng.gen_range(0.0..85.0f64).to_radians();
            let phi = rng.gen_range(0.0..std::f64::consts::TAU);
            Vector3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            )
        };
        let p = ray * rng.gen_range(0.3..8.0);
        points.push([p.x, p.y, p.z]);
    }
    points
}

/// For every lens model: calibrate a small synthetic set, write the exports, load them
/// with the real consumers (cv2 by the yaml's distortion_model, mrcal by its
/// `.cameramodel`) and project with them: the same pixels as ours to 1e-6 px. A model a
/// format cannot represent must be left out with a warning that names it.
#[test]
fn exports_of_every_lens_model_project_like_us() {
    if !python_has(&["cv2", "mrcal"]) {
        return;
    }
    for (m, model) in LensModel::ALL.into_iter().enumerate() {
        let mut g = Generator::new(Preset::T2, Some(10), 40 + m as u64).with_models(&[model]);
        g.bend_scale = 0.0;
        let (d, _) = g.generate();
        let c = calibrate(
            &d,
            &Request {
                method: Method::Standard,
                settings: exact_settings(),
                gauge: None,
            },
        )
        .unwrap_or_else(|e| panic!("{model}: {e}"));
        let dir = tempfile::tempdir().unwrap();
        let written = write_calibration(dir.path(), &c).unwrap();
        let cam = &d.cameras[0];
        let k = c.state.intrinsics[0];
        assert_eq!(k.model(), model);
        eprintln!("{model}: warnings {:?}", written.warnings);

        // What each format can hold: (OpenCV distortion_model, coefficients), mrcal model.
        let (opencv, mrcal) = match model {
            LensModel::Radial3 => (Some(("plumb_bob", 5)), Some("LENSMODEL_OPENCV5")),
            LensModel::OpenCv5 => (Some(("plumb_bob", 5)), Some("LENSMODEL_OPENCV5")),
            LensModel::OpenCv8 => (Some(("rational_polynomial", 8)), Some("LENSMODEL_OPENCV8")),
            LensModel::Kb4 => (Some(("fisheye", 4)), None),
            LensModel::DoubleSphere => (None, None),
            LensModel::Pinhole => (Some(("plumb_bob", 5)), Some("LENSMODEL_PINHOLE")),
        };
        let yaml = dir.path().join("opencv.yaml");
        let cameramodel = dir.path().join(format!("{}.cameramodel", cam.name));
        assert_eq!(yaml.exists(), opencv.is_some(), "{model}: opencv.yaml");
        assert_eq!(
            cameramodel.exists(),
            mrcal.is_some(),
            "{model}: .cameramodel"
        );
        assert_left_out_files_are_named(model, &cam.name, &written.warnings, opencv, mrcal);
        if opencv.is_none() && mrcal.is_none() {
            continue;
        }

        let points = probe_points(&k, cam.width, cam.height, 7 + m as u64);
        let payload = serde_json::json!({ "points": points }).to_string();
        let tools = run_tool(
            "check_exports.py",
            &[dir.path().to_str().unwrap().to_string(), cam.name.clone()],
            &payload,
        );
        let t = &tools[&cam.name];
        if let Some((name, n)) = opencv {
            assert_eq!(t["distortion_model"].as_str(), Some(name), "{model}");
            assert_eq!(t["coefficients"].as_u64(), Some(n), "{model}");
        }
        if let Some(name) = mrcal {
            assert_eq!(t["lensmodel"].as_str(), Some(name), "{model}");
        }
        assert_tools_project_like_us(model, &k, &points, t, opencv.is_some(), mrcal.is_some());
    }
}

/// One warning per export file left out, naming the file and the model.
fn assert_left_out_files_are_named(
    model: LensModel,
    camera: &str,
    warnings: &[String],
    opencv: Option<(&str, u64)>,
    mrcal: Option<&str>,
) {
    let mut expected = Vec::new();
    if opencv.is_none() {
        expected.push("opencv.yaml".to_string());
    }
    if mrcal.is_none() {
        expected.push(format!("{camera}.cameramodel"));
    }
    // The ROS, Kalibr and COLMAP warnings are checked in tests/exports.rs.
    let ours: Vec<&String> = warnings
        .iter()
        .filter(|w| w.starts_with("opencv.yaml") || w.contains(".cameramodel"))
        .collect();
    assert_eq!(ours.len(), expected.len(), "{model}: {ours:?}");
    for file in &expected {
        assert!(
            warnings
                .iter()
                .any(|w| w.contains(file.as_str()) && w.contains(&format!("`{model}`"))),
            "{model}: no warning naming {file} and the model: {:?}",
            warnings
        );
    }
}

/// OpenCV and mrcal, reading our exports, project `points` as we do (1e-6 px).
fn assert_tools_project_like_us(
    model: LensModel,
    k: &Intrinsics,
    points: &[[f64; 3]],
    t: &serde_json::Value,
    opencv: bool,
    mrcal: bool,
) {
    for (tool, present) in [("opencv", opencv), ("mrcal", mrcal)] {
        if !present {
            assert!(
                t[tool].is_null(),
                "{model}: {tool} read a file that is not there"
            );
            continue;
        }
        let mut worst = 0.0f64;
        for (i, p) in points.iter().enumerate() {
            let ours = k.project(&Vector3::from(*p)).unwrap();
            let (u, v) = (
                t[tool][i][0].as_f64().unwrap(),
                t[tool][i][1].as_f64().unwrap(),
            );
            let diff = (u - ours.x).abs().max((v - ours.y).abs());
            worst = worst.max(diff);
            assert!(
                diff <= 1e-6,
                "{model} {tool} point {i} {p:?}: ({u}, {v}) vs ({}, {})",
                ours.x,
                ours.y
            );
        }
        eprintln!(
            "{model} via {tool}: {} points, max projection difference {worst:.2e} px",
            points.len()
        );
    }
}

/// mrcal's LENSMODEL_OPENCV8 (and OPENCV5) projection equals ours to 1e-9 px for the
/// same parameters: random parameters (denominator of the rational term kept well away
/// from zero) and random points over a wide field.
#[test]
fn mrcal_projection_equals_ours_for_the_same_parameters() {
    if !python_has(&["mrcal"]) {
        return;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut cases = Vec::new();
    let mut ours = Vec::new();
    for case in 0..40 {
        let model = if case % 4 == 3 {
            LensModel::OpenCv5
        } else {
            LensModel::OpenCv8
        };
        let mut params = vec![
            rng.gen_range(300.0..3000.0),
            rng.gen_range(300.0..3000.0),
            rng.gen_range(200.0..1000.0),
            rng.gen_range(150.0..700.0),
        ];
        for name in &model.param_names()[4..] {
            params.push(match *name {
                "p1" | "p2" => rng.gen_range(-0.01..0.01),
                // |k4 r² + k5 r⁴ + k6 r⁶| < 0.5 for r² ≤ 0.72 below.
                "k4" | "k5" | "k6" => rng.gen_range(-0.3..0.3),
                _ => rng.gen_range(-0.5..0.5),
            });
        }
        let k = deformcal::Intrinsics::from_params(model, &params).unwrap();
        let points: Vec<[f64; 3]> = (0..100)
            .map(|_| {
                let z = rng.gen_range(0.2..10.0);
                [
                    rng.gen_range(-0.6..0.6) * z,
                    rng.gen_range(-0.6..0.6) * z,
                    z,
                ]
            })
            .collect();
        ours.push(
            points
                .iter()
                .map(|p| k.project(&Vector3::from(*p)).unwrap())
                .collect::<Vec<_>>(),
        );
        cases.push(serde_json::json!({
            "lensmodel": model.info().mrcal.unwrap(),
            "intrinsics": params,
            "points": points,
        }));
    }
    let payload = serde_json::json!({ "cases": cases }).to_string();
    let out = run_tool("mrcal_project.py", &[], &payload);
    let mut worst = 0.0f64;
    for (c, case) in ours.iter().enumerate() {
        for (i, q) in case.iter().enumerate() {
            let mr = &out["projections"][c][i];
            let (u, v) = (mr[0].as_f64().unwrap(), mr[1].as_f64().unwrap());
            let diff = (u - q.x).abs().max((v - q.y).abs());
            worst = worst.max(diff);
            assert!(
                diff <= 1e-9,
                "case {c} ({}) point {i}: mrcal ({u}, {v}) vs ours ({}, {})",
                cases[c]["lensmodel"],
                q.x,
                q.y
            );
        }
    }
    eprintln!("mrcal vs deformcal projection: max difference {worst:.2e} px");
}
