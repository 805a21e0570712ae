//! Fisheye photos to the rim of the image circle, rendered by the project's own
//! renderer with the exact truth: a `kb4` lens seeing a 180°-symmetric 8×6 board
//! (9×7 squares: turned by 180° it looks the same) and a `ds` lens seeing a 9×6
//! board, both with a 190° image circle cut by the sensor, boards tilted up to
//! 70° and reaching into the circle's rim, blur, noise and vignetting.
//!
//! On each set: boards found against OpenCV's findChessboardCorners on the same
//! images, corners found against those whose four squares are wholly in the
//! picture (overall and in the rim ring beyond 75° off the axis), the corners'
//! RMS error to the truth, and `standard`'s mapping error to the true lens over
//! the image circle.
use crate::common;

use deformcal::app::detect::render::{fully_visible, render_board, Pose, Scene};
use deformcal::app::detect::{detect_image, Detection};
use deformcal::model::metrics::{grid_rays, mapping_error_rot_of};
use deformcal::model::selection::AutoSettings;
use deformcal::solver::problem::{Loss, SolverSettings};
use deformcal::solver::select::calibrate_auto;
use deformcal::{CameraSpec, Dataset, Intrinsics, LensModel, Method, Request, Target};
use nalgebra::{Rotation3, Unit, Vector3};
use std::path::{Path, PathBuf};
use std::process::Command;

const W: u32 = 1032;
const H: u32 = 778;
/// The lenses' field of view: the image circle's diameter in degrees.
const CIRCLE_DEG: f64 = 190.0;
/// Corners further off the axis than this are the rim ring.
const RIM_DEG: f64 = 75.0;
const SPACING: f64 = 0.035;

/// An equidistant-like `kb4` lens whose 190° circle is 1008 px wide.
fn kb4() -> Intrinsics {
    Intrinsics::from_params(
        LensModel::Kb4,
        &[300.0, 300.0, 515.3, 388.8, 0.02, -0.01, 0.003, -0.0005],
    )
    .unwrap()
}

/// A `ds` lens with about the same circle.
fn ds() -> Intrinsics {
    Intrinsics::from_params(
        LensModel::DoubleSphere,
        &[255.0, 255.0, 516.2, 389.1, -0.2, 0.6],
    )
    .unwrap()
}

/// View `k` of a set: the board's centre `theta` off the axis at azimuth `phi`
/// and `dist` m away, its normal tilted by `tilt` from the line of sight about an
/// axis at `tilt_dir`, turned by `spin` in its plane (angles in degrees).
struct View {
    theta: f64,
    phi: f64,
    dist: f64,
    tilt: f64,
    tilt_dir: f64,
    spin: f64,
}

/// Twelve views: four near the axis, eight reaching into the rim, tilts to 70°.
fn views() -> Vec<View> {
    #[rustfmt::skip]
    let v = [
        (10.0, 0.0, 0.30, 20.0, 30.0, 5.0),
        (35.0, 200.0, 0.32, 45.0, 100.0, -10.0),
        (45.0, 60.0, 0.28, 60.0, 10.0, 20.0),
        (55.0, 330.0, 0.30, 70.0, 80.0, 0.0),
        (68.0, 180.0, 0.30, 35.0, 90.0, 8.0),
        (70.0, 0.0, 0.28, 50.0, 0.0, -15.0),
        (72.0, 160.0, 0.35, 65.0, 45.0, 30.0),
        (74.0, 15.0, 0.33, 20.0, 120.0, 90.0),
        (62.0, 100.0, 0.26, 55.0, 170.0, 0.0),
        (66.0, 270.0, 0.27, 40.0, 20.0, -5.0),
        (76.0, 195.0, 0.36, 30.0, 60.0, 175.0),
        (50.0, 135.0, 0.25, 70.0, 135.0, 45.0),
    ];
    v.iter()
        .map(|&(theta, phi, dist, tilt, tilt_dir, spin)| View {
            theta,
            phi,
            dist,
            tilt,
            tilt_dir,
            spin,
        })
        .collect()
}

fn scene(lens: Intrinsics, rows: usize, cols: usize, k: usize, v: &View) -> Scene {
    let rad = f64::to_radians;
    let (th, ph) = (rad(v.theta), rad(v.phi));
    let dir = Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
    // Board +z (away from its printed side) along the line of sight, then tilted
    // and spun.
    let face = Rotation3::rotation_between(&Vector3::z(), &dir).unwrap();
    let axis = Unit::new_normalize(Vector3::new(
        rad(v.tilt_dir).cos(),
        rad(v.tilt_dir).sin(),
        0.0,
    ));
    let tilt = Rotation3::from_axis_angle(&axis, rad(v.tilt));
    let spin = Rotation3::from_axis_angle(&Vector3::z_axis(), rad(v.spin));
    let rot = face * tilt * spin;
    let half = Vector3::new(
        (cols - 1) as f64 * SPACING / 2.0,
        (rows - 1) as f64 * SPACING / 2.0,
        0.0,
    );
    let t = dir * v.dist - rot * half;
    Scene {
        camera: lens,
        image_circle_deg: CIRCLE_DEG,
        vignetting: 0.45,
        pose: Pose {
            rvec: rot.scaled_axis().into(),
            t: t.into(),
        },
        bend: 0.0,
        rows,
        cols,
        spacing: SPACING,
        width: W,
        height: H,
        blur: 0.8 + 0.1 * (k % 4) as f64,
        noise: 1.5 + 0.5 * (k % 3) as f64,
        seed: 40 + k as u64,
        // 16 × 16 samples per pixel on edges: with 4 × 4 the renderer's own
        // aliasing moved the junctions by about 0.04 px (measured on noise-free
        // views: 0.081 px RMS at 4, 0.054 at 8, 0.050 at 16), as much as the
        // detector's error; a camera's pixel integrates the light exactly.
        supersample: 16,
    }
}

/// What one set's detection gave against the truth.
#[derive(Default, Debug)]
struct Tally {
    boards: usize,
    visible: usize,
    found: usize,
    rim_visible: usize,
    rim_found: usize,
    /// Found corners more than 1 px from the truth of their index (under the
    /// board's symmetries): wrongly indexed.
    misplaced: usize,
    squared_error: f64,
    matched: usize,
}

/// The angle (degrees) off the axis of the ray the true lens sees at `uv`.
fn off_axis_deg(lens: &Intrinsics, uv: [f64; 2]) -> f64 {
    let ray = lens
        .unproject(&nalgebra::Vector2::new(uv[0], uv[1]))
        .unwrap();
    ray.x.hypot(ray.y).atan2(ray.z).to_degrees()
}

/// Board index maps under which the coloured board looks the same.
fn symmetric_index(rows: usize, cols: usize, flip: bool, index: usize) -> usize {
    if flip {
        rows * cols - 1 - index
    } else {
        index
    }
}

/// Count one view's detection against its truth; returns the detection with
/// every corner moved onto its truth (what a perfect detector of the same
/// corners would give).
fn tally_view(
    t: &mut Tally,
    lens: &Intrinsics,
    sc: &Scene,
    truth: &[Option<[f64; 2]>],
    det: Option<&Detection>,
) -> Option<Detection> {
    let visible = fully_visible(sc);
    let rim: Vec<bool> = truth
        .iter()
        .map(|u| u.is_some_and(|uv| off_axis_deg(lens, uv) >= RIM_DEG))
        .collect();
    t.visible += visible.iter().filter(|v| **v).count();
    t.rim_visible += visible.iter().zip(&rim).filter(|(v, r)| **v && **r).count();
    let det = det?;
    t.boards += 1;
    // The labelling that puts the most corners on their truth (a 180°-symmetric
    // board may be labelled either way).
    let symmetric = (sc.rows + sc.cols).is_multiple_of(2);
    let flips: &[bool] = if symmetric { &[false, true] } else { &[false] };
    let errors = |flip: bool| -> Vec<(usize, f64)> {
        det.corners
            .iter()
            .map(|c| {
                let i = symmetric_index(sc.rows, sc.cols, flip, c.index);
                let e = truth[i].map_or(f64::INFINITY, |u| (u[0] - c.uv[0]).hypot(u[1] - c.uv[1]));
                (i, e)
            })
            .collect()
    };
    let best = flips
        .iter()
        .map(|&f| errors(f))
        .max_by_key(|e| e.iter().filter(|(_, e)| *e <= 1.0).count())
        .unwrap();
    let mut ideal = det.clone();
    for (c, (i, _)) in ideal.corners.iter_mut().zip(&best) {
        c.uv = truth[*i].unwrap_or(c.uv);
    }
    for (i, e) in best {
        if e > 1.0 {
            t.misplaced += 1;
            continue;
        }
        t.squared_error += e * e;
        t.matched += 1;
        if visible[i] {
            t.found += 1;
            t.rim_found += rim[i] as usize;
        }
    }
    Some(ideal)
}

/// One set's detections: per view as found, and moved onto the truth.
struct SetRun {
    tally: Tally,
    dets: Vec<Option<Detection>>,
    ideal: Vec<Option<Detection>>,
    files: Vec<PathBuf>,
}

/// Render, save and detect a set.
fn run_set(dir: &Path, lens: Intrinsics, rows: usize, cols: usize) -> SetRun {
    let mut tally = Tally::default();
    let (mut dets, mut ideal, mut files) = (Vec::new(), Vec::new(), Vec::new());
    for (k, v) in views().iter().enumerate() {
        let sc = scene(lens, rows, cols, k, v);
        let (img, truth) = render_board(&sc);
        let path = dir.join(format!("view-{k:02}.png"));
        img.save(&path).unwrap();
        let det = detect_image(&image::DynamicImage::ImageLuma8(img), rows, cols);
        let before = (tally.found, tally.visible);
        ideal.push(tally_view(
            &mut tally,
            &lens,
            &sc,
            &truth,
            det.as_ref().ok(),
        ));
        eprintln!(
            "view {k:2}: {:?}, corners {} of {} fully visible",
            det.as_ref()
                .map(|d| d.corners.len())
                .map_err(|e| e.to_string()),
            tally.found - before.0,
            tally.visible - before.1
        );
        dets.push(det.ok());
        files.push(path);
    }
    SetRun {
        tally,
        dets,
        ideal,
        files,
    }
}

/// How many of `images` OpenCV's findChessboardCorners finds a rows×cols board in
/// (the classic detector with its usual flags); None without cv2.
fn opencv_boards(images: &[PathBuf], rows: usize, cols: usize) -> Option<usize> {
    if !common::python_has(&["cv2"]) {
        return None;
    }
    let script = "import sys, cv2\n\
        r, c = int(sys.argv[1]), int(sys.argv[2])\n\
        f = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE\n\
        print(sum(cv2.findChessboardCorners(cv2.imread(p, 0), (c, r), f)[0] for p in sys.argv[3:]))\n";
    let out = Command::new(common::PYTHON)
        .args(["-c", script, &rows.to_string(), &cols.to_string()])
        .args(images)
        .output()
        .ok()?;
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().parse().ok()
}

/// The detections of the first `views` views as a dataset.
fn dataset(lens: &Intrinsics, rows: usize, cols: usize, dets: &[Option<Detection>]) -> Dataset {
    let keyed = dets.iter().enumerate().flat_map(|(k, d)| {
        d.iter()
            .flat_map(move |d| d.corners.iter().map(move |c| (0, k as i64, c.index, c.uv)))
    });
    let target = Target {
        rows,
        cols,
        spacing: SPACING,
    };
    Dataset::from_keyed(
        target,
        vec![CameraSpec::new("cam0", W, H, lens.model())],
        keyed,
    )
}

/// The rotation-compensated mapping error (px) of `fit` to the true lens over
/// the image circle.
fn mapping_error(lens: &Intrinsics, fit: &Intrinsics) -> f64 {
    let rays: Vec<_> = grid_rays(lens, W, H)
        .into_iter()
        .filter(|(_, r)| r.x.hypot(r.y).atan2(r.z).to_degrees() <= CIRCLE_DEG / 2.0)
        .collect();
    mapping_error_rot_of(&rays, fit)
}

/// `standard`'s mapping error from the detections.
fn standard_error(lens: Intrinsics, rows: usize, cols: usize, dets: &[Option<Detection>]) -> f64 {
    let c = common::run(
        &dataset(&lens, rows, cols, dets),
        Method::Standard,
        Loss::None,
    );
    mapping_error(&lens, &c.state.intrinsics[0])
}

/// `standard`'s mean mapping error (4 draws) from the corners on their truth plus
/// independent Gaussian noise of RMS `rms` px: what a detector with errors of
/// the same size but unbiased and uncorrelated would give.
fn noisy_error(
    lens: Intrinsics,
    rows: usize,
    cols: usize,
    ideal: &[Option<Detection>],
    rms: f64,
) -> f64 {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let normal = Normal::new(0.0, rms / 2f64.sqrt()).unwrap();
    let draws: Vec<f64> = (0..4)
        .map(|seed| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let noisy: Vec<Option<Detection>> = ideal
                .iter()
                .map(|d| {
                    d.clone().map(|mut d| {
                        for c in &mut d.corners {
                            c.uv[0] += normal.sample(&mut rng);
                            c.uv[1] += normal.sample(&mut rng);
                        }
                        d
                    })
                })
                .collect();
            standard_error(lens, rows, cols, &noisy)
        })
        .collect();
    draws.iter().sum::<f64>() / draws.len() as f64
}

/// `auto` on the first 6, 8 and 12 views: it answers, and its choice maps no
/// worse than 1.5 × `standard`'s error plus 0.02 px (the board is rigid, so
/// `standard` is the right model and anything richer only adds variance).
fn auto_on_small_captures(
    name: &str,
    lens: Intrinsics,
    rows: usize,
    cols: usize,
    dets: &[Option<Detection>],
) {
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings::recommended(),
        gauge: None,
    };
    for n in [6, 8, 12] {
        let d = dataset(&lens, rows, cols, &dets[..n]);
        let c = calibrate_auto(&d, &request, &AutoSettings::default(), &|| {})
            .unwrap_or_else(|e| panic!("{name}, {n} photos: auto failed: {e}"));
        let standard = common::run_with(&d, Method::Standard, SolverSettings::recommended());
        let (e, es) = (
            mapping_error(&lens, &c.state.intrinsics[0]),
            mapping_error(&lens, &standard.state.intrinsics[0]),
        );
        let sel = c.selection.clone().unwrap();
        eprintln!(
            "{name}, {n} photos: auto chose {} ({e:.4} px; standard {es:.4} px), {} folds: {}",
            c.method, sel.folds, sel.reason
        );
        assert!(
            e <= 1.5 * es + 0.02,
            "{name}, {n} photos: auto {e} px, standard {es} px"
        );
    }
}

/// Run one set and hold it to the targets.
fn check_set(name: &str, lens: Intrinsics, rows: usize, cols: usize) {
    let dir = tempfile::tempdir().unwrap();
    let SetRun {
        tally: t,
        dets,
        ideal,
        files,
    } = run_set(dir.path(), lens, rows, cols);
    let rms = (t.squared_error / t.matched.max(1) as f64).sqrt();
    let share = t.found as f64 / t.visible as f64;
    let rim_share = t.rim_found as f64 / t.rim_visible.max(1) as f64;
    let opencv = opencv_boards(&files, rows, cols);
    let map = standard_error(lens, rows, cols, &dets);
    let map_ideal = standard_error(lens, rows, cols, &ideal);
    let rim_free: Vec<Option<Detection>> = dets
        .iter()
        .map(|d| {
            d.clone().map(|mut d| {
                d.corners.retain(|c| off_axis_deg(&lens, c.uv) < RIM_DEG);
                d
            })
        })
        .collect();
    let map_rim_free = standard_error(lens, rows, cols, &rim_free);
    let map_noise = noisy_error(lens, rows, cols, &ideal, rms);
    eprintln!(
        "{name}: mapping error {map:.4} px; the same corners on their truth {map_ideal:.4} px, \
         plus independent noise of the detector's RMS {map_noise:.4} px (mean of 4); without the \
         rim ring {map_rim_free:.4} px"
    );
    auto_on_small_captures(name, lens, rows, cols, &dets);
    eprintln!(
        "{name} {rows}x{cols}: boards {} of {} (OpenCV {opencv:?}); corners {} of {} fully visible \
         ({:.1} %), rim ring {} of {} ({:.1} %); {} misplaced; RMS to truth {rms:.4} px; \
         standard's mapping error {map:.4} px",
        t.boards,
        dets.len(),
        t.found,
        t.visible,
        100.0 * share,
        t.rim_found,
        t.rim_visible,
        100.0 * rim_share,
        t.misplaced,
    );
    assert_eq!(t.misplaced, 0, "{name}: corners with a wrong index");
    if let Some(n) = opencv {
        assert!(t.boards >= n, "{name}: {} boards, OpenCV {n}", t.boards);
    }
    assert_eq!(t.boards, dets.len(), "{name}: every view has a board");
    // The targets: 98 % of the corners, the rim ring with them, 0.06 px RMS.
    // Measured 100 % of both sets and of both rim rings, RMS 0.050 (kb4) and
    // 0.053 px (ds), mapping errors 0.040 and 0.045 px. With square windows on
    // the grown corners the detector found 98.4 % and 96.2 % (rim 92.8 % and
    // 81.7 %); before the grid growth 59.5 % and 81.2 %, and 7 and 11 boards.
    assert!(
        share >= 0.98,
        "{name}: {:.1} % of the corners",
        100.0 * share
    );
    assert!(t.rim_visible >= 40, "{name}: the set reaches the rim");
    assert!(
        rim_share >= 0.98,
        "{name}: {:.1} % of the rim ring",
        100.0 * rim_share
    );
    assert!(rms <= 0.06, "{name}: RMS {rms} px");
    assert!(map <= 0.05, "{name}: mapping error {map} px");
}

#[test]
fn kb4_photos_to_the_rim_with_a_symmetric_board() {
    check_set("kb4", kb4(), 6, 8);
}

#[test]
fn ds_photos_to_the_rim() {
    check_set("ds", ds(), 6, 9);
}
