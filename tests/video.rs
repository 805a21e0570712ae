//! A video in, end to end through the real binary: a rendered video of a carried,
//! slowly bending board (held near the image centre most of the time, with quick
//! swings to the corners, some frames smeared by motion) written as an mp4 with
//! ffmpeg → `deformcal calibrate` with `[data] video`: at most `max_frames` kept,
//! the planted blurred frames not, timestamps in `detections.csv`, the cache on a
//! rerun, and the intrinsics at least as close to the truth (mapping error) as a
//! calibration from every 10th frame of the same mp4. Also: no ffmpeg, and a file
//! that is not a video, each one message and a non-zero exit.
use deformcal::app::detect::render::{render_board, Camera, Scene};
use deformcal::model::lens::Intrinsics;
use deformcal::model::metrics::mapping_error;
use image::GrayImage;
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};

const W: u32 = 640;
const H: u32 = 480;
const FPS: f64 = 30.0;
const FRAMES: usize = 240;
/// Frames smeared by a fast move (during the swings; 60 and 130 are also among
/// every 10th).
const BLURRED: [usize; 8] = [52, 58, 60, 122, 128, 130, 192, 198];
const MAX_FRAMES: usize = 20;

fn camera() -> Camera {
    Camera {
        fx: 560.0,
        fy: 560.0,
        cx: 319.5,
        cy: 239.5,
        k1: -0.12,
        k2: 0.03,
    }
}

fn deformcal(args: &[&str], path_env: Option<&str>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_deformcal"));
    c.args(args);
    if let Some(p) = path_env {
        c.env("PATH", p);
    }
    c.output().expect("run deformcal")
}

fn have_ffmpeg() -> bool {
    Command::new("ffmpeg").arg("-version").output().is_ok()
}

/// No ffmpeg: says that the test is skipped.
fn ffmpeg_missing() -> bool {
    let missing = !have_ffmpeg();
    if missing {
        eprintln!("skipped: no `ffmpeg` on PATH (Debian: apt-get install ffmpeg; CI installs it)");
    }
    missing
}

/// Where the board is held at key frames: (frame, rotation, distance, shift).
const KEYS: [(usize, [f64; 3], f64, [f64; 2]); 12] = [
    (0, [0.05, 0.0, 0.0], 0.55, [0.0, 0.0]),
    (40, [0.1, -0.05, 0.05], 0.56, [0.01, 0.0]),
    (55, [0.45, -0.3, 0.1], 0.5, [-0.12, -0.08]),
    (70, [0.05, 0.0, 0.0], 0.55, [0.0, 0.0]),
    (110, [-0.05, 0.05, 0.0], 0.55, [0.0, 0.01]),
    (125, [-0.4, 0.35, -0.1], 0.5, [0.12, 0.08]),
    (140, [0.0, 0.05, 0.0], 0.55, [0.0, 0.0]),
    (180, [0.08, 0.0, 0.02], 0.56, [-0.01, 0.0]),
    (195, [0.4, 0.35, 0.2], 0.5, [0.12, -0.08]),
    (210, [0.0, 0.0, 0.0], 0.55, [0.0, 0.0]),
    (225, [-0.4, -0.35, 0.0], 0.5, [-0.12, 0.08]),
    (239, [0.05, 0.0, 0.0], 0.55, [0.0, 0.0]),
];

/// The scene of frame `i`: the key poses eased into each other, the board
/// bending slowly (a few mm over seconds), as a carried board does.
fn scene_at(i: f64) -> Scene {
    let k = KEYS.iter().rposition(|k| k.0 as f64 <= i).unwrap_or(0);
    let (a, b) = (KEYS[k], KEYS[(k + 1).min(KEYS.len() - 1)]);
    let span = (b.0 as f64 - a.0 as f64).max(1.0);
    let s = ((i - a.0 as f64) / span).clamp(0.0, 1.0);
    let s = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
    let mix = |x: f64, y: f64| x + (y - x) * s;
    let rvec = [
        mix(a.1[0], b.1[0]),
        mix(a.1[1], b.1[1]),
        mix(a.1[2], b.1[2]),
    ];
    let (dist, shift) = (mix(a.2, b.2), [mix(a.3[0], b.3[0]), mix(a.3[1], b.3[1])]);
    Scene {
        camera: camera().into(),
        bend: 0.002 * (2.0 * std::f64::consts::PI * i / FRAMES as f64).sin(),
        width: W,
        height: H,
        blur: 0.7,
        noise: 1.5,
        seed: i as u64,
        supersample: 2,
        ..crate::detect_common::scene(6, 9, rvec, dist, shift)
    }
}

/// Motion blur: the frame averaged over the poses of ±0.3 frames around it (a
/// shutter open for 60 % of the frame time during a quick swing).
fn frame(i: usize) -> GrayImage {
    if !BLURRED.contains(&i) {
        return render_board(&scene_at(i as f64)).0;
    }
    let steps = 7;
    let shots: Vec<GrayImage> = (0..steps)
        .map(|k| {
            render_board(&scene_at(
                i as f64 - 0.3 + 0.6 * k as f64 / (steps - 1) as f64,
            ))
            .0
        })
        .collect();
    GrayImage::from_fn(W, H, |x, y| {
        let sum: u32 = shots.iter().map(|s| s.get_pixel(x, y).0[0] as u32).sum();
        image::Luma([((sum + steps / 2) / steps) as u8])
    })
}

/// Renders the video and pipes it to ffmpeg, a few frames at a time.
fn write_video(path: &Path) {
    let chunks: Vec<Vec<usize>> = (0..FRAMES)
        .collect::<Vec<_>>()
        .chunks(8)
        .map(<[usize]>::to_vec)
        .collect();
    let frames = chunks
        .into_iter()
        .flat_map(|c| c.par_iter().map(|&i| frame(i)).collect::<Vec<_>>());
    encode(path, frames);
}

/// Writes `frames` (W × H grey) as H.264 at 30 fps, near-lossless as a good
/// camera records.
fn encode(path: &Path, frames: impl Iterator<Item = GrayImage>) {
    let mut ff = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray"])
        .args(["-s", &format!("{W}x{H}"), "-r", "30", "-i", "-"])
        .args([
            "-c:v", "libx264", "-preset", "veryfast", "-crf", "10", "-pix_fmt", "yuv420p",
        ])
        .arg(path)
        .stdin(Stdio::piped())
        .spawn()
        .expect("start ffmpeg");
    let mut stdin = ff.stdin.take().unwrap();
    for img in frames {
        stdin.write_all(img.as_raw()).unwrap();
    }
    drop(stdin);
    assert!(
        ff.wait().unwrap().success(),
        "ffmpeg could not write the video"
    );
}

/// The calibrated camera of `out/calibration.json` and its mapping error to the truth.
fn mapping_error_of(out: &Path) -> f64 {
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("calibration.json")).unwrap()).unwrap();
    let k = &json["cameras"][0]["intrinsics"];
    let f = |n: &str| k[n].as_f64().unwrap_or(0.0);
    let est = Intrinsics::radial3([
        f("fx"),
        f("fy"),
        f("cx"),
        f("cy"),
        f("k1"),
        f("k2"),
        f("k3"),
    ]);
    mapping_error(&camera().into(), &est, W, H)
}

const SETUP: &str = "[target]\nrows = 6\ncols = 9\nspacing = 0.03\n\
    [[cameras]]\nname = \"cam0\"\nwidth = 640\nheight = 480\nmodel = \"radial3\"\n";
const METHOD: &str = "[calibration]\nmethod = \"dynamic\"\n";

/// (frame, time, status, reason) of every row of `detections.csv`.
fn rows(out: &Path) -> Vec<(usize, f64, String, String)> {
    let text = std::fs::read_to_string(out.join("detections.csv")).unwrap();
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let head: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(
        head,
        [
            "file",
            "camera",
            "frame",
            "time_s",
            "sharpness",
            "corners",
            "status",
            "reason"
        ]
    );
    r.records()
        .map(|x| {
            let x = x.unwrap();
            (
                x[2].parse().unwrap(),
                x[3].parse().unwrap(),
                x[6].to_string(),
                x[7].to_string(),
            )
        })
        .collect()
}

#[test]
fn chosen_frames_calibrate_at_least_as_well_as_every_tenth() {
    if ffmpeg_missing() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    write_video(&dir.path().join("capture.mp4"));
    let config = dir.path().join("video.toml");
    std::fs::write(
        &config,
        format!("{SETUP}[data]\nvideo = \"capture.mp4\"\nstride = 2\nmax_frames = {MAX_FRAMES}\n{METHOD}[output]\ndir = \"out\"\n"),
    )
    .unwrap();
    let run = deformcal(&["calibrate", "--config", config.to_str().unwrap()], None);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let out = dir.path().join("out");
    let rows = rows(&out);
    assert_eq!(rows.len(), FRAMES / 2, "every 2nd frame sampled");
    let kept: Vec<&(usize, f64, String, String)> = rows
        .iter()
        .filter(|r| r.2 == "complete" || r.2 == "partial")
        .collect();
    eprintln!(
        "kept frames: {:?}",
        kept.iter().map(|r| r.0).collect::<Vec<_>>()
    );
    assert!(
        (3..=MAX_FRAMES).contains(&kept.len()),
        "{} kept",
        kept.len()
    );
    assert!(kept.windows(2).all(|w| w[0].0 < w[1].0), "time order");
    for r in &rows {
        assert!(
            (r.1 - r.0 as f64 / FPS).abs() < 1e-3,
            "frame {} at {} s",
            r.0,
            r.1
        );
    }
    for b in BLURRED {
        let r = rows.iter().find(|r| r.0 == b).unwrap();
        assert!(
            r.2 == "skipped" || r.2 == "rejected",
            "blurred frame {b} kept: {r:?}"
        );
    }
    let flagged = rows
        .iter()
        .filter(|r| r.3.starts_with("motion blur"))
        .count();
    let wrongly = rows
        .iter()
        .filter(|r| r.3.starts_with("motion blur") && !BLURRED.contains(&r.0))
        .count();
    eprintln!("{flagged} frames flagged as motion-blurred, {wrongly} of them not planted");
    assert!(
        flagged >= BLURRED.len() / 2 && wrongly <= 2,
        "{flagged} flagged, {wrongly} wrongly"
    );
    let chosen = mapping_error_of(&out);

    // The same mp4, every 10th frame, through the photos path.
    let tenth = dir.path().join("tenth");
    std::fs::create_dir_all(&tenth).unwrap();
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(dir.path().join("capture.mp4"))
        .args(["-vf", "select=not(mod(n\\,10))", "-fps_mode", "passthrough"])
        .arg(tenth.join("f%03d.png"))
        .status()
        .unwrap();
    assert!(st.success());
    let config10 = dir.path().join("tenth.toml");
    std::fs::write(
        &config10,
        format!("{SETUP}[data]\nphotos = \"tenth/f*.png\"\n{METHOD}[output]\ndir = \"out10\"\n"),
    )
    .unwrap();
    let run10 = deformcal(&["calibrate", "--config", config10.to_str().unwrap()], None);
    assert!(
        run10.status.success(),
        "{}",
        String::from_utf8_lossy(&run10.stderr)
    );
    let stderr10 = String::from_utf8_lossy(&run10.stderr);
    let found = stderr10.lines().find(|l| l.starts_with("board found in"));
    eprintln!("every 10th: {}", found.unwrap_or("?"));
    let tenth_err = mapping_error_of(&dir.path().join("out10"));
    eprintln!("mapping error to the truth: chosen {} frames {chosen:.4} px, every 10th ({} frames) {tenth_err:.4} px", kept.len(), FRAMES / 10);
    assert!(
        chosen <= tenth_err,
        "chosen {chosen} px, every 10th {tenth_err} px"
    );

    // A rerun decodes nothing: every sampled frame comes from the cache.
    let again = deformcal(&["calibrate", "--config", config.to_str().unwrap()], None);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("{} reused from the cache", FRAMES / 2)),
        "{stderr}"
    );
    assert!((mapping_error_of(&out) - chosen).abs() < 1e-9);
}

#[test]
fn no_ffmpeg_or_no_video_is_one_message() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.mp4"), b"this is not a video").unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!("{SETUP}[data]\nvideo = \"bad.mp4\"\n[output]\ndir = \"out\"\n"),
    )
    .unwrap();
    let c = config.to_str().unwrap();
    let empty = dir.path().join("empty-path");
    std::fs::create_dir_all(&empty).unwrap();
    let none = deformcal(&["calibrate", "--config", c], Some(empty.to_str().unwrap()));
    let stderr = String::from_utf8_lossy(&none.stderr);
    assert_eq!(none.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("bad.mp4")
            && stderr.contains("is not installed")
            && stderr.contains("apt-get install ffmpeg"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!dir.path().join("out/calibration.json").exists());
    if !have_ffmpeg() {
        eprintln!("skipped the unreadable-video half: no `ffmpeg` on PATH");
        return;
    }
    let bad = deformcal(&["calibrate", "--config", c], None);
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("bad.mp4: not a readable video"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "one message: {stderr}");
    // A missing file names the file.
    let gone = deformcal(
        &[
            "calibrate",
            "--video",
            dir.path().join("gone.mp4").to_str().unwrap(),
            "--board",
            "9x6",
            "--square",
            "0.03",
        ],
        None,
    );
    let stderr = String::from_utf8_lossy(&gone.stderr);
    assert_ne!(gone.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("gone.mp4"), "{stderr}");
}

/// `(u, v)` of a `w` × `h` picture turned counter-clockwise by `ccw` degrees
/// (a quarter-turn multiple), in the turned picture.
fn turn_point(p: [f64; 2], w: u32, h: u32, ccw: i32) -> [f64; 2] {
    let (w, h) = (w as f64 - 1.0, h as f64 - 1.0);
    match ccw.rem_euclid(360) {
        90 => [p[1], w - p[0]],
        180 => [w - p[0], h - p[1]],
        270 => [h - p[1], p[0]],
        _ => p,
    }
}

/// A phone records a portrait video as landscape frames plus a display matrix;
/// players (and ffmpeg) turn the frames for display. Our frames must be the
/// upright ones, of the displayed size, with the board's corners where they
/// are in the upright picture (within 1 px: H.264 moves some by 0.4 px; a
/// wrong turn or a mirror moves them by hundreds). The expected turn is read from ffprobe's
/// `rotation` (libavutil's display matrix angle, counter-clockwise).
#[test]
fn rotated_videos_come_out_upright() {
    use deformcal::app::video::ffmpeg::{probe, Frames};
    if ffmpeg_missing() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let keys = [0.0, 55.0, 125.0, 195.0];
    let shots: Vec<_> = keys
        .par_iter()
        .map(|&i| render_board(&scene_at(i)))
        .collect();
    let plain = dir.path().join("plain.mp4");
    encode(&plain, shots.iter().map(|s| s.0.clone()));
    for tag in [0, 90, 180, 270] {
        let video = dir.path().join(format!("rotate{tag}.mp4"));
        let st = Command::new("ffmpeg")
            .args(["-v", "error", "-y", "-i"])
            .arg(&plain)
            .args(["-c", "copy", "-metadata:s:v:0", &format!("rotate={tag}")])
            .arg(&video)
            .status()
            .unwrap();
        assert!(st.success());
        let side = Command::new("ffprobe")
            .args(["-v", "error", "-select_streams", "v:0"])
            .args([
                "-show_entries",
                "stream_side_data=rotation",
                "-of",
                "csv=p=0",
            ])
            .arg(&video)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&side.stdout);
        let ccw = text
            .trim()
            .trim_matches(',')
            .parse::<f64>()
            .unwrap_or(0.0)
            .round() as i32;
        assert_eq!(ccw.rem_euclid(90), 0, "rotate={tag}: rotation {text}");
        let quarter = ccw.rem_euclid(180) == 90;
        let p = probe(&video).unwrap();
        let size = if quarter { (H, W) } else { (W, H) };
        assert_eq!((p.width, p.height), size, "rotate={tag} (rotation {ccw}°)");
        let mut frames = Frames::start(&video, &p, 1).unwrap();
        let mut k = 0;
        while let Some(f) = frames.next_frame().unwrap() {
            assert_eq!(f.image.dimensions(), size);
            let det = deformcal::app::detect::detect_image(
                &image::DynamicImage::ImageLuma8(f.image),
                6,
                9,
            )
            .unwrap_or_else(|e| panic!("rotate={tag} frame {k}: {e}"));
            let truth = &shots[k].1;
            let worst = det
                .corners
                .iter()
                .map(|c| {
                    let t = turn_point(truth[c.index].unwrap(), W, H, ccw);
                    (t[0] - c.uv[0]).hypot(t[1] - c.uv[1])
                })
                .fold(0.0, f64::max);
            assert!(
                det.corners.len() >= 20 && worst < 1.0,
                "rotate={tag} (rotation {ccw}°) frame {k}: {} corners, worst {worst:.3} px from the upright truth",
                det.corners.len()
            );
            k += 1;
        }
        frames.finish().unwrap();
        assert_eq!(k, keys.len());
    }
}
