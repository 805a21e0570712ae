//! ChArUco boards on rendered photos with exact truth: ids as OpenCV numbers them,
//! sub-pixel accuracy, partial views, several dictionaries, against OpenCV's
//! `cv2.aruco` on the same images; and a calibration from ChArUco photos
//! through the real binary against the truth and against the true corners.
use crate::common;
use crate::detect_common;

use deformcal::app::detect::charuco::{Albedo, CharucoSpec};
use deformcal::app::detect::render::{render_with_albedo, Scene};
use deformcal::app::detect::{Detection, Detector};
use detect_common::*;
use image::{DynamicImage, GrayImage};
use std::path::Path;

fn spec(rows: usize, cols: usize, dictionary: &str) -> CharucoSpec {
    CharucoSpec {
        rows,
        cols,
        square: 0.03,
        marker: 0.022,
        dictionary: dictionary.into(),
    }
}

/// A scene of the board's inner corners in view `k` of a deterministic random
/// sequence: tilts to ±0.5 rad, any in-plane rotation, 0.45 to 0.7 m, blur
/// 0.5 to 1.2 px. Every third view is partial: the board's centre is put near
/// one of the image's edges or corners (at most 0.1 of the image inside it, at
/// most 0.05 beyond it), so that part of the board lies outside the picture.
fn random_scene(s: &CharucoSpec, k: u64) -> Scene {
    let mut state = k.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5851_F42D;
    let mut uniform = |lo: f64, hi: f64| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((state >> 11) as f64 / (1u64 << 53) as f64)
    };
    let rvec = [uniform(-0.5, 0.5), uniform(-0.5, 0.5), uniform(-3.1, 3.1)];
    let dist = uniform(0.45, 0.7);
    // Where the board's centre lands, as a fraction of the image (0.5 = centre).
    let mut at = [uniform(0.47, 0.53), uniform(0.47, 0.53)];
    if k % 3 == 2 {
        let near_edge = |x: f64| {
            if x < 0.5 {
                x * 0.3 - 0.05
            } else {
                1.05 - (x - 0.5) * 0.3
            }
        };
        // Sides in turn: left/right, top/bottom, then a corner.
        match (k / 3) % 3 {
            0 => at = [near_edge(uniform(0.0, 1.0)), uniform(0.25, 0.75)],
            1 => at = [uniform(0.25, 0.75), near_edge(uniform(0.0, 1.0))],
            _ => at = [near_edge(uniform(0.0, 1.0)), near_edge(uniform(0.0, 1.0))],
        }
    }
    let shift = shift_to(at, dist);
    let t = s.target();
    let mut sc = scene(t.rows, t.cols, rvec, dist, shift);
    sc.spacing = s.square;
    sc.blur = uniform(0.5, 1.2);
    sc.noise = 2.0;
    sc.seed = k;
    // 4×4 supersampling aliases the junctions by a few hundredths of a pixel,
    // which would be charged to the detector.
    sc.supersample = 16;
    sc
}

fn render(s: &CharucoSpec, sc: &Scene) -> (GrayImage, Vec<Option<[f64; 2]>>) {
    let albedo = Albedo::new(s).expect("a valid board");
    render_with_albedo(sc, &|x, y| albedo.grey(x, y))
}

fn detect(s: &CharucoSpec, img: &GrayImage) -> Option<Detection> {
    let det = Detector {
        charuco: Some(s.clone()),
        ..Detector::default()
    };
    let t = s.target();
    det.detect_image(&DynamicImage::ImageLuma8(img.clone()), t.rows, t.cols)
        .ok()
}

/// OpenCV's corners (id → uv) per image, and OpenCV's board layout.
fn opencv(s: &CharucoSpec, files: &[String]) -> serde_json::Value {
    let input = serde_json::json!({
        "rows": s.rows, "cols": s.cols, "square": s.square, "marker": s.marker,
        "dictionary": s.dictionary, "images": files,
    });
    common::run_tool("charuco_cv2.py", &[], &input.to_string())
}

/// Per board: our corners' squared errors against truth, our count and OpenCV's,
/// OpenCV's squared errors. Panics on a wrong id (a corner over 1 px from the
/// truth of its id) in either tool.
#[derive(Default)]
struct Tally {
    ours: Vec<f64>,
    theirs: Vec<f64>,
    /// The same on the partial views only (every third view).
    partial_ours: Vec<f64>,
    partial_theirs: usize,
}

fn check_board(s: &CharucoSpec, views: u64, dir: &Path) -> Tally {
    let mut files = Vec::new();
    let mut truths = Vec::new();
    let mut tally = Tally::default();
    for k in 0..views {
        let sc = random_scene(s, k);
        let (img, truth) = render(s, &sc);
        let partial = k % 3 == 2;
        let outside = truth.iter().filter(|t| t.is_none()).count();
        assert!(
            !partial || (outside > 0 && outside < truth.len()),
            "{} view {k}: {outside} of {} corners out of view, a partial view wants some",
            s.dictionary,
            truth.len()
        );
        let file = dir.join(format!("{}-{}x{}-{k:02}.png", s.dictionary, s.rows, s.cols));
        img.save(&file).unwrap();
        if let Some(det) = detect(s, &img) {
            for c in &det.corners {
                let t = truth[c.index].unwrap_or_else(|| {
                    panic!(
                        "{} view {k}: corner {} is out of view",
                        s.dictionary, c.index
                    )
                });
                let e = (c.uv[0] - t[0]).hypot(c.uv[1] - t[1]);
                assert!(
                    e < 1.0,
                    "{} view {k}: corner {} off by {e} px",
                    s.dictionary,
                    c.index
                );
                tally.ours.push(e * e);
                if partial {
                    tally.partial_ours.push(e * e);
                }
            }
        }
        files.push(file.to_str().unwrap().to_string());
        truths.push(truth);
    }
    let cv = opencv(s, &files);
    for (k, found) in cv["corners"].as_array().unwrap().iter().enumerate() {
        for (id, uv) in found.as_object().unwrap() {
            let id: usize = id.parse().unwrap();
            let t = truths[k][id].expect("OpenCV's corner is in view");
            let e = (uv[0].as_f64().unwrap() - t[0]).hypot(uv[1].as_f64().unwrap() - t[1]);
            assert!(
                e < 1.0,
                "OpenCV {} view {k}: id {id} off by {e} px",
                s.dictionary
            );
            tally.theirs.push(e * e);
            tally.partial_theirs += usize::from(k % 3 == 2);
        }
    }
    // OpenCV's board places corner id at ((c+1)·square, (r+1)·square): ours at
    // (c·square, r·square), the same grid one square over (docs/conventions.md).
    let t = s.target();
    for (id, xy) in cv["layout"].as_object().unwrap() {
        let id: usize = id.parse().unwrap();
        let (r, c) = (id / t.cols, id % t.cols);
        let x = xy[0].as_f64().unwrap() - s.square;
        let y = xy[1].as_f64().unwrap() - s.square;
        assert!((x - c as f64 * s.square).abs() < 1e-6 && (y - r as f64 * s.square).abs() < 1e-6);
    }
    tally
}

fn rms(sq: &[f64]) -> f64 {
    (sq.iter().sum::<f64>() / sq.len().max(1) as f64).sqrt()
}

/// Per board of four boards and three dictionaries (random poses, blur, noise,
/// partial views): our tally and OpenCV's on the same images, every id right.
fn tallies() -> &'static [(CharucoSpec, Tally)] {
    static TALLIES: std::sync::OnceLock<Vec<(CharucoSpec, Tally)>> = std::sync::OnceLock::new();
    TALLIES.get_or_init(measure_tallies)
}

fn measure_tallies() -> Vec<(CharucoSpec, Tally)> {
    let dir = tempfile::tempdir().unwrap();
    let boards = [
        spec(5, 7, "DICT_4X4_50"),
        spec(7, 9, "DICT_5X5_100"),
        spec(6, 8, "DICT_6X6_250"),
        spec(8, 6, "DICT_4X4_50"),
    ];
    boards
        .into_iter()
        .map(|s| {
            let tally = check_board(&s, 12, dir.path());
            eprintln!(
                "{} {}x{}: ours {} corners, RMS {:.4} px; OpenCV {} corners, RMS {:.4} px; \
                 partial views: ours {} (RMS {:.4} px), OpenCV {}",
                s.dictionary,
                s.rows,
                s.cols,
                tally.ours.len(),
                rms(&tally.ours),
                tally.theirs.len(),
                rms(&tally.theirs),
                tally.partial_ours.len(),
                rms(&tally.partial_ours),
                tally.partial_theirs,
            );
            (s, tally)
        })
        .collect()
}

/// Every id right and our corners within 0.06 px RMS of the truth.
#[test]
fn rendered_charuco_corners_match_truth() {
    if !common::python_has(&["cv2"]) {
        return;
    }
    let all: Vec<f64> = tallies()
        .iter()
        .flat_map(|(_, t)| t.ours.iter().copied())
        .collect();
    let ours = rms(&all);
    eprintln!("all boards: ours RMS {ours:.4} px over {}", all.len());
    assert!(ours <= 0.06, "RMS {ours} px");
}

/// At least as many corners as OpenCV finds on the same images, on every board
/// and on its partial views alone.
#[test]
fn rendered_charuco_boards_find_as_many_corners_as_opencv() {
    if !common::python_has(&["cv2"]) {
        return;
    }
    for (s, tally) in tallies() {
        let board = format!("{} {}x{}", s.dictionary, s.rows, s.cols);
        assert!(
            tally.ours.len() >= tally.theirs.len(),
            "{board}: {} corners, OpenCV {}",
            tally.ours.len(),
            tally.theirs.len()
        );
        assert!(
            tally.partial_ours.len() >= tally.partial_theirs,
            "{board}, partial views: {} corners, OpenCV {}",
            tally.partial_ours.len(),
            tally.partial_theirs
        );
    }
}

fn deformcal(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .expect("run deformcal")
}

/// The shift (metres) that puts a board's centre `dist` m away at `at`, a
/// fraction of the image (0.5 = centre; 0 or 1 = on its edge), lens distortion
/// aside.
fn shift_to(at: [f64; 2], dist: f64) -> [f64; 2] {
    let cam = camera();
    [
        (at[0] * W as f64 - cam.cx) / cam.fx * dist,
        (at[1] * H as f64 - cam.cy) / cam.fy * dist,
    ]
}

/// Well-tilted views, half of them with the board's centre on the image's
/// edge or corner, so that part of the board is outside the picture (where a
/// chessboard's place could be ambiguous and a ChArUco board's is not);
/// (rotation, distance, shift).
fn calibration_views() -> Vec<([f64; 3], f64, [f64; 2])> {
    vec![
        ([0.45, -0.1, 0.05], 0.6, [0.0, 0.0]),
        ([-0.4, 0.2, 0.1], 0.6, [0.02, 0.01]),
        ([0.1, 0.5, -0.1], 0.65, [-0.03, 0.0]),
        ([0.2, -0.45, 0.2], 0.55, [0.03, -0.02]),
        ([-0.3, -0.35, 1.6], 0.65, [0.0, 0.03]),
        ([0.35, 0.35, -0.2], 0.5, shift_to([0.02, 0.15], 0.5)),
        ([-0.5, 0.0, 0.0], 0.6, shift_to([0.98, 0.85], 0.6)),
        ([0.0, 0.45, 3.0], 0.55, shift_to([0.9, 0.02], 0.55)),
        ([0.25, 0.25, 0.3], 0.45, shift_to([0.1, 0.95], 0.45)),
        ([0.3, -0.3, -0.1], 0.5, shift_to([0.5, 1.0], 0.5)),
    ]
}

/// The intrinsics and their σ from a calibration.json.
fn intrinsics(path: &Path) -> (serde_json::Value, serde_json::Value) {
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let cam = &json["cameras"][0];
    (
        cam["intrinsics"].clone(),
        cam["uncertainty"]["intrinsics_std"].clone(),
    )
}

/// ChArUco photos through the binary: the intrinsics are the truth's, and equal
/// to a calibration from the true positions of the same corners within 3 σ of
/// the reported uncertainty.
#[test]
fn calibration_from_charuco_photos_matches_truth() {
    let s = spec(7, 10, "DICT_5X5_100");
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("photos")).unwrap();
    let mut truths = Vec::new();
    for (k, (rvec, dist, shift)) in calibration_views().into_iter().enumerate() {
        let t = s.target();
        let mut sc = scene(t.rows, t.cols, rvec, dist, shift);
        sc.seed = k as u64;
        sc.supersample = 4;
        let (img, truth) = render(&s, &sc);
        img.save(dir.path().join(format!("photos/img-{k:02}.png")))
            .unwrap();
        truths.push(truth);
    }
    let cut = truths
        .iter()
        .filter(|t| t.iter().any(|c| c.is_none()))
        .count();
    assert!(cut >= 5, "only {cut} views leave the image");
    let board = "[target]\ntype = \"charuco\"\nrows = 7\ncols = 10\nsquare = 0.03\nmarker = 0.022\ndictionary = \"DICT_5X5_100\"\n";
    let camera_toml =
        format!("[[cameras]]\nname = \"cam0\"\nwidth = {W}\nheight = {H}\nmodel = \"radial3\"\n");
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!("{board}{camera_toml}[data]\nphotos = \"photos/img-*.png\"\n[calibration]\nmethod = \"standard\"\n[output]\ndir = \"out\"\n"),
    )
    .unwrap();
    let out = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.path().join("out/detections.csv")).unwrap();
    eprintln!("{cut} of the views leave the image; detections:\n{csv}");
    assert!(
        csv.lines().filter(|l| l.contains(",partial,")).count() >= 3,
        "partial views keep their ids: {csv}"
    );

    // The same corners at their true positions.
    let obs = std::fs::read_to_string(dir.path().join("out/observations.csv")).unwrap();
    let mut exact = String::from("camera,frame,corner,u,v\n");
    for line in obs.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (frame, corner): (usize, usize) = (f[1].parse().unwrap(), f[2].parse().unwrap());
        let t = truths[frame][corner].unwrap_or_else(|| {
            panic!(
                "view {frame}: corner {corner}, detected at ({}, {}), is out of view",
                f[3], f[4]
            )
        });
        exact.push_str(&format!("{},{frame},{corner},{},{}\n", f[0], t[0], t[1]));
    }
    std::fs::write(dir.path().join("exact.csv"), exact).unwrap();
    let config2 = dir.path().join("exact.toml");
    std::fs::write(
        &config2,
        format!("{board}{camera_toml}[data]\nobservations = \"exact.csv\"\n[calibration]\nmethod = \"standard\"\n[output]\ndir = \"exact\"\n"),
    )
    .unwrap();
    let out = deformcal(&["--config", config2.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (ours, std) = intrinsics(&dir.path().join("out/calibration.json"));
    let (exact, _) = intrinsics(&dir.path().join("exact/calibration.json"));
    let cam = camera();
    for (name, truth) in [
        ("fx", cam.fx),
        ("fy", cam.fy),
        ("cx", cam.cx),
        ("cy", cam.cy),
        ("k1", cam.k1),
    ] {
        let (a, b, sd) = (
            ours[name].as_f64().unwrap(),
            exact[name].as_f64().unwrap(),
            std[name].as_f64().unwrap(),
        );
        eprintln!("{name}: photos {a:.5} ± {sd:.5}, true corners {b:.5}, truth {truth}");
        assert!((a - b).abs() <= 3.0 * sd, "{name}: {a} vs {b} (σ {sd})");
        assert!(
            (b - truth).abs() <= 1e-3 * truth.abs().max(1.0),
            "{name}: exact {b} vs {truth}"
        );
    }
}
