//! The structure-from-motion loop-closure experiment (the paper's section 5)
//! against known truth: the true camera closes the loop to the noise's drift,
//! the error grows with a controlled focal-length and distortion error, the
//! COLMAP export reads back to the same geometry, bad `[sfm]` keys are clear
//! errors, and the protocol and the `sfm` subcommand carry the figure.
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::prepare;
use deformcal::app::protocol_report::{protocol_csv, report_tables, summarise};
use deformcal::app::sfm::{colmap_scene, match_pairs, Experiment, SfmConfig};
use deformcal::app::sfm_report::sfm_plot;
use deformcal::model::lens::Intrinsics;
use deformcal::model::synthetic::true_intrinsics;
use deformcal::Method;
use nalgebra::{Quaternion, UnitQuaternion, Vector2, Vector3};
use std::path::Path;
use std::process::Command;

fn experiment(frames: usize, noise_px: f64) -> Experiment {
    let config = SfmConfig {
        frames,
        noise_px,
        ..SfmConfig::default()
    };
    Experiment::new(&config, &true_intrinsics(), 1936, 1216).unwrap()
}

fn loop_px(e: &Experiment, camera: &Intrinsics) -> f64 {
    e.run(camera).unwrap().loop_closure_px
}

/// Without noise the true camera closes the loop exactly; with σ = 0.5 px the
/// drift of a 60-frame chain of window adjustments leaves a few σ (a random
/// walk: no image is ever matched to the first), far below a 1 % focal error.
#[test]
fn true_camera_closes_the_loop_at_the_noise_level() {
    let cam = true_intrinsics();
    let exact = loop_px(&experiment(60, 0.0), &cam);
    assert!(exact < 0.02, "noise-free loop closure {exact} px");
    let noisy = experiment(60, 0.5);
    let e = loop_px(&noisy, &cam);
    assert!(e > 0.05 && e < 2.5, "loop closure {e} px at σ = 0.5 px");
    let off = cam
        .with_param("fx", cam.fx() * 1.01)
        .with_param("fy", cam.fy() * 1.01);
    assert!(loop_px(&noisy, &off) > 4.0 * e);
}

fn strictly_increasing(v: &[f64]) -> bool {
    v.windows(2).all(|w| w[1] > w[0])
}

#[test]
fn loop_error_grows_monotonically_with_focal_and_distortion_error() {
    let e = experiment(60, 0.5);
    let cam = true_intrinsics();
    let focal: Vec<f64> = [0.0, 0.005, 0.01, 0.02]
        .iter()
        .map(|d| {
            let c = cam
                .with_param("fx", cam.fx() * (1.0 + d))
                .with_param("fy", cam.fy() * (1.0 + d));
            loop_px(&e, &c)
        })
        .collect();
    assert!(strictly_increasing(&focal), "focal sweep {focal:?}");
    let k1 = cam.get("k1").unwrap();
    let radial: Vec<f64> = [0.0, 0.02, 0.05, 0.1]
        .iter()
        .map(|d| loop_px(&e, &cam.with_param("k1", k1 + d)))
        .collect();
    assert!(strictly_increasing(&radial), "k1 sweep {radial:?}");
}

/// Reads `images.txt` back: per image id, the pose and its (x, y, point id) list.
type Image = (UnitQuaternion<f64>, Vector3<f64>, Vec<(f64, f64, usize)>);
fn read_images(text: &str) -> Vec<Image> {
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    lines
        .chunks(2)
        .enumerate()
        .map(|(j, pair)| {
            let head: Vec<&str> = pair[0].split_whitespace().collect();
            assert_eq!(head[0].parse::<usize>().unwrap(), j + 1);
            assert_eq!(head[8], "1");
            let v: Vec<f64> = head[1..8].iter().map(|s| s.parse().unwrap()).collect();
            let q = UnitQuaternion::from_quaternion(Quaternion::new(v[0], v[1], v[2], v[3]));
            let pts: Vec<&str> = pair[1].split_whitespace().collect();
            let obs = pts
                .chunks(3)
                .map(|c| {
                    (
                        c[0].parse().unwrap(),
                        c[1].parse().unwrap(),
                        c[2].parse().unwrap(),
                    )
                })
                .collect();
            (q, Vector3::new(v[4], v[5], v[6]), obs)
        })
        .collect()
}

#[test]
fn colmap_export_reads_back_to_the_scene() {
    let e = experiment(20, 0.0);
    let (images, points) = colmap_scene(&e.scene);
    let imgs = read_images(&images);
    assert_eq!(imgs.len(), 21);
    let cam = true_intrinsics();
    let mut checked = 0;
    for line in points.lines().filter(|l| !l.starts_with('#')) {
        let f: Vec<&str> = line.split_whitespace().collect();
        let id: usize = f[0].parse().unwrap();
        let x = Vector3::new(
            f[1].parse().unwrap(),
            f[2].parse().unwrap(),
            f[3].parse().unwrap(),
        );
        let track: Vec<usize> = f[8..].iter().map(|s| s.parse().unwrap()).collect();
        for p in track.chunks(2) {
            let (q, t, obs) = &imgs[p[0] - 1];
            let (u, v, pid) = obs[p[1]];
            assert_eq!(pid, id, "track and image disagree");
            // COLMAP's world-to-camera pose and its pixel origin (0.5 at the top-left centre).
            let uv = cam.project(&(q * x + t)).unwrap();
            assert!((uv - Vector2::new(u - 0.5, v - 0.5)).norm() < 1e-6);
            checked += 1;
        }
    }
    let features: usize = e.scene.features.iter().map(Vec::len).sum();
    assert_eq!(checked, features);
    let pairs = match_pairs(&e.scene);
    assert_eq!(pairs.lines().count(), 20);
    assert_eq!(
        pairs.lines().last(),
        Some("frame_0019.png frame_0000_again.png")
    );
}

fn config_error(sfm: &str) -> String {
    let text = format!("[data]\nsynthetic = \"t2\"\n\n[sfm]\n{sfm}\n");
    Config::parse(&text, Path::new("bad.toml"))
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_sfm_config_is_a_clear_error() {
    let e = config_error("frams = 100");
    assert!(
        e.contains("bad.toml") && e.contains("line 5") && e.contains("did you mean `frames`"),
        "{e}"
    );
    let e = config_error("frames = 100\nnoise_px = -1.0");
    assert!(e.contains("line 6") && e.contains("sfm.noise_px"), "{e}");
    let e = config_error("window = 200");
    assert!(e.contains("sfm.window"), "{e}");
    let e = config_error("detect_prob = 0.0");
    assert!(e.contains("sfm.detect_prob"), "{e}");
}

#[test]
fn protocol_rows_report_the_loop_closure() {
    let text = "[data]\nsynthetic = \"t2\"\n[sfm]\nframes = 40\n";
    let config = Config::parse(text, Path::new("p.toml")).unwrap();
    let protocol = ProtocolConfig {
        subsets: 2,
        images_per_subset: 20,
        seed: 3,
        methods: vec![Method::Standard, Method::Full],
        auto: false,
    };
    let setup = prepare(&config, &protocol).unwrap();
    let rows = setup.run(None, &|| {});
    for r in &rows {
        assert!(r.ok(), "{:?}", r.error);
        let lc = r
            .loop_closure_px
            .unwrap_or_else(|| panic!("{:?}", r.sfm_error));
        assert!(lc.is_finite() && lc > 0.0);
    }
    let csv = String::from_utf8(protocol_csv(&setup.header, &rows).unwrap()).unwrap();
    assert!(csv.lines().next().unwrap().contains("loop_closure_px"));
    let summary = summarise(&setup.header, &rows);
    let s = &summary.methods["full"].metrics["loop_closure_px"];
    assert_eq!(s.n, 2);
    let tables = report_tables(&summary, &rows);
    assert!(tables.iter().any(|t| t.title.contains("Table 1")));
    let svg = sfm_plot(&setup.header, &rows).unwrap().unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("loop-closure RMSE"));
}

#[test]
fn sfm_subcommand_tests_a_calibration_and_refuses_a_missing_one() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(
        &cfg,
        "[data]\nsynthetic = \"t2\"\nimages = 20\n[calibration]\nmethod = \"standard\"\n[sfm]\nframes = 30\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let c = cfg.to_str().unwrap();
    let missing = Command::new(bin)
        .args(["sfm", "--config", c, "--calibration", "nope.json"])
        .output()
        .unwrap();
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(err.contains("nope.json"), "{err}");
    assert!(Command::new(bin)
        .args(["--config", c])
        .output()
        .unwrap()
        .status
        .success());
    let calib = dir.path().join("out/calibration.json");
    let out = Command::new(bin)
        .args([
            "sfm",
            "--config",
            c,
            "--calibration",
            calib.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("loop-closure error"));
    for f in [
        "sfm.json",
        "cameras.txt",
        "images.txt",
        "points3D.txt",
        "match_pairs.txt",
    ] {
        assert!(dir.path().join("out/sfm").join(f).is_file(), "{f}");
    }
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/sfm/sfm.json")).unwrap(),
    )
    .unwrap();
    assert!(json["loop_closure_px"].as_f64().unwrap() > 0.0);
}

#[test]
fn sfm_refuses_a_failed_or_invalid_calibration_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(
        &cfg,
        "[data]\nsynthetic = \"t2\"\nimages = 12\n[calibration]\nmethod = \"standard\"\n[sfm]\nframes = 30\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let c = cfg.to_str().unwrap();
    let run = Command::new(bin).args(["--config", c]).output().unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let good: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    let mut failed = good.clone();
    failed["failure"] = serde_json::json!({"reasons": ["the RMSE is 9 px"], "hints": []});
    let mut negative = good;
    negative["cameras"][0]["intrinsics"]["fx"] = (-1.0).into();
    for (name, json, message) in [
        (
            "FAILED-calibration.json",
            failed,
            "FAILED its guard rails (the RMSE is 9 px)",
        ),
        (
            "negative.json",
            negative,
            "intrinsics.fx must be positive (got -1)",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, json.to_string()).unwrap();
        let out = Command::new(bin)
            .args([
                "sfm",
                "--config",
                c,
                "--calibration",
                path.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name} accepted");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.contains(&format!("{name}: ")) && err.contains(message),
            "{err}"
        );
        assert!(
            !dir.path().join("out/sfm").exists(),
            "{name}: output written"
        );
    }
}
