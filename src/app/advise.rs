//! `deformcal advise`: where to hold the board next. From a calibration (its
//! intrinsics, noise and the views it was made of) this predicts, for candidate
//! board poses over image positions, distances and tilts, the expected mapping
//! error (docs/conventions.md §3a) after adding that view, and picks the three
//! that lower it most (greedily: the second given the first). The picture shows
//! the projection uncertainty over the image with each advised board's outline.
//!
//! The prediction is linear: a view adds its Fisher information on the free
//! intrinsics, its own pose eliminated (Schur complement), at unit noise, to the
//! information of the views so far; the board is taken rigid (its bend and the
//! static correction are not modelled), as in the `standard` method.
//! Computing a calibration is the solver's; this module only reads one.

use crate::app::calibration_json::CalibrationJson;
use crate::error::{Error, Result};
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::lens::{PixelDerivatives, MAX_PARAMS};
use crate::model::pose::Pose;
use crate::model::target::Target;
use crate::model::uncertainty::{mapping_forms, projection_uncertainty_map, UncertaintyMap};
use nalgebra::{DMatrix, Rotation3, Vector2, Vector3};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Least share of the board's corners a candidate must show (partial views count).
const MIN_VISIBLE: f64 = 0.5;

/// `deformcal advise`'s arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct Args {
    /// The calibration to improve.
    #[arg(long)]
    pub calibration: PathBuf,
    /// The config it was made with (its board and its observations).
    #[arg(long)]
    pub config: PathBuf,
    /// The camera to advise on (default: the first).
    #[arg(long)]
    pub camera: Option<String>,
    /// Where to write the picture (SVG).
    #[arg(long, default_value = "advice.svg")]
    pub out: PathBuf,
}

/// What a camera's calibration knows, in the terms the prediction needs.
#[derive(Clone, Debug)]
pub struct Knowledge {
    pub intrinsics: Intrinsics,
    pub width: u32,
    pub height: u32,
    /// Per lens parameter: estimated (true) or held.
    pub free: Vec<bool>,
    pub target: Target,
    /// σ̂, px per coordinate.
    pub noise_px: f64,
    /// Information on the free intrinsics at unit noise (free × free).
    pub information: DMatrix<f64>,
}

/// One advised board pose.
#[derive(Clone, Debug, PartialEq)]
pub struct Advised {
    pub camera_from_board: Pose,
    /// The board's outer corners (of its corner grid) in the image, px.
    pub outline: [[f64; 2]; 4],
    /// Corners of the board inside the image.
    pub corners_in_view: usize,
    /// Expected mapping error after adding this view and the ones before it, px.
    pub predicted_error_px: f64,
}

/// The advice: the uncertainty now and the poses to add.
#[derive(Clone, Debug)]
pub struct Advice {
    pub current_error_px: f64,
    pub map: UncertaintyMap,
    pub poses: Vec<Advised>,
}

impl std::fmt::Display for Advice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "expected mapping error now {:.3} px",
            self.current_error_px
        )?;
        for (i, p) in self.poses.iter().enumerate() {
            let c = p
                .outline
                .iter()
                .fold([0.0, 0.0], |a, q| [a[0] + q[0] / 4.0, a[1] + q[1] / 4.0]);
            let t = p.camera_from_board.translation;
            let tilt = nalgebra::Vector3::from(p.camera_from_board.rotation)
                .norm()
                .to_degrees();
            write!(
                f,
                "\n{}. board centred at pixel ({:.0}, {:.0}), {:.2} m away, tilted {:.0}°, {} corners in view: {:.3} px after adding it",
                i + 1,
                c[0],
                c[1],
                (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt(),
                tilt,
                p.corners_in_view,
                p.predicted_error_px
            )?;
        }
        Ok(())
    }
}

fn free_indices(free: &[bool]) -> Vec<usize> {
    (0..free.len()).filter(|&i| free[i]).collect()
}

/// Fisher information on the free intrinsics (unit noise) of one view of
/// `corners`, the view's six pose parameters eliminated; `None` if no corner
/// projects.
pub fn view_information(
    k: &Intrinsics,
    free: &[bool],
    target: &Target,
    camera_from_board: &Pose,
    corners: &[usize],
) -> Option<DMatrix<f64>> {
    information_where(k, free, target, camera_from_board, corners, |_, _| true).1
}

/// A candidate pose's corners inside the image and their information
/// ([`view_information`] of the corners in front of the camera whose pixel lies
/// inside the image, each corner projected once).
fn candidate_information(kn: &Knowledge, pose: &Pose) -> (usize, Option<DMatrix<f64>>) {
    let (w, h) = (kn.width as f64, kn.height as f64);
    let all: Vec<usize> = (0..kn.target.num_corners()).collect();
    information_where(
        &kn.intrinsics,
        &kn.free,
        &kn.target,
        pose,
        &all,
        |xc, uv| xc.z > 0.0 && uv.x >= 0.0 && uv.y >= 0.0 && uv.x <= w - 1.0 && uv.y <= h - 1.0,
    )
}

/// The number of `corners` that project and that `keep` (camera-frame point,
/// pixel) accepts, and their information as [`view_information`] has it.
fn information_where(
    k: &Intrinsics,
    free: &[bool],
    target: &Target,
    camera_from_board: &Pose,
    corners: &[usize],
    keep: impl Fn(&Vector3<f64>, &Vector2<f64>) -> bool,
) -> (usize, Option<DMatrix<f64>>) {
    let idx = free_indices(free);
    let mut sum = NormalSum::new(idx.len(), corners.len());
    // `Pose::transform`'s arithmetic, its rotation made once per view.
    let (r, t) = (
        camera_from_board.rotation_matrix(),
        camera_from_board.translation_vector(),
    );
    for &c in corners {
        let xc = r * target.nominal(c) + t;
        if let Some(d) = k.project_with_derivatives(&xc) {
            if keep(&xc, &d.uv) {
                sum.add(&idx, &xc, &d);
            }
        }
    }
    (sum.used, sum.eliminate_pose())
}

/// Σ JᵀJ over a view's corners, J = 2 × (free + 6) per corner as
/// [`view_jacobian`] has it. The rows are kept (Jᵀ, column by column) and
/// multiplied once: a blocked matrix product sums the report's 200 candidate
/// views of up to a whole board each in a fraction of the time of a rank-2
/// update per corner.
struct NormalSum {
    m: usize,
    jt: Vec<f64>,
    used: usize,
}

impl NormalSum {
    /// For a view of at most `corners` corners.
    fn new(free: usize, corners: usize) -> Self {
        let m = free + 6;
        NormalSum {
            m,
            jt: Vec::with_capacity(2 * corners * m),
            used: 0,
        }
    }

    fn add(&mut self, idx: &[usize], xc: &Vector3<f64>, d: &PixelDerivatives) {
        let [r0, r1] = view_jacobian(idx, xc, d);
        self.jt.extend_from_slice(&r0[..self.m]);
        self.jt.extend_from_slice(&r1[..self.m]);
        self.used += 1;
    }

    /// The Schur complement on the intrinsics; `None` without a corner or for
    /// a singular pose block.
    fn eliminate_pose(&self) -> Option<DMatrix<f64>> {
        if self.used == 0 {
            return None;
        }
        let (m, n) = (self.m, self.m - 6);
        let jt = DMatrix::from_column_slice(m, 2 * self.used, &self.jt);
        let mut a = &jt * jt.transpose();
        // Symmetric to the bit, as the inverse below expects.
        a.fill_upper_triangle_with_lower_triangle();
        let aa = a.view((0, 0), (n, n)).into_owned();
        let ab = a.view((0, n), (n, 6)).into_owned();
        let bb = a.view((n, n), (6, 6)).into_owned();
        let bb_inv = bb.try_inverse()?;
        Some(&aa - &ab * bb_inv * ab.transpose())
    }
}

/// The 2 × (free + 6) Jacobian of a corner's projection: the free intrinsics,
/// then a small rotation and translation of the point in the camera frame (any
/// full parameterisation of the pose gives the same Schur complement). All in
/// closed form: the translation's columns are ∂uv/∂x_c, the rotation's follow
/// from them by the chain rule: ∂uv/∂ω_a = ∂uv/∂x_c (e_a × x_c).
fn view_jacobian(
    idx: &[usize],
    xc: &Vector3<f64>,
    d: &PixelDerivatives,
) -> [[f64; MAX_PARAMS + 6]; 2] {
    let mut rows = [[0.0; MAX_PARAMS + 6]; 2];
    let n = idx.len();
    for (col, &i) in idx.iter().enumerate() {
        rows[0][col] = d.d_params[0][i];
        rows[1][col] = d.d_params[1][i];
    }
    for a in 0..3 {
        let column = d.d_point.column(a);
        rows[0][n + 3 + a] = column.x;
        rows[1][n + 3 + a] = column.y;
        let w = Vector3::ith(a, 1.0).cross(xc);
        let column = d.d_point * w;
        rows[0][n + a] = column.x;
        rows[1][n + a] = column.y;
    }
    rows
}

/// The expected mapping error (px) at noise σ̂ for information `info` (free × free).
pub fn expected_error(kn: &Knowledge, info: &DMatrix<f64>) -> Option<f64> {
    let (h, _, m) = mapping_forms(&kn.intrinsics, kn.width, kn.height)?;
    error_with(kn, &h, m, info)
}

/// [`expected_error`] with the mapping-error form H over M grid points given:
/// the advice asks this of every candidate, in several rounds.
fn error_with(kn: &Knowledge, h: &DMatrix<f64>, m: usize, info: &DMatrix<f64>) -> Option<f64> {
    let sigma = full_covariance(kn, info)?;
    Some(kn.noise_px * ((h * sigma).trace().max(0.0) / m as f64).sqrt())
}

/// Σ_θ at unit noise over all lens parameters (held rows and columns zero).
fn full_covariance(kn: &Knowledge, info: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let inv = info.clone().cholesky()?.inverse();
    let idx = free_indices(&kn.free);
    let n = kn.free.len();
    let mut sigma = DMatrix::zeros(n, n);
    for (a, &i) in idx.iter().enumerate() {
        for (b, &j) in idx.iter().enumerate() {
            sigma[(i, j)] = inv[(a, b)];
        }
    }
    Some(sigma)
}

/// The candidate poses: the board's centre on a 5 × 4 grid of image positions,
/// at two distances (the board a third and a half of the image wide), facing
/// the camera or tilted by 35° about either of its axes either way.
pub fn candidates(kn: &Knowledge) -> Vec<Pose> {
    let k = &kn.intrinsics;
    let t = &kn.target;
    let board_w = (t.cols.max(t.rows) - 1) as f64 * t.spacing;
    let focal = k.params()[0];
    let tilt = 35f64.to_radians();
    let tilts = [
        (0.0, 0.0),
        (tilt, 0.0),
        (-tilt, 0.0),
        (0.0, tilt),
        (0.0, -tilt),
    ];
    let mut out = Vec::new();
    for gy in 0..4 {
        for gx in 0..5 {
            let px = Vector2::new(
                (0.1 + 0.2 * gx as f64) * kn.width as f64,
                (0.125 + 0.25 * gy as f64) * kn.height as f64,
            );
            let Some(ray) = k.unproject(&px) else {
                continue;
            };
            if ray.z <= 1e-6 {
                continue;
            }
            for share in [0.33, 0.5] {
                let dist = board_w * focal / (share * kn.width as f64);
                let centre = ray * (dist / ray.z);
                for (ax, ay) in tilts {
                    let r = Rotation3::from_euler_angles(ax, ay, 0.0);
                    out.push(Pose::from_parts(&r, &centre));
                }
            }
        }
    }
    out
}

/// A candidate pose's corners in view and their information:
/// [`candidate_information`], or in the tests the central-difference
/// reference it must reproduce.
type CandidateInformation = fn(&Knowledge, &Pose) -> (usize, Option<DMatrix<f64>>);

/// The advice: the current uncertainty map and the `count` poses that lower the
/// expected mapping error most, greedily. `None` when the calibration's
/// information is singular (it does not determine every free intrinsic).
pub fn advise(kn: &Knowledge, count: usize) -> Option<Advice> {
    advise_with(kn, count, candidate_information)
}

fn advise_with(kn: &Knowledge, count: usize, view_info: CandidateInformation) -> Option<Advice> {
    let (h, _, m) = mapping_forms(&kn.intrinsics, kn.width, kn.height)?;
    let current_error_px = error_with(kn, &h, m, &kn.information)?;
    let sigma = full_covariance(kn, &kn.information)? * kn.noise_px.powi(2);
    let map = projection_uncertainty_map(&kn.intrinsics, &sigma, kn.width, kn.height, 32);
    let need = (MIN_VISIBLE * kn.target.num_corners() as f64).ceil() as usize;
    let views: Vec<(Pose, usize, DMatrix<f64>)> = candidates(kn)
        .into_iter()
        .filter_map(|p| {
            let (seen, info) = view_info(kn, &p);
            if seen < need.max(4) {
                return None;
            }
            Some((p, seen, info?))
        })
        .collect();
    let mut info = kn.information.clone();
    let mut taken = vec![false; views.len()];
    let mut poses = Vec::new();
    for _ in 0..count {
        let best = views
            .iter()
            .enumerate()
            .filter(|(i, _)| !taken[*i])
            .filter_map(|(i, v)| Some((i, error_with(kn, &h, m, &(&info + &v.2))?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let Some((i, err)) = best else { break };
        taken[i] = true;
        info += &views[i].2;
        poses.push(Advised {
            camera_from_board: views[i].0,
            outline: outline(kn, &views[i].0),
            corners_in_view: views[i].1,
            predicted_error_px: err,
        });
    }
    Some(Advice {
        current_error_px,
        map,
        poses,
    })
}

/// The board's four outer grid corners projected (unclipped; may lie outside).
fn outline(kn: &Knowledge, pose: &Pose) -> [[f64; 2]; 4] {
    let t = &kn.target;
    let ids = [0, t.cols - 1, t.num_corners() - 1, (t.rows - 1) * t.cols];
    ids.map(|i| {
        let xc = pose.transform(&t.nominal(i));
        kn.intrinsics
            .project(&xc)
            .map_or([f64::NAN; 2], |uv| [uv.x, uv.y])
    })
}

/// The information of every view of camera `camera` in `dataset`, with the
/// calibration's poses: camera_from_board = camera_from_camera0 ∘ camera0_from_board.
pub fn dataset_information(
    k: &Intrinsics,
    free: &[bool],
    dataset: &Dataset,
    camera: usize,
    camera_pose: &Pose,
    frame_poses: &[Option<Pose>],
) -> DMatrix<f64> {
    let n = free.iter().filter(|f| **f).count();
    let mut info = DMatrix::zeros(n, n);
    for (frame, pose) in frame_poses.iter().enumerate() {
        let Some(pose) = pose else { continue };
        let corners: Vec<usize> = dataset
            .observations
            .iter()
            .filter(|o| o.camera == camera && o.frame == frame)
            .map(|o| o.corner)
            .collect();
        if corners.is_empty() {
            continue;
        }
        let camera_from_board = camera_pose.compose(pose);
        if let Some(v) = view_information(k, free, &dataset.target, &camera_from_board, &corners) {
            info += v;
        }
    }
    info
}

/// Reads the calibration and its config's observations, advises, writes the SVG.
pub fn run(args: &Args) -> Result<Advice> {
    let json = CalibrationJson::load(&args.calibration)?;
    let config = crate::app::config::Config::load(&args.config)?;
    let (dataset, _) = crate::app::source::load_data(&config)?;
    let camera = match &args.camera {
        None => 0,
        Some(name) => json
            .cameras
            .iter()
            .position(|c| &c.name == name)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "advise: no camera `{name}` in {}",
                    args.calibration.display()
                ))
            })?,
    };
    let cam = &json.cameras[camera];
    let noise_px = json.noise_px.ok_or_else(|| {
        Error::Invalid(format!(
            "advise: {} has no noise estimate (noise_px)",
            args.calibration.display()
        ))
    })?;
    let free: Vec<bool> = config
        .cameras
        .get(camera)
        .map(|c| c.held().iter().map(|h| !h).collect())
        .unwrap_or_else(|| vec![true; cam.intrinsics.params().len()]);
    let frame_poses: Vec<Option<Pose>> = dataset
        .frame_ids
        .iter()
        .map(|id| {
            json.frames.iter().find(|f| f.frame == *id).map(|f| Pose {
                rotation: f.rotation,
                translation: f.translation,
            })
        })
        .collect();
    let camera_pose = Pose {
        rotation: cam.rotation,
        translation: cam.translation,
    };
    let information = dataset_information(
        &cam.intrinsics,
        &free,
        &dataset,
        camera,
        &camera_pose,
        &frame_poses,
    );
    let kn = Knowledge {
        intrinsics: cam.intrinsics,
        width: cam.width,
        height: cam.height,
        free,
        target: dataset.target,
        noise_px,
        information,
    };
    let advice = advise(&kn, 3).ok_or_else(|| {
        Error::Degenerate("advise: the views so far do not determine every free intrinsic".into())
    })?;
    crate::app::fsio::write_atomic(&args.out, svg(&kn, &advice).as_bytes())?;
    Ok(advice)
}

/// The picture: the projection-uncertainty map (σ in px, grey to red) with the
/// advised boards' outlines, numbered, and each one's predicted error.
pub fn svg(kn: &Knowledge, advice: &Advice) -> String {
    let (w, h) = (kn.width as f64, kn.height as f64);
    let legend = 0.12 * h;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" viewBox=\"0 0 {w} {}\">",
        w.min(1200.0),
        (w.min(1200.0) / w * (h + legend)).round(),
        h + legend
    );
    let map = &advice.map;
    let (lo, hi) = (map.min(), map.max().max(map.min() + 1e-12));
    let (cw, ch) = (w / map.columns as f64, h / map.rows as f64);
    for r in 0..map.rows {
        for c in 0..map.columns {
            let v = map.sigma_px[r * map.columns + c];
            let t = if v.is_finite() {
                (v - lo) / (hi - lo)
            } else {
                0.0
            };
            let _ = writeln!(
                s,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\"/>",
                c as f64 * cw,
                r as f64 * ch,
                cw + 0.5,
                ch + 0.5,
                colour(t)
            );
        }
    }
    board_outlines(&mut s, advice, w, h);
    let _ = writeln!(
        s,
        "<rect x=\"0\" y=\"{h}\" width=\"{w}\" height=\"{legend}\" fill=\"#ffffff\"/>"
    );
    // Two lines, smaller than the labels: one line overflows a 640 px image.
    let caption = (h / 36.0).round();
    let lines = [
        format!(
            "projection σ {lo:.3} px (grey) to {hi:.3} px (red); expected mapping error now {:.3} px",
            advice.current_error_px
        ),
        "outlines: the next boards to add, each with the expected error after adding it".to_string(),
    ];
    for (i, line) in lines.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"{caption}\">{line}</text>",
            0.01 * w,
            h + (0.4 + 0.35 * i as f64) * legend,
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The advised boards' outlines, numbered, with each one's predicted error.
fn board_outlines(s: &mut String, advice: &Advice, w: f64, h: f64) {
    let font = (h / 28.0).round();
    let colours = ["#1f5fd6", "#118a3a", "#7a2bbf"];
    for (i, p) in advice.poses.iter().enumerate() {
        let pts: Vec<String> = p
            .outline
            .iter()
            .map(|q| format!("{:.1},{:.1}", q[0], q[1]))
            .collect();
        let col = colours[i % colours.len()];
        let _ = writeln!(
            s,
            "<polygon points=\"{}\" fill=\"none\" stroke=\"{col}\" stroke-width=\"{:.1}\" stroke-dasharray=\"{:.1}\"/>",
            pts.join(" "),
            h / 200.0,
            if i == 0 { 0.0 } else { h / 60.0 }
        );
        let cx = p.outline.iter().map(|q| q[0]).sum::<f64>() / 4.0;
        let cy = p.outline.iter().map(|q| q[1]).sum::<f64>() / 4.0;
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"{font}\" fill=\"{col}\" text-anchor=\"middle\">{}: {:.3} px</text>",
            cx.clamp(0.0, w),
            cy.clamp(font, h),
            i + 1,
            p.predicted_error_px
        );
    }
}

/// Grey (0) to red (1).
fn colour(t: f64) -> String {
    let t = t.clamp(0.0, 1.0);
    let r = (200.0 + 55.0 * t) as u8;
    let g = (200.0 * (1.0 - t) + 40.0 * t) as u8;
    let b = (200.0 * (1.0 - t) + 40.0 * t) as u8;
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// What camera `k` of a finished calibration knows, from the covariance the
/// pipeline already computed (its inverse is the information so far, at unit
/// noise; nothing is solved again) and its noise estimate; `None` when the
/// calibration has no covariance or no noise estimate.
pub fn knowledge_of(c: &crate::solver::calibrate::Calibration, k: usize) -> Option<Knowledge> {
    let cov = c.covariance.as_ref().ok()?.cameras.get(k)?;
    let noise_px = c.assessment.trust.as_ref()?.noise_px;
    let idx = free_indices(&cov.free);
    let block = DMatrix::from_fn(idx.len(), idx.len(), |a, b| cov.unit[(idx[a], idx[b])]);
    let information = block.cholesky()?.inverse();
    let cam = c.dataset.cameras.get(k)?;
    Some(Knowledge {
        intrinsics: *c.state.intrinsics.get(k)?,
        width: cam.width,
        height: cam.height,
        free: cov.free.clone(),
        target: c.dataset.target,
        noise_px,
        information,
    })
}

#[cfg(test)]
#[path = "advise_tests.rs"]
mod tests;
