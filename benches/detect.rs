//! Detection time per megapixel: our detector single-threaded and over all cores
//! (rayon, one image per task), against OpenCV's classic detector + cornerSubPix
//! (one thread) on the same images. Images: rendered 9×6 boards at 1280×960, and
//! OpenCV's sample photos (640×480) when tests/opencv_photos.rs has cached them.
//! Run with `cargo bench --bench detect`.
#[path = "../tests/detect_common/mod.rs"]
mod detect_common;

use deformcal::app::detect::render::{render_board, Camera, Scene};
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
}
