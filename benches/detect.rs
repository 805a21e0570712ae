//! Detection time per megapixel: our detector single-threaded and over all cores
//! (rayon, one image per task), against OpenCV's classic detector + cornerSubPix
//! (one thread) on the same images. Images: rendered 9×6 boards at 1280×960, and
//! OpenCV's sample photos (640×480) when tests/opencv_photos.rs has cached them;
//! and ChArUco boards (800×600), whole and partly outside the image (where a
//! second pass at ×2 runs), against OpenCV's `cv2.aruco`.
//! Run with `cargo bench --bench detect`.
#[path = "../tests/detect_common/mod.rs"]
mod detect_common;

use deformcal::app::detect::charuco::{Albedo, CharucoSpec};
use deformcal::app::detect::render::{render_board, render_with_albedo, Camera, Scene};
use deformcal::app::detect::Detector;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const REPEATS: usize = 3;

/// A 9×6 board, 30 mm squares, in one of a few poses, at 1280×960.
fn scene(k: usize) -> Scene {
    let rvec = [
        0.3 - 0.1 * k as f64,
        0.2 * (k % 3) as f64 - 0.2,
        0.4 * k as f64,
    ];
    Scene {
        camera: Camera {
            fx: 1100.0,
            fy: 1100.0,
            cx: 639.5,
            cy: 479.5,
            k1: -0.1,
            k2: 0.02,
        }
        .into(),
        width: 1280,
        height: 960,
        seed: k as u64,
        supersample: 4,
        ..detect_common::scene(6, 9, rvec, 0.6, [0.0, 0.0])
    }
}

/// Median over REPEATS of the wall time of `f`, in ms.
fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..REPEATS)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[REPEATS / 2]
}

/// Times one image set and prints a line per detector.
fn bench(label: &str, paths: &[PathBuf]) {
    let images: Vec<image::DynamicImage> = paths.iter().map(|p| image::open(p).unwrap()).collect();
    let mp: f64 = images
        .iter()
        .map(|i| (i.width() * i.height()) as f64 / 1e6)
        .sum();
    let det = Detector::default();
    let run = |img: &image::DynamicImage| det.detect_image(img, 6, 9).is_ok();
    let found = images.iter().filter(|i| run(i)).count();
    // calib-targets computes its corner response on rayon's pool: one thread
    // means a pool of one.
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let one = median_ms(|| {
        single.install(|| {
            images.iter().for_each(|i| {
                run(i);
            })
        })
    });
    let threads = rayon::current_num_threads();
    let all = median_ms(|| {
        images.par_iter().for_each(|i| {
            run(i);
        })
    });
    println!(
        "{label}: {} images, {:.2} MP each, boards found {found}",
        images.len(),
        mp / images.len() as f64
    );
    println!("  deformcal, 1 thread:   {:7.1} ms/MP", one / mp);
    println!("  deformcal, {threads} threads:  {:7.1} ms/MP", all / mp);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/tools/opencv_photos.py");
    match Command::new("/usr/bin/python3")
        .arg(script)
        .args(["6", "9", "0.03"])
        .args(paths)
        .output()
    {
        Ok(out) if out.status.success() => {
            let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            let ms = j["ms_per_image"].as_f64().unwrap();
            println!(
                "  OpenCV findChessboardCorners + cornerSubPix, 1 thread: {:7.1} ms/MP (boards found {})",
                ms * images.len() as f64 / mp,
                j["found"].as_array().unwrap().len()
            );
        }
        _ => println!("  OpenCV: not measured (needs /usr/bin/python3 with python3-opencv)"),
    }
}

/// A 5 × 7-square DICT_4X4_50 board (24 inner corners) in view `k`: tilted,
/// 0.5 m away, centred or (`partial`) with its centre near the image's left or
/// top edge, so that part of it is outside the picture.
fn charuco_scene(spec: &CharucoSpec, k: usize, partial: bool) -> Scene {
    let t = spec.target();
    let rvec = [
        0.3 - 0.15 * (k % 4) as f64,
        0.25 - 0.1 * (k % 5) as f64,
        0.5 * k as f64,
    ];
    let cam = detect_common::camera();
    let dist = 0.5;
    let at = match (partial, k % 2) {
        (false, _) => [0.5, 0.5],
        (true, 0) => [0.02, 0.5],
        (true, _) => [0.5, 0.03],
    };
    let shift = [
        (at[0] * detect_common::W as f64 - cam.cx) / cam.fx * dist,
        (at[1] * detect_common::H as f64 - cam.cy) / cam.fy * dist,
    ];
    Scene {
        spacing: spec.square,
        seed: k as u64,
        ..detect_common::scene(t.rows, t.cols, rvec, dist, shift)
    }
}

/// ChArUco detection time per megapixel, one thread, for whole and partial
/// views apart: a view with corners unfound (every partial one) pays for the
/// second pass at ×2.
fn bench_charuco(dir: &Path) {
    let spec = CharucoSpec {
        rows: 5,
        cols: 7,
        square: 0.03,
        marker: 0.022,
        dictionary: "DICT_4X4_50".into(),
    };
    let albedo = Albedo::new(&spec).unwrap();
    let det = Detector {
        charuco: Some(spec.clone()),
        ..Detector::default()
    };
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let t = spec.target();
    for partial in [false, true] {
        let label = if partial { "partial" } else { "whole" };
        let paths: Vec<PathBuf> = (0..8)
            .map(|k| {
                let p = dir.join(format!("charuco-{label}-{k}.png"));
                let sc = charuco_scene(&spec, k, partial);
                render_with_albedo(&sc, &|x, y| albedo.grey(x, y))
                    .0
                    .save(&p)
                    .unwrap();
                p
            })
            .collect();
        let images: Vec<image::DynamicImage> =
            paths.iter().map(|p| image::open(p).unwrap()).collect();
        let mp: f64 = images
            .iter()
            .map(|i| (i.width() * i.height()) as f64 / 1e6)
            .sum();
        let corners: usize = images
            .iter()
            .filter_map(|i| det.detect_image(i, t.rows, t.cols).ok())
            .map(|d| d.corners.len())
            .sum();
        let ms = median_ms(|| {
            single.install(|| {
                images.iter().for_each(|i| {
                    let _ = det.detect_image(i, t.rows, t.cols);
                })
            })
        });
        println!(
            "ChArUco 5x7 DICT_4X4_50, {label} views, {} images, 800x600: corners found {corners}",
            images.len()
        );
        println!("  deformcal, 1 thread:   {:7.1} ms/MP", ms / mp);
        let input = serde_json::json!({
            "rows": spec.rows, "cols": spec.cols, "square": spec.square,
            "marker": spec.marker, "dictionary": spec.dictionary, "images": paths,
        });
        match opencv_charuco(&input) {
            Some(j) => {
                let found: usize = j["corners"]
                    .as_array()
                    .map(|a| {
                        a.iter()
                            .filter_map(|c| c.as_object())
                            .map(|c| c.len())
                            .sum()
                    })
                    .unwrap_or(0);
                println!(
                    "  OpenCV cv2.aruco + cornerSubPix, 1 thread: {:7.1} ms/MP (corners found {found})",
                    j["ms_per_image"].as_f64().unwrap_or(f64::NAN) * images.len() as f64 / mp
                );
            }
            None => println!("  OpenCV: not measured (needs /usr/bin/python3 with python3-opencv)"),
        }
    }
}

/// tests/tools/charuco_cv2.py on `input`, its JSON answer, or None when it
/// cannot run.
fn opencv_charuco(input: &serde_json::Value) -> Option<serde_json::Value> {
    use std::io::Write;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/tools/charuco_cv2.py");
    let mut child = Command::new("/usr/bin/python3")
        .arg(script)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .ok()?;
    child
        .stdin
        .take()?
        .write_all(input.to_string().as_bytes())
        .ok()?;
    let out = child.wait_with_output().ok()?;
    if !out.status.success() {
        return None;
    }
    serde_json::from_slice(&out.stdout).ok()
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let rendered: Vec<PathBuf> = (0..8)
        .map(|k| {
            let p = dir.path().join(format!("board-{k}.png"));
            render_board(&scene(k)).0.save(&p).unwrap();
            p
        })
        .collect();
    bench("rendered 9x6 boards, 1280x960", &rendered);
    let photos = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-data/opencv-doc/photos");
    let mut samples: Vec<PathBuf> = std::fs::read_dir(&photos)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    samples.retain(|p| p.extension().is_some_and(|e| e == "jpg"));
    samples.sort();
    if samples.is_empty() {
        println!(
            "OpenCV sample photos: not cached (run cargo test --release --test integration opencv_photos::)"
        );
    } else {
        bench("OpenCV sample photos, 640x480", &samples);
    }
    bench_charuco(dir.path());
}
