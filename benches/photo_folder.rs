//! A big photo folder as a user calibrates from it: FRAMES rendered 9 × 6 boards
//! (1600 × 1200 JPEG, random poses, blur and noise) in DIR, then `deformcal detect`
//! and `deformcal calibrate` on them through the real binary, each timed with its
//! peak memory (/usr/bin/time), and `detect` again to time the cache.
//! Rendering is skipped for frames already in DIR, so a second run times only
//! the program.
//!
//! `FRAMES=2000 DIR=/tmp/deformcal-folder cargo bench --bench photo_folder`
//! (defaults: 200 frames, a temporary folder). Needs the release binary
//! (`cargo build --release`).
#[path = "../tests/detect_common/mod.rs"]
mod detect_common;

use deformcal::app::detect::render::{render_board, Camera, Scene};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Command;

const W: u32 = 1600;
const H: u32 = 1200;
/// Distinct board poses rendered; the other frames are these with other noise.
const POSES: usize = 250;
/// Grey-level noise σ of every frame.
const NOISE: f64 = 2.0;

/// Adds Gaussian noise of σ `sigma` (Box–Muller on [`unit`]) to `img`.
fn add_noise(img: &mut image::GrayImage, sigma: f64, seed: u64) {
    for (i, p) in img.pixels_mut().enumerate() {
        let (a, b) = (unit(i, seed).max(1e-300), unit(i, !seed));
        let g = (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos();
        p.0[0] = (p.0[0] as f64 + sigma * g).round().clamp(0.0, 255.0) as u8;
    }
}

/// A number in [0, 1) from `k` and `salt` (splitmix64): the poses must not
/// depend on the order frames are rendered in.
fn unit(k: usize, salt: u64) -> f64 {
    let mut z = (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ salt;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Frame `k`: the board tilted up to about 35°, 0.45–0.8 m away, anywhere in
/// the image, as a handheld capture would have it (flat: a bent board costs the
/// renderer eight ray intersections per sample).
fn scene(k: usize) -> Scene {
    let u = |salt: u64| unit(k, salt) * 2.0 - 1.0;
    let rvec = [0.6 * u(1), 0.6 * u(2), 0.5 * u(3)];
    let dist = 0.45 + 0.35 * unit(k, 4);
    let shift = [0.25 * dist * u(5), 0.18 * dist * u(6)];
    Scene {
        camera: Camera {
            fx: 1350.0,
            fy: 1350.0,
            cx: 799.5,
            cy: 599.5,
            k1: -0.12,
            k2: 0.03,
        }
        .into(),
        vignetting: 0.1,
        width: W,
        height: H,
        blur: 0.8 + 0.6 * unit(k, 8),
        noise: NOISE,
        seed: k as u64,
        supersample: 2,
        ..detect_common::scene(6, 9, rvec, dist, shift)
    }
}

/// Renders the frames not yet in `dir` as JPEG (quality 92, as a phone writes).
/// Ray casting a 2 MP frame takes about 1.5 s, so [`POSES`] poses are rendered
/// without noise and each is written FRAMES / [`POSES`] times with noise of its
/// own: every file differs, costs a full decode and detection, and is a
/// physically possible picture (a board held still), as a video's frames are.
fn render_missing(dir: &Path, frames: usize) {
    std::fs::create_dir_all(dir.join("photos")).unwrap();
    let poses = frames.min(POSES);
    (0..poses).into_par_iter().for_each(|p| {
        let copies: Vec<usize> = (p..frames).step_by(poses).collect();
        let path = |k: usize| dir.join(format!("photos/frame-{k:05}.jpg"));
        if copies.iter().all(|&k| path(k).exists()) {
            return;
        }
        let clean = render_board(&Scene {
            noise: 0.0,
            ..scene(p)
        })
        .0;
        for k in copies {
            let mut img = clean.clone();
            add_noise(&mut img, NOISE, k as u64);
            let mut out = std::io::BufWriter::new(std::fs::File::create(path(k)).unwrap());
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 92)
                .encode_image(&img)
                .unwrap();
        }
    });
    let config = format!(
        "[target]\nrows = 6\ncols = 9\nspacing = 0.03\n\
         [[cameras]]\nname = \"cam0\"\nwidth = {W}\nheight = {H}\nmodel = \"radial3\"\n\
         [data]\nphotos = \"photos/frame-*.jpg\"\n[output]\ndir = \"out\"\n"
    );
    std::fs::write(dir.join("config.toml"), config).unwrap();
}

/// One run of the binary as GNU time saw it.
struct Run {
    /// Wall time (s).
    wall: f64,
    /// User and system CPU time (s): what the run costs on a loaded machine.
    cpu: f64,
    /// Peak resident memory (MB).
    peak_mb: f64,
}

/// Runs the binary with `args` in `dir` under GNU time.
fn timed(dir: &Path, args: &[&str]) -> Run {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/release/deformcal");
    let report = dir.join("time.txt");
    let out = Command::new("/usr/bin/time")
        .arg("-f")
        .arg("%e %U %S %M")
        .arg("-o")
        .arg(&report)
        .arg(&bin)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run /usr/bin/time and target/release/deformcal");
    assert!(
        out.status.success(),
        "deformcal {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&report).unwrap();
    let f: Vec<f64> = text
        .split_whitespace()
        .map(|s| s.parse::<f64>().unwrap())
        .collect();
    Run {
        wall: f[0],
        cpu: f[1] + f[2],
        peak_mb: f[3] / 1024.0,
    }
}

fn main() {
    let frames: usize = std::env::var("FRAMES").map_or(200, |s| s.parse().unwrap());
    let temp = tempfile::tempdir().unwrap();
    let dir: PathBuf = std::env::var("DIR").map_or(temp.path().to_path_buf(), PathBuf::from);
    let t = std::time::Instant::now();
    render_missing(&dir, frames);
    println!(
        "{frames} frames of {W} × {H} in {} ({:.0} s to render the missing ones)",
        dir.display(),
        t.elapsed().as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(dir.join("out"));
    let threads = rayon::current_num_threads();
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{threads} threads, load average {}",
        load.split_whitespace().next().unwrap_or("?")
    );
    let r = timed(&dir, &["detect", "--config", "config.toml"]);
    let mp = frames as f64 * (W * H) as f64 / 1e6;
    println!(
        "detect: {:.1} s ({:.1} ms per frame), CPU {:.1} s ({:.1} ms per frame, {:.1} ms/MP, decoding included), peak {:.0} MB",
        r.wall,
        r.wall * 1e3 / frames as f64,
        r.cpu,
        r.cpu * 1e3 / frames as f64,
        r.cpu * 1e3 / mp,
        r.peak_mb
    );
    let r = timed(&dir, &["detect", "--config", "config.toml"]);
    println!(
        "detect again, from the cache: {:.2} s, peak {:.0} MB",
        r.wall, r.peak_mb
    );
    let r = timed(&dir, &["calibrate", "--config", "config.toml"]);
    println!(
        "calibrate (the default `auto`, detections from the cache): {:.1} s, CPU {:.1} s, peak {:.0} MB",
        r.wall, r.cpu, r.peak_mb
    );
    let csv = std::fs::read_to_string(dir.join("out/detections.csv")).unwrap();
    let found = csv
        .lines()
        .filter(|l| l.contains(",complete,") || l.contains(",partial,"))
        .count();
    println!("boards found in {found} of {frames} frames");
}
