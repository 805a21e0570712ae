//! The held-out stereo experiment of tests/real_stereo.rs and benches/stereo_photos.rs:
//! photos of a stereo pair (left*.jpg, right*.jpg) detected into a dataset, split
//! into halves of frame pairs by seeded shuffles, each method calibrated on one half
//! and judged on the other by `model::epipolar` (docs/real-photos.md), and the same
//! for OpenCV's stereoCalibrate on the same training corners.
use deformcal::app::config::Config;
use deformcal::model::epipolar::{stereo_errors, StereoErrors};
use deformcal::model::metrics::Stat;
use deformcal::model::selection::AutoSettings;
use deformcal::solver::calibrate::SharedWarmStart;
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::calibrate_auto_sharing;
use deformcal::{Dataset, Intrinsics, LensModel, Method, Pose, Request, Target};
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// The methods in table order; `auto` is `calibrate_auto` with the default settings.
pub const METHODS: [&str; 5] = ["standard", "static", "dynamic", "full", "auto"];

/// The lens models compared.
pub const MODELS: [LensModel; 2] = [LensModel::Radial3, LensModel::OpenCv5];

/// The photos `left*.jpg` and `right*.jpg` of `folder` (the wildcard is the frame)
/// detected into a stereo dataset; `work` receives detections.csv and the cache.
pub fn load(folder: &Path, target: Target, work: &Path) -> Result<Dataset, String> {
    let first = std::fs::read_dir(folder)
        .map_err(|e| format!("{}: {e}", folder.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("left"))
        })
        .min()
        .ok_or_else(|| format!("{}: no left*.jpg", folder.display()))?;
    let (w, h) =
        image::image_dimensions(&first).map_err(|e| format!("{}: {e}", first.display()))?;
    let camera = |name: &str| {
        format!("[[cameras]]\nname = \"{name}\"\nwidth = {w}\nheight = {h}\nmodel = \"radial3\"\n")
    };
    let text = format!(
        "[target]\nrows = {}\ncols = {}\nspacing = {}\n{}{}\
         [data]\nphotos = {{ left = \"left*.jpg\", right = \"right*.jpg\" }}\n\
         [output]\ndir = \"{}\"\n",
        target.rows,
        target.cols,
        target.spacing,
        camera("left"),
        camera("right"),
        work.display()
    );
    // The config's own folder anchors the patterns: the photos' folder.
    let config = Config::parse(&text, &folder.join("stereo.toml")).map_err(|e| e.to_string())?;
    let loaded = deformcal::app::source::load(&config).map_err(|e| e.to_string())?;
    Ok(loaded.dataset)
}

/// `count` seeded splits of frames `0..n` into (training, held-out) halves, the
/// training half the larger when `n` is odd (it gives `auto` more folds).
pub fn splits(n: usize, count: usize) -> Vec<(Vec<usize>, Vec<usize>)> {
    (0..count as u64)
        .map(|seed| {
            let mut frames: Vec<usize> = (0..n).collect();
            frames.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
            let (train, test) = frames.split_at(n.div_ceil(2));
            let (mut train, mut test) = (train.to_vec(), test.to_vec());
            train.sort_unstable();
            test.sort_unstable();
            (train, test)
        })
        .collect()
}

/// One calibration's figures on its held-out half.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub split: usize,
    pub model: LensModel,
    /// A name of [`METHODS`] or `opencv`.
    pub method: String,
    pub errors: StereoErrors,
    /// The method `auto` chose (the method itself otherwise).
    pub chosen: String,
}

/// `data` with every camera under lens model `model`.
fn with_model(data: &Dataset, model: LensModel) -> Dataset {
    let mut d = data.clone();
    for c in &mut d.cameras {
        c.model = model;
    }
    d
}

/// Every method of [`METHODS`] under every model of [`MODELS`] on every split.
/// Every method with the default settings (`auto` with its default folds).
pub fn run(data: &Dataset, splits: &[(Vec<usize>, Vec<usize>)]) -> Vec<Outcome> {
    let jobs: Vec<(usize, LensModel)> = (0..splits.len())
        .flat_map(|s| MODELS.map(|m| (s, m)))
        .collect();
    let mut out: Vec<Outcome> = jobs
        .par_iter()
        .flat_map_iter(|&(s, model)| {
            let (train, test) = &splits[s];
            let data = with_model(data, model);
            let (train, test) = (data.subset(train), data.subset(test));
            // The deformation methods start from the same `standard` solve.
            let warm = SharedWarmStart::default();
            METHODS
                .iter()
                .map(|&name| {
                    let c = calibrated(&train, name, &warm)
                        .unwrap_or_else(|e| panic!("split {s}, {model}, {name}: {e}"));
                    let errors = stereo_errors(&c.state.intrinsics, &c.state.camera_poses, &test)
                        .unwrap_or_else(|e| panic!("split {s}, {model}, {name}: {e}"));
                    Outcome {
                        split: s,
                        model,
                        method: name.to_string(),
                        errors,
                        chosen: c.method.to_string(),
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect();
    out.sort_by_key(|o| (o.split, o.model));
    out
}

fn calibrated(
    train: &Dataset,
    name: &str,
    warm: &SharedWarmStart,
) -> deformcal::Result<deformcal::Calibration> {
    // What a config that names only the method gets: the board priors estimated.
    let request = |method| Request {
        method,
        settings: SolverSettings::recommended(),
        gauge: None,
    };
    if name == "auto" {
        // The default folds, which a 7-pair training half turns into leave-one-out.
        let auto = AutoSettings::default();
        return calibrate_auto_sharing(train, &request(Method::Standard), &auto, warm, &|| {});
    }
    let method = Method::parse(name).expect("a method of METHODS");
    warm.calibrate(train, &request(method))
}

/// Debian's interpreter, where python3-opencv installs cv2.
pub const PYTHON: &str = "/usr/bin/python3";

/// Whether `/usr/bin/python3` can import cv2.
pub fn have_opencv() -> bool {
    std::process::Command::new(PYTHON)
        .args(["-c", "import cv2"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Per camera `cv2.calibrateCamera` (`radial3`: CALIB_ZERO_TANGENT_DIST; `opencv5`:
/// its default model) on every view of the training half, then `cv2.stereoCalibrate`
/// on the corners both cameras see: with CALIB_FIX_INTRINSIC (`opencv`, the textbook
/// stereo calibration) and from those intrinsics with CALIB_USE_INTRINSIC_GUESS
/// (`opencv-joint`: both lenses refined with the rig, as `standard` does), on
/// exactly our corners. Reads JSON on stdin, writes JSON.
const OPENCV_STEREO: &str = r#"
import json, sys
import cv2
import numpy as np

job = json.load(sys.stdin)
rows, cols, s = job["rows"], job["cols"], job["spacing"]
size = (job["width"], job["height"])
crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-15)

def board(i):
    r, c = divmod(i, cols)
    return ((c - (cols - 1) / 2) * s, (r - (rows - 1) / 2) * s, 0.0)

def arrays(views):
    obj = [np.array([board(i) for i, _ in v], np.float32) for v in views]
    img = [np.array([uv for _, uv in v], np.float32).reshape(-1, 1, 2) for v in views]
    return obj, img

out = []
for run in job["runs"]:
    flags = cv2.CALIB_ZERO_TANGENT_DIST if run["model"] == "radial3" else 0
    cams = []
    for views in run["views"]:
        obj, img = arrays(views)
        _, k, d, _, _ = cv2.calibrateCamera(obj, img, size, None, None, flags=flags, criteria=crit)
        cams.append((k, d))
    obj, left = arrays(run["left"])
    _, right = arrays(run["right"])
    both = []
    for joint in (False, True):
        f = (flags | cv2.CALIB_USE_INTRINSIC_GUESS) if joint else cv2.CALIB_FIX_INTRINSIC
        rms, k0, d0, k1, d1, r, t, _, _ = cv2.stereoCalibrate(
            obj, left, right, cams[0][0].copy(), cams[0][1].copy(), cams[1][0].copy(),
            cams[1][1].copy(), size, flags=f, criteria=crit)
        both.append({"k": [k0.tolist(), k1.tolist()],
                     "d": [d0.ravel().tolist(), d1.ravel().tolist()],
                     "r": r.tolist(), "t": t.ravel().tolist(), "rms": rms})
    out.append(both)
print(json.dumps(out))
"#;

/// Corners of one view as (corner, [u, v]), in corner order.
type View = Vec<(usize, [f64; 2])>;

fn views(d: &Dataset) -> Vec<BTreeMap<usize, View>> {
    let mut out: Vec<BTreeMap<usize, View>> = vec![BTreeMap::new(); d.cameras.len()];
    for o in &d.observations {
        out[o.camera]
            .entry(o.frame)
            .or_default()
            .push((o.corner, o.uv));
    }
    for v in out.iter_mut().flat_map(|c| c.values_mut()) {
        v.sort_by_key(|c| c.0);
    }
    out
}

/// OpenCV's stereo calibration (see [`OPENCV_STEREO`]) of every split's training
/// half under every model of [`MODELS`], judged on the held-out half.
pub fn run_opencv(data: &Dataset, splits: &[(Vec<usize>, Vec<usize>)]) -> Vec<Outcome> {
    // The fewest corners `calibrateCamera` needs in a view of a planar board.
    const MIN_CORNERS: usize = 6;
    let mut runs = Vec::new();
    let mut keys = Vec::new();
    for (s, (train, _)) in splits.iter().enumerate() {
        let v = views(&data.subset(train));
        let per_camera: Vec<Vec<&View>> = v
            .iter()
            .map(|c| c.values().filter(|v| v.len() >= MIN_CORNERS).collect())
            .collect();
        let (mut left, mut right) = (Vec::new(), Vec::new());
        for (frame, l) in &v[0] {
            let Some(r) = v[1].get(frame) else { continue };
            let common: Vec<usize> = l
                .iter()
                .map(|c| c.0)
                .filter(|i| r.iter().any(|c| c.0 == *i))
                .collect();
            if common.len() < MIN_CORNERS {
                continue;
            }
            let pick = |v: &View| -> View {
                v.iter()
                    .filter(|c| common.contains(&c.0))
                    .copied()
                    .collect()
            };
            left.push(pick(l));
            right.push(pick(r));
        }
        for model in MODELS {
            runs.push(serde_json::json!({
                "model": model.name(), "views": per_camera, "left": left, "right": right,
            }));
            keys.push((s, model));
        }
    }
    let cam = &data.cameras[0];
    let job = serde_json::json!({
        "rows": data.target.rows, "cols": data.target.cols, "spacing": data.target.spacing,
        "width": cam.width, "height": cam.height, "runs": runs,
    });
    let result = python(OPENCV_STEREO, &job.to_string());
    let mut out = Vec::new();
    for (&(s, model), both) in keys.iter().zip(result.as_array().expect("a list")) {
        for (method, r) in ["opencv", "opencv-joint"]
            .into_iter()
            .zip(both.as_array().expect("two"))
        {
            let f = |v: &serde_json::Value| v.as_f64().expect("a number");
            let intrinsics: Vec<Intrinsics> = (0..2)
                .map(|k| {
                    let m = |i: usize, j: usize| f(&r["k"][k][i][j]);
                    let d: Vec<f64> = r["d"][k].as_array().unwrap().iter().map(f).collect();
                    let p: Vec<f64> = match model {
                        LensModel::Radial3 => {
                            vec![m(0, 0), m(1, 1), m(0, 2), m(1, 2), d[0], d[1], d[4]]
                        }
                        _ => vec![
                            m(0, 0),
                            m(1, 1),
                            m(0, 2),
                            m(1, 2),
                            d[0],
                            d[1],
                            d[2],
                            d[3],
                            d[4],
                        ],
                    };
                    Intrinsics::from_params(model, &p).expect("the model's parameters")
                })
                .collect();
            let rot = Matrix3::from_fn(|i, j| f(&r["r"][i][j]));
            let t = Vector3::from_fn(|i, _| f(&r["t"][i]));
            let right_from_left = Pose::from_parts(&Rotation3::from_matrix_unchecked(rot), &t);
            let test = data.subset(&splits[s].1);
            let errors = stereo_errors(&intrinsics, &[Pose::identity(), right_from_left], &test)
                .unwrap_or_else(|e| panic!("split {s}, {model}, {method}: {e}"));
            out.push(Outcome {
                split: s,
                model,
                method: method.into(),
                errors,
                chosen: method.into(),
            });
        }
    }
    out
}

/// Runs a Python script with `stdin` and parses its JSON output.
fn python(script: &str, stdin: &str) -> serde_json::Value {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let mut child = Command::new(PYTHON)
        .args(["-c", script])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("run {PYTHON}: {e}"));
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "OpenCV's stereo calibration failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The figures of one method × model over the splits.
#[derive(Debug, Clone)]
pub struct Row {
    pub method: String,
    pub model: LensModel,
    pub epipolar: Stat,
    pub triangulation: Stat,
    /// Splits where the method's figure is lower than `standard`'s.
    pub epipolar_wins: usize,
    pub triangulation_wins: usize,
    /// The per-split difference from `standard` (method − standard).
    pub epipolar_vs_standard: Stat,
    pub triangulation_vs_standard: Stat,
    /// How often `auto` chose each method.
    pub chosen: BTreeMap<String, usize>,
}

/// The table of [`run`]'s (and [`run_opencv`]'s) outcomes, one row per method × model.
pub fn rows(outcomes: &[Outcome]) -> Vec<Row> {
    let mut out = Vec::new();
    for model in MODELS {
        let of = |method: &str| -> BTreeMap<usize, &Outcome> {
            outcomes
                .iter()
                .filter(|o| o.model == model && o.method == method)
                .map(|o| (o.split, o))
                .collect()
        };
        let standard = of("standard");
        for method in METHODS.iter().copied().chain(["opencv", "opencv-joint"]) {
            let mine = of(method);
            if mine.is_empty() {
                continue;
            }
            let pick = |f: fn(&StereoErrors) -> f64| -> (Stat, usize, Stat) {
                let values = mine.values().map(|o| f(&o.errors));
                let diffs: Vec<f64> = mine
                    .iter()
                    .map(|(s, o)| f(&o.errors) - f(&standard[s].errors))
                    .collect();
                (
                    Stat::of(values).expect("finite figures"),
                    diffs.iter().filter(|d| **d < 0.0).count(),
                    Stat::of(diffs).expect("finite figures"),
                )
            };
            let (epipolar, epipolar_wins, epipolar_vs_standard) = pick(|e| e.epipolar_mean_px);
            let (triangulation, triangulation_wins, triangulation_vs_standard) =
                pick(|e| e.triangulation_rms_mm);
            let mut chosen = BTreeMap::new();
            for o in mine.values() {
                *chosen.entry(o.chosen.clone()).or_insert(0) += 1;
            }
            out.push(Row {
                method: method.to_string(),
                model,
                epipolar,
                triangulation,
                epipolar_wins,
                triangulation_wins,
                epipolar_vs_standard,
                triangulation_vs_standard,
                chosen,
            });
        }
    }
    out
}

/// The table as Markdown.
pub fn table(rows: &[Row], splits: usize) -> String {
    let mut s = String::from(
        "| method | model | epipolar px (mean ± std over splits) | triangulation mm | \
         − standard, per split: epipolar px | triangulation mm | \
         wins vs standard: epipolar | triangulation | auto chose |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let chosen = if r.method == "auto" {
            r.chosen
                .iter()
                .map(|(m, n)| format!("{m} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        } else {
            String::new()
        };
        s += &format!(
            "| {} | {} | {:.4} ± {:.4} | {:.3} ± {:.3} | {:+.4} ± {:.4} | {:+.3} ± {:.3} | \
             {}/{splits} | {}/{splits} | {chosen} |\n",
            r.method,
            r.model,
            r.epipolar.mean,
            r.epipolar.std,
            r.triangulation.mean,
            r.triangulation.std,
            r.epipolar_vs_standard.mean,
            r.epipolar_vs_standard.std,
            r.triangulation_vs_standard.mean,
            r.triangulation_vs_standard.std,
            r.epipolar_wins,
            r.triangulation_wins,
        );
    }
    s
}
