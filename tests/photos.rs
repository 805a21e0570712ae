//! Photos in, end to end through the real binary and the real solver: rendered
//! photos of a 9×6 board through a known camera → `deformcal --config` → intrinsics
//! close to the truth; detections.csv, the cache on a rerun, non-image files
//! skipped, several cameras with PNG 16 bit, TIFF and JPEG, and `deformcal detect`.
use crate::detect_common;

use deformcal::app::detect::render::render_board;
use deformcal::app::detect::Detector;
use deformcal::app::photos::{cache, detect_photos, PhotoRun};
use detect_common::*;
use image::{DynamicImage, ImageBuffer, Luma};
use std::path::Path;
use std::process::{Command, Output};

fn deformcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .expect("run deformcal")
}

/// Varied, well-tilted views (so the focal length is observable), some boards bent
/// and some partly out of view; (rotation, distance, shift, bend).
fn views() -> Vec<([f64; 3], f64, [f64; 2], f64)> {
    vec![
        ([0.45, -0.1, 0.05], 0.55, [0.0, 0.0], 0.0),
        ([-0.4, 0.2, 0.1], 0.55, [0.02, 0.01], 0.003),
        ([0.1, 0.5, -0.1], 0.6, [-0.03, 0.0], 0.0),
        ([0.2, -0.45, 0.2], 0.5, [0.03, -0.02], 0.0),
        ([-0.3, -0.35, 1.6], 0.6, [0.0, 0.03], 0.002),
        ([0.35, 0.35, -0.2], 0.45, [-0.05, -0.04], 0.0),
        ([-0.5, 0.0, 0.0], 0.6, [0.05, 0.05], 0.0),
        ([0.0, 0.45, 3.0], 0.5, [0.06, -0.05], 0.0),
        ([0.25, 0.25, 0.3], 0.42, [-0.17, 0.0], 0.0),
        ([0.3, -0.3, -0.1], 0.5, [-0.06, 0.05], 0.003),
    ]
}

/// Renders the views as 8-bit PNGs `dir/<prefix>-NN.png`.
fn write_photos(dir: &Path, prefix: &str) {
    std::fs::create_dir_all(dir).unwrap();
    for (k, (rvec, dist, shift, bend)) in views().into_iter().enumerate() {
        let mut sc = scene(6, 9, rvec, dist, shift);
        sc.bend = bend;
        sc.seed = k as u64;
        sc.supersample = 4;
        let (img, _) = render_board(&sc);
        img.save(dir.join(format!("{prefix}-{k:02}.png"))).unwrap();
    }
}

const BOARD: &str = "[target]\nrows = 6\ncols = 9\nspacing = 0.03\n";

#[test]
fn photos_to_intrinsics_with_cache_and_report() {
    let dir = tempfile::tempdir().unwrap();
    write_photos(&dir.path().join("photos"), "img");
    std::fs::write(dir.path().join("photos/img-99.png"), b"not a picture").unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!(
            "{BOARD}[[cameras]]\nname = \"cam0\"\nwidth = {W}\nheight = {H}\nmodel = \"radial3\"\n\
             [data]\nphotos = \"photos/img-*.png\"\n[calibration]\nmethod = \"dynamic\"\n[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
    let out = deformcal(&["--config", config.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("skipped photos/img-99.png: unreadable"),
        "{stderr}"
    );
    assert!(
        stderr.contains("board found in 10 of 11 images"),
        "{stderr}"
    );

    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("out/calibration.json")).unwrap())
            .unwrap();
    let k = &json["cameras"][0]["intrinsics"];
    let cam = camera();
    let f = |n: &str| k[n].as_f64().unwrap();
    eprintln!(
        "fx {} fy {} cx {} cy {} k1 {} k2 {} rmse {}",
        f("fx"),
        f("fy"),
        f("cx"),
        f("cy"),
        f("k1"),
        f("k2"),
        json["rmse_px"]
    );
    assert!((f("fx") / cam.fx - 1.0).abs() < 0.003, "fx {}", f("fx"));
    assert!((f("fy") / cam.fy - 1.0).abs() < 0.003, "fy {}", f("fy"));
    assert!((f("cx") - cam.cx).abs() < 1.0, "cx {}", f("cx"));
    assert!((f("cy") - cam.cy).abs() < 1.0, "cy {}", f("cy"));
    assert!((f("k1") - cam.k1).abs() < 0.01, "k1 {}", f("k1"));
    assert!(json["rmse_px"].as_f64().unwrap() < 0.1);

    let csv = std::fs::read_to_string(dir.path().join("out/detections.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "file,camera,frame,corners,status,reason");
    assert_eq!(lines.len(), 12, "{csv}");
    assert!(lines[1].starts_with("photos/img-00.png,cam0,0,54,complete,"));
    assert!(
        lines.iter().any(|l| l.contains(",partial,")),
        "the board cut by the image edge: {csv}"
    );
    assert!(lines[11].starts_with("photos/img-99.png,cam0,10,0,unreadable,"));
    let obs = std::fs::read_to_string(dir.path().join("out/observations.csv")).unwrap();
    assert!(obs.starts_with("camera,frame,corner,u,v\n"));

    // Unchanged photos: nothing is detected again, and the result is the same.
    let again = deformcal(&["--config", config.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{stderr}");
    assert!(stderr.contains("11 reused from the cache"), "{stderr}");
    let json2: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("out/calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["cameras"], json2["cameras"]);
    // A changed photo is detected again; the others still come from the cache.
    let p = dir.path().join("photos/img-03.png");
    let img = image::open(&p).unwrap().to_luma8();
    let flipped = ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
        *img.get_pixel(img.width() - 1 - x, y)
    });
    flipped.save(&p).unwrap();
    let third = deformcal(&["--config", config.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&third.stderr);
    assert!(stderr.contains("10 reused from the cache"), "{stderr}");
}

/// What `detect_photos` made of the photos of the config in `dir`.
fn photo_run(dir: &Path) -> PhotoRun {
    let config = dir.join("c.toml");
    let c = deformcal::Config::load(&config).unwrap();
    detect_photos(
        &c.data,
        c.target,
        c.charuco.as_ref(),
        &c.cameras,
        &c.output_dir,
        false,
    )
    .unwrap()
}

/// A rerun from the cache hands the calibration exactly the observations of a
/// fresh detection, weights included, and those are the detector's own corners
/// (nothing on the way changes an id, a pixel or a weight); a cache file of the
/// older format (a corner as four floats) or a broken one is detected afresh.
#[test]
fn the_cache_keeps_each_corner_as_the_detector_gave_it() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    for (k, (rvec, dist, shift, _)) in views().into_iter().take(4).enumerate() {
        let mut sc = scene(6, 9, rvec, dist, shift);
        // Noise so that corners' σ, and so their weights, differ.
        sc.noise = 12.0;
        sc.seed = 7 + k as u64;
        let (img, _) = render_board(&sc);
        img.save(photos.join(format!("img-{k:02}.png"))).unwrap();
    }
    std::fs::write(
        dir.path().join("c.toml"),
        format!(
            "{BOARD}[[cameras]]\nname = \"cam0\"\nwidth = {W}\nheight = {H}\nmodel = \"radial3\"\n\
             [data]\nphotos = \"photos/img-*.png\"\n[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
    let fresh = photo_run(dir.path());
    assert!(fresh.images.iter().all(|r| !r.cached));
    assert_eq!(fresh.images.len(), 4);
    // Each image's observations are its detection's corners, field by field.
    for r in &fresh.images {
        let det = Detector::default()
            .detect_file(&dir.path().join(&r.file.name), 6, 9)
            .unwrap();
        let frame = fresh
            .dataset
            .frame_ids
            .iter()
            .position(|&f| f == r.file.frame);
        let seen: Vec<(usize, [f64; 2], f64)> = fresh
            .dataset
            .observations
            .iter()
            .filter(|o| Some(o.frame) == frame)
            .map(|o| (o.corner, o.uv, o.weight))
            .collect();
        let detected: Vec<(usize, [f64; 2], f64)> = det
            .corners
            .iter()
            .map(|c| (c.index, c.uv, c.weight))
            .collect();
        assert_eq!(seen, detected, "{}", r.file.name);
    }
    let weights: Vec<f64> = fresh
        .dataset
        .observations
        .iter()
        .map(|o| o.weight)
        .collect();
    let (lo, hi) = weights
        .iter()
        .fold((1.0f64, 0.0f64), |(lo, hi), &w| (lo.min(w), hi.max(w)));
    assert!(
        lo < 0.9 && hi - lo > 0.1,
        "weights should vary: {weights:?}"
    );
    let out = dir.path().join("out");
    let csv = || std::fs::read(out.join("observations.csv")).unwrap();
    let fresh_csv = csv();

    let cached = photo_run(dir.path());
    assert!(cached.images.iter().all(|r| r.cached));
    assert_eq!(cached.dataset, fresh.dataset);
    assert_eq!(csv(), fresh_csv);

    // The older format: no version, each corner as [id, u, v, σ].
    let file = out.join(cache::FILE_NAME);
    let mut old: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
    old.as_object_mut().unwrap().remove("version");
    for entry in old["images"].as_object_mut().unwrap().values_mut() {
        let corners = entry["outcome"]["corners"].as_array_mut().unwrap();
        for c in corners.iter_mut() {
            *c = serde_json::json!([c["index"], c["uv"][0], c["uv"][1], c["sigma"]]);
        }
    }
    std::fs::write(&file, serde_json::to_vec(&old).unwrap()).unwrap();
    let after_old = photo_run(dir.path());
    assert!(after_old.images.iter().all(|r| !r.cached));
    assert_eq!(after_old.dataset, fresh.dataset);
    assert!(photo_run(dir.path()).images.iter().all(|r| r.cached));

    std::fs::write(&file, b"{\"version\": 2, \"settings\": ").unwrap();
    let after_broken = photo_run(dir.path());
    assert!(after_broken.images.iter().all(|r| !r.cached));
    assert_eq!(after_broken.dataset, fresh.dataset);
    assert_eq!(csv(), fresh_csv);
}

#[test]
fn two_cameras_any_format_and_detect_only() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    write_photos(&photos, "left");
    write_photos(&photos, "right");
    // The left camera's photos as colour JPEG, the right one's as 16-bit TIFF.
    for k in 0..views().len() {
        for (side, ext) in [("left", "jpg"), ("right", "tif")] {
            let p = photos.join(format!("{side}-{k:02}.png"));
            let img = image::open(&p).unwrap().to_luma8();
            std::fs::remove_file(&p).unwrap();
            let out = photos.join(format!("{side}-{k:02}.{ext}"));
            if side == "right" {
                let g16: ImageBuffer<Luma<u16>, Vec<u16>> =
                    ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
                        Luma([img.get_pixel(x, y)[0] as u16 * 257])
                    });
                DynamicImage::ImageLuma16(g16).save(out).unwrap();
            } else {
                DynamicImage::ImageLuma8(img).to_rgb8().save(out).unwrap();
            }
        }
    }
    // Camera 1 misses time step 07: frames still pair by what `*` matched.
    std::fs::remove_file(photos.join("right-07.tif")).unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!(
            "{BOARD}[[cameras]]\nname = \"cam0\"\nwidth = {W}\nheight = {H}\n\
             [[cameras]]\nname = \"cam1\"\nwidth = {W}\nheight = {H}\n\
             [data]\nphotos = {{ cam0 = \"photos/left-*.jpg\", cam1 = \"photos/right-*.tif\" }}\n[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
    let obs = dir.path().join("obs.csv");
    let out = deformcal(&[
        "detect",
        "--config",
        config.to_str().unwrap(),
        "--out",
        obs.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("board found in 19 of 19 images"),
        "{stderr}"
    );
    let csv = std::fs::read_to_string(dir.path().join("out/detections.csv")).unwrap();
    assert!(csv.contains("photos/right-08.tif,cam1,8,"), "{csv}");
    assert!(csv.contains("photos/left-09.jpg,cam0,9,"), "{csv}");
    assert!(csv.contains("photos/left-07.jpg,cam0,7,"), "{csv}");
    assert!(!csv.contains("right-07"), "{csv}");
    let text = std::fs::read_to_string(&obs).unwrap();
    assert!(text.contains("\ncam1,0,0,"), "16-bit TIFF detected");
    assert!(text.contains("\ncam0,9,0,"), "colour JPEG detected");
    assert!(
        !dir.path().join("out/calibration.json").exists(),
        "detect only"
    );
}

#[test]
fn a_photo_of_another_size_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    write_photos(&dir.path().join("photos"), "img");
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!(
            "{BOARD}[[cameras]]\nname = \"cam0\"\nwidth = 1024\nheight = 768\n\
             [data]\nphotos = \"photos/*.png\"\n[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
    let out = deformcal(&["--config", config.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.starts_with("error: photos `photos/*.png`") && stderr.contains("800x600"),
        "{stderr}"
    );
    assert!(!dir.path().join("out").exists());
}

/// Three files that are not images: detection rejects each, so the error says how
/// many files the pattern listed without rendering photos.
fn write_non_images(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    for f in ["a.png", "b.png", "c.png"] {
        std::fs::write(dir.join(f), b"not a picture").unwrap();
    }
}

/// Runs deformcal in `dir` on the config `c.toml` given by its bare name.
fn run_in(dir: &Path, config: &str) -> String {
    std::fs::write(dir.join("c.toml"), config).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(["--config", "c.toml"])
        .current_dir(dir)
        .output()
        .expect("run deformcal");
    assert!(!out.status.success());
    String::from_utf8_lossy(&out.stderr).to_string()
}

const CAM0: &str = "[[cameras]]\nname = \"cam0\"\nwidth = 640\nheight = 480\n";

#[test]
fn patterns_without_a_folder_start_in_the_configs_folder() {
    let dir = tempfile::tempdir().unwrap();
    write_non_images(&dir.path().join("photos"));
    for pattern in ["**/*.png", "photos/*.png", "*/*.png"] {
        let stderr = run_in(
            dir.path(),
            &format!("{BOARD}{CAM0}[data]\nphotos = \"{pattern}\"\n"),
        );
        assert!(
            stderr.contains(&format!("photos `{pattern}`")) && stderr.contains("in 0 of 3 images"),
            "{pattern}: {stderr}"
        );
    }
}

#[cfg(unix)]
#[test]
fn a_link_loop_lists_each_photo_once() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    write_non_images(&photos);
    std::os::unix::fs::symlink(".", photos.join("loop")).unwrap();
    std::os::unix::fs::symlink("..", photos.join("up")).unwrap();
    let stderr = run_in(
        dir.path(),
        &format!("{BOARD}{CAM0}[data]\nphotos = \"photos/**/*.png\"\n"),
    );
    assert!(stderr.contains("in 0 of 3 images"), "{stderr}");
}

#[cfg(unix)]
#[test]
fn one_photo_reached_by_two_names_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_non_images(&dir.path().join("photos/real"));
    std::os::unix::fs::symlink("real", dir.path().join("photos/alias")).unwrap();
    let stderr = run_in(
        dir.path(),
        &format!("{BOARD}{CAM0}[data]\nphotos = \"photos/*/*.png\"\n"),
    );
    assert!(
        stderr.starts_with("error: photos `photos/*/*.png`: `photos/alias/a.png` and `photos/real/a.png` are the same file"),
        "{stderr}"
    );
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    // The same photos for two cameras: a rig with no baseline.
    let stderr = run_in(
        dir.path(),
        &format!(
            "{BOARD}{CAM0}[[cameras]]\nname = \"cam1\"\nwidth = 640\nheight = 480\n\
             [data]\nphotos = {{ cam0 = \"photos/real/*.png\", cam1 = \"photos/real/*.png\" }}\n"
        ),
    );
    assert!(
        stderr.contains("`photos/real/a.png` is matched by the patterns of both camera `cam0` and camera `cam1`"),
        "{stderr}"
    );
    assert!(!dir.path().join("out").exists());
}

/// An 8 × 6 board (9 × 7 squares) looks alike turned by 180°: its views are
/// labelled by their orientation in the image, so a correction per corner of the
/// printed board cannot use them. `static` is refused with a message and no
/// output; `auto` leaves `full` out of its default candidates (and says so) and
/// calibrates.
#[test]
fn a_board_alike_turned_by_180_degrees_has_no_per_corner_correction() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir_all(&photos).unwrap();
    for (k, (rvec, dist, shift, _)) in views().into_iter().take(8).enumerate() {
        let mut sc = scene(6, 8, rvec, dist, shift);
        sc.seed = k as u64;
        sc.supersample = 4;
        let (img, _) = render_board(&sc);
        img.save(photos.join(format!("img-{k:02}.png"))).unwrap();
    }
    let write = |method: &str| {
        let config = dir.path().join(format!("{method}.toml"));
        std::fs::write(
            &config,
            format!(
                "[target]\nrows = 6\ncols = 8\nspacing = 0.03\n[[cameras]]\nname = \"cam0\"\n\
                 width = {W}\nheight = {H}\nmodel = \"radial3\"\n[data]\nphotos = \"photos/img-*.png\"\n\
                 [calibration]\nmethod = \"{method}\"\n[output]\ndir = \"out-{method}\"\n"
            ),
        )
        .unwrap();
        config
    };
    let out = deformcal(&["--config", write("static").to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("method `static` estimates a correction per corner")
            && stderr.contains("looks alike turned by 180 degrees"),
        "{stderr}"
    );
    assert!(!dir.path().join("out-static/calibration.json").exists());

    let out = deformcal(&["--config", write("auto").to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("auto left out full"), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("out-auto/calibration.json")).unwrap(),
    )
    .unwrap();
    let text = json.to_string();
    assert!(!json["method"].as_str().unwrap().contains("full"), "{text}");
    assert!(text.contains("auto left out full"), "{text}");
    let csv = std::fs::read_to_string(dir.path().join("out-auto/detections.csv")).unwrap();
    assert!(csv.contains("labelled by its orientation"), "{csv}");
}
