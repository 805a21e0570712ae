//! Guards of the calibration pipeline against confident wrong answers: screening
//! the observations before initialisation (outside the image, views that fit no
//! planar board), refusing solves that made no progress or whose cost is not
//! finite, rejecting outliers after the robust solve (mrcal's scheme), and warning
//! when the views cannot determine the focal length. The pipeline in
//! `calibrate` calls these; they hold no state of their own.
use crate::error::{Error, Result};
use crate::model::board::Method;
use crate::model::dataset::{Dataset, Observation};
use crate::model::zhang;
use crate::solver::problem::{rmse, Problem, SolveReport, SolverSettings, State};
use nalgebra::Vector2;
use std::collections::BTreeMap;

/// How far outside the image (as a fraction of its width or height) a corner may
/// lie before it is dropped: detectors report corners up to the border, and a few
/// pixels beyond is rounding, not data.
pub const OUTSIDE_MARGIN: f64 = 0.02;

/// Largest fraction of a camera's observations that may lie outside its image and
/// be dropped: a stray detection or two is noise, more means the declared size is
/// not the images' (a calibration of what is left comes out confidently wrong).
pub const MAX_OUTSIDE_FRACTION: f64 = 0.05;

/// At most this many items are named in one warning.
const NAMED: usize = 5;

/// A list cut to its first few items.
fn named(items: &[String]) -> String {
    let mut s = items[..items.len().min(NAMED)].join(", ");
    if items.len() > NAMED {
        s.push_str(&format!(" and {} more", items.len() - NAMED));
    }
    s
}

/// Drops the observations outside their camera's image by more than
/// [`OUTSIDE_MARGIN`], naming them in a warning; refuses data with none inside,
/// and a camera with more than [`MAX_OUTSIDE_FRACTION`] of its observations outside.
pub fn drop_outside_image(dataset: &Dataset, warnings: &mut Vec<String>) -> Result<Dataset> {
    let inside = |o: &Observation| {
        let c = &dataset.cameras[o.camera];
        let (w, h) = (c.width as f64, c.height as f64);
        let (mu, mv) = (OUTSIDE_MARGIN * w, OUTSIDE_MARGIN * h);
        (-0.5 - mu..=w - 0.5 + mu).contains(&o.uv[0])
            && (-0.5 - mv..=h - 0.5 + mv).contains(&o.uv[1])
    };
    let outside: Vec<String> = dataset
        .observations
        .iter()
        .filter(|o| !inside(o))
        .map(|o| {
            format!(
                "{} corner {} at ({:.1}, {:.1})",
                dataset.view_name(o.camera, o.frame),
                o.corner,
                o.uv[0],
                o.uv[1]
            )
        })
        .collect();
    if outside.is_empty() {
        return Ok(dataset.clone());
    }
    if outside.len() == dataset.observations.len() {
        let sizes: Vec<String> = dataset
            .cameras
            .iter()
            .map(|c| format!("{} {}×{}", c.name, c.width, c.height))
            .collect();
        return Err(Error::Degenerate(format!(
            "every observation lies outside its image ({}): check the cameras' width and height",
            sizes.join(", ")
        )));
    }
    check_outside_fraction(dataset, &inside)?;
    warnings.push(format!(
        "{} observation(s) outside the image dropped: {}",
        outside.len(),
        named(&outside)
    ));
    let mut kept = dataset.clone();
    kept.observations.retain(inside);
    Ok(kept)
}

/// Refuses the first camera with more than [`MAX_OUTSIDE_FRACTION`] of its
/// observations outside its image, naming its declared size and where its
/// corners actually lie.
fn check_outside_fraction(dataset: &Dataset, inside: &dyn Fn(&Observation) -> bool) -> Result<()> {
    for (k, cam) in dataset.cameras.iter().enumerate() {
        let mine: Vec<&Observation> = dataset
            .observations
            .iter()
            .filter(|o| o.camera == k)
            .collect();
        let outside = mine.iter().filter(|o| !inside(o)).count();
        if outside == 0 || (outside as f64) <= MAX_OUTSIDE_FRACTION * mine.len() as f64 {
            continue;
        }
        let span = |i: usize| {
            let (lo, hi) = mine
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), o| {
                    (lo.min(o.uv[i]), hi.max(o.uv[i]))
                });
            format!("{lo:.0}..{hi:.0}")
        };
        return Err(Error::Degenerate(format!(
            "camera {}: {outside} of its {} observations ({:.0}%) lie outside its declared {}×{} image (its corners span u {}, v {}): check its width and height",
            cam.name,
            mine.len(),
            100.0 * outside as f64 / mine.len() as f64,
            cam.width,
            cam.height,
            span(0),
            span(1)
        )));
    }
    Ok(())
}

/// A view's homography may miss its corners by this fraction of the view's size in
/// pixels (RMS) before it is judged not to show the board as numbered: lens
/// distortion bends a view by a few percent, a shuffled or mis-sized numbering by
/// tens of percent.
const MAX_HOMOGRAPHY_MISFIT: f64 = 0.08;

/// RMS misfit of the best homography of a view, relative to the view's pixel extent;
/// `None` when it has too few corners for one.
fn homography_misfit(board: &[Vector2<f64>], image: &[Vector2<f64>]) -> Option<f64> {
    let h = zhang::homography(board, image)?;
    let mut sum = 0.0;
    for (b, i) in board.iter().zip(image) {
        let p = h * nalgebra::Vector3::new(b.x, b.y, 1.0);
        let e = Vector2::new(p.x / p.z, p.y / p.z) - i;
        sum += e.norm_squared();
    }
    let (mut lo, mut hi) = (image[0], image[0]);
    for p in image {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi - lo).norm().max(1.0);
    let misfit = (sum / board.len() as f64).sqrt() / extent;
    Some(if misfit.is_finite() { misfit } else { f64::MAX })
}

/// Board points and pixels of one view.
type Correspondences = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// Drops the views whose corners no planar board numbered as `[target]` explains
/// (a frame with shuffled corner indices), naming them; when no view fits, says what
/// is likely wrong instead of failing later with a misleading message.
pub fn drop_inconsistent_views(dataset: &Dataset, warnings: &mut Vec<String>) -> Result<Dataset> {
    let mut views: BTreeMap<(usize, usize), Correspondences> = BTreeMap::new();
    for o in &dataset.observations {
        let p = dataset.target.nominal(o.corner);
        let e = views.entry((o.frame, o.camera)).or_default();
        e.0.push(Vector2::new(p.x, p.y));
        e.1.push(Vector2::new(o.uv[0], o.uv[1]));
    }
    let mut bad = Vec::new();
    let mut fitted = 0;
    for (&(frame, camera), (b, i)) in &views {
        if let Some(m) = homography_misfit(b, i) {
            fitted += 1;
            if m > MAX_HOMOGRAPHY_MISFIT {
                bad.push(((camera, frame), m));
            }
        }
    }
    if bad.is_empty() {
        return Ok(dataset.clone());
    }
    let t = dataset.target;
    if bad.len() == fitted {
        return Err(Error::Degenerate(format!(
            "no view's corners fit a planar {} × {} board with corner i = row·{} + col \
             (misfit {:.0}% of the view's size or more): check target.rows and target.cols \
             (swapped?) and the corner numbering",
            t.rows,
            t.cols,
            t.cols,
            100.0 * bad.iter().map(|b| b.1).fold(f64::MAX, f64::min)
        )));
    }
    let names: Vec<String> = bad
        .iter()
        .map(|&((c, f), m)| format!("{} ({:.0}%)", dataset.view_name(c, f), 100.0 * m))
        .collect();
    warnings.push(format!(
        "{} view(s) dropped: their corners fit no planar board numbered as [target] (shuffled or wrong corner indices?): {}",
        bad.len(),
        named(&names)
    ));
    let drop: std::collections::HashSet<(usize, usize)> = bad.iter().map(|b| b.0).collect();
    let mut kept = dataset.clone();
    kept.observations
        .retain(|o| !drop.contains(&(o.camera, o.frame)));
    Ok(kept)
}

/// A solve that stops without a step from a start this far off (RMSE, pixels) made
/// no progress: the cost underflowed or is flat, it did not converge.
const POOR_START_PX: f64 = 2.0;

/// Refuses a stage whose cost is not finite or underflows, or that "converged"
/// without a single step from a fresh start (Zhang's, or `standard`'s for a
/// deformation method: neither is ever the optimum) or from a poor one: all leave
/// the starting point as the answer. Only a re-solve after outlier rejection
/// (`fresh` false) may legitimately stop at once.
pub fn check_stage(method: Method, report: &SolveReport, fresh: bool) -> Result<()> {
    if !(report.initial_cost.is_finite() && report.final_cost.is_finite())
        || report.residuals.iter().any(|r| !r.is_finite())
    {
        return Err(Error::Solver(format!(
            "the {method} solve failed: its cost is not finite (initial {}, final {})",
            report.initial_cost, report.final_cost
        )));
    }
    let start = rmse(&report.residuals);
    // A zero cost with non-zero residuals is an underflow, not a perfect fit.
    if report.final_cost <= 0.0 && start > 1e-9 {
        return Err(Error::Solver(format!(
            "the {method} solve failed: the cost underflows to zero at an RMSE of {start:.3} px; \
             check loss_scale_px and the observation weights"
        )));
    }
    if report.iterations <= 0 && (fresh || start > POOR_START_PX) {
        // Ceres says which test stopped it: a tolerance met before the first
        // step is the tolerance's fault, not the loss's.
        let cause = if report.message.contains("tolerance") {
            format!(
                "Ceres stopped on a tolerance before its first step ({}); \
                 check calibration.function_tolerance, gradient_tolerance and parameter_tolerance",
                report.message.trim_end_matches('.')
            )
        } else {
            "the cost is flat or underflows; check loss_scale_px and the observation weights".into()
        };
        return Err(Error::Solver(format!(
            "the {method} solve made no progress from its start (RMSE {start:.3} px after 0 iterations): {cause}"
        )));
    }
    Ok(())
}

/// An observation that outlier rejection removed, with its residual when rejected.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejected {
    pub observation: Observation,
    pub residual_px: f64,
}

/// Rounds of rejection and re-solve at most; each round only adds rejections, so
/// this bounds the work, not the answer (it is stable long before).
const MAX_REJECTION_ROUNDS: usize = 10;

/// A re-solve after a rejection stops after a successful step that changed
/// the cost by at most this fraction of it. It starts next to its optimum,
/// which its first Gauss-Newton step reaches: Ceres' tolerances then refused a
/// second step, computed only to be refused, which left the answer where the
/// first had put it, at the price of a Jacobian and a linear solve (`full`,
/// 1 600 `t2` images: 0.5 s of 3.2). That first step changes the cost by about
/// 3e-5 of it (`cargo bench --bench speed -- growth`, `SPEED_VERBOSE=1`); a
/// larger change is followed by more steps, as before.
const SETTLE_COST_CHANGE: f64 = 1e-4;

/// Share of rejected observations above which the data are called unreliable.
pub const WARN_REJECTED_FRACTION: f64 = 0.1;

/// The result of outlier rejection: the data kept, the final residuals, the
/// corners whose correction is frozen, the extra solves and the rejected.
pub struct Rejection {
    pub dataset: Dataset,
    pub residuals: Vec<f64>,
    pub frozen: Vec<usize>,
    pub reports: Vec<SolveReport>,
    pub rejected: Vec<Rejected>,
}

/// σ of one pixel coordinate, robustly: 1.4826 × the median absolute residual
/// (the normal distribution's MAD), so outliers do not inflate it.
fn robust_sigma(residuals: &[f64]) -> f64 {
    let mut a: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
    if a.is_empty() {
        return 0.0;
    }
    let mid = a.len() / 2;
    let (_, m, _) = a.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m
}

/// The median of `v` (sorted in place), the mean of the middle two for an even count.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The corners a deviation may draw on: two steps in each direction along the
/// board's rows and columns (a corner left of a gross outlier is compared with it).
const REACH: isize = 2;

/// How far each observation's residual stands out from its neighbours' on the
/// board, larger coordinate, in units of the noise of that comparison (an
/// extrapolation from two corners is twice as noisy as a median of four). A model error (a bend
/// `standard` cannot follow) moves neighbours alike and cancels here; a bad
/// detection does not. Inside the board the comparison is with the component-wise
/// median of the four adjacent residuals, which cancels a residual field that is
/// linear over the board. On the board's edge, or next to a corner not seen (or
/// rejected in an earlier round), a median of neighbours does not cancel it: a
/// corner would stand out by the field's slope, be rejected, expose the next
/// corner, and rejection would eat a bent view round by round. There the
/// comparison is with the median of the linear predictions available: centred
/// ((a + b)/2 of the two neighbours along a row or column) and one-sided
/// (2a − b of the next two in one direction).
fn local_deviations(dataset: &Dataset, residuals: &[f64]) -> Vec<f64> {
    let obs = &dataset.observations;
    let (rows, cols) = (dataset.target.rows as isize, dataset.target.cols as isize);
    // One view at a time, its corners in a dense slot per board corner (the last
    // observation of a corner seen twice), so a neighbour is found without a map.
    let mut order: Vec<usize> = (0..obs.len()).collect();
    order.sort_by_key(|&i| (obs[i].camera, obs[i].frame));
    let slots = obs
        .iter()
        .map(|o| o.corner + 1)
        .max()
        .unwrap_or(0)
        .max(dataset.target.num_corners());
    let mut at = vec![usize::MAX; slots];
    let mut out = vec![0.0; obs.len()];
    for view in
        order.chunk_by(|&a, &b| (obs[a].camera, obs[a].frame) == (obs[b].camera, obs[b].frame))
    {
        for &i in view {
            at[obs[i].corner] = i;
        }
        // The residual of the corner `step` steps from `corner` along `(dr, dc)`.
        let residual = |corner: usize, (dr, dc): (isize, isize), step: isize| {
            let (r, c) = (
                (corner as isize / cols) + dr * step,
                (corner as isize % cols) + dc * step,
            );
            if r < 0 || c < 0 || r >= rows || c >= cols {
                return None;
            }
            let j = at[(r * cols + c) as usize];
            (j != usize::MAX).then(|| [residuals[2 * j], residuals[2 * j + 1]])
        };
        for &i in view {
            let r = [residuals[2 * i], residuals[2 * i + 1]];
            out[i] = corner_deviation(obs[i].corner, r, &residual);
        }
        for &i in view {
            at[obs[i].corner] = usize::MAX;
        }
    }
    out
}

/// A prediction of a corner's residual from its neighbours': its value, and its
/// weights on the corners within reach (slot 2·direction + step − 1), for the
/// deviation's noise.
type Prediction = ([f64; 2], [f64; 8]);

/// How far residual `r` of `corner` stands out from its neighbours', in units of
/// the comparison's noise (see [`local_deviations`]); `residual(corner,
/// direction, step)` is a neighbour's residual where it was seen.
fn corner_deviation(
    corner: usize,
    r: [f64; 2],
    residual: &impl Fn(usize, (isize, isize), isize) -> Option<[f64; 2]>,
) -> f64 {
    let single = |d: usize| {
        residual(corner, DIRECTIONS[d], 1).map(|a| {
            let mut w = [0.0; 8];
            w[2 * d] = 1.0;
            (a, w)
        })
    };
    // On the stack: this runs for every corner in every rejection round.
    let mut adjacent: [Prediction; 4] = [([0.0; 2], [0.0; 8]); 4];
    let mut adjacent_count = 0;
    for p in (0..4).filter_map(single) {
        adjacent[adjacent_count] = p;
        adjacent_count += 1;
    }
    let mut linear: [Prediction; 6] = [([0.0; 2], [0.0; 8]); 6];
    let linear_count = if adjacent_count < 4 {
        linear_predictions(corner, residual, &mut linear)
    } else {
        0
    };
    let predictions = if linear_count > 0 {
        &linear[..linear_count]
    } else {
        &adjacent[..adjacent_count]
    };
    let (prediction, noise) = if predictions.is_empty() {
        ([0.0, 0.0], 1.0)
    } else {
        // The deviation's noise in units of one residual's, taking the
        // median as the mean: √(1 + Σ w²) of the mean prediction.
        let m = predictions.len() as f64;
        let spread: f64 = (0..8)
            .map(|k| (predictions.iter().map(|p| p.1[k]).sum::<f64>() / m).powi(2))
            .sum();
        (median2(predictions), (1.0 + spread).sqrt())
    };
    let deviation = (r[0] - prediction[0])
        .abs()
        .max((r[1] - prediction[1]).abs());
    deviation / noise
}

/// The linear predictions of `corner`'s residual where its neighbours allow them,
/// written into `out`; returns how many: centred ((a + b)/2 of the two
/// neighbours along a row or column), then one-sided (2a − b of the next two in
/// one direction).
fn linear_predictions(
    corner: usize,
    residual: &impl Fn(usize, (isize, isize), isize) -> Option<[f64; 2]>,
    out: &mut [Prediction; 6],
) -> usize {
    let mut count = 0;
    for (a, b) in [(0, 1), (2, 3)] {
        if let (Some(x), Some(y)) = (
            residual(corner, DIRECTIONS[a], 1),
            residual(corner, DIRECTIONS[b], 1),
        ) {
            let mut w = [0.0; 8];
            (w[2 * a], w[2 * b]) = (0.5, 0.5);
            out[count] = ([0.5 * (x[0] + y[0]), 0.5 * (x[1] + y[1])], w);
            count += 1;
        }
    }
    for (d, &step) in DIRECTIONS.iter().enumerate() {
        if let (Some(x), Some(y)) = (residual(corner, step, 1), residual(corner, step, REACH)) {
            let mut w = [0.0; 8];
            (w[2 * d], w[2 * d + 1]) = (2.0, -1.0);
            out[count] = ([2.0 * x[0] - y[0], 2.0 * x[1] - y[1]], w);
            count += 1;
        }
    }
    count
}

/// Left, right, up, down on the board, as (row, column) steps.
const DIRECTIONS: [(isize, isize); 4] = [(0, -1), (0, 1), (-1, 0), (1, 0)];

/// The component-wise median of (at most six) predicted 2-vectors.
fn median2(predictions: &[([f64; 2], [f64; 8])]) -> [f64; 2] {
    let (mut us, mut vs) = ([0.0; 6], [0.0; 6]);
    let n = predictions.len();
    for (k, p) in predictions.iter().enumerate() {
        (us[k], vs[k]) = (p.0[0], p.0[1]);
    }
    [median(&mut us[..n]), median(&mut vs[..n])]
}

/// The corners within [`REACH`] of `corner` along its row and column: those whose
/// deviation may draw on it, and it on them.
fn within_reach(corner: usize, target: &crate::model::target::Target) -> Vec<usize> {
    let (rows, cols) = (target.rows as isize, target.cols as isize);
    let (row, col) = (corner as isize / cols, corner as isize % cols);
    let mut out = Vec::with_capacity(4 * REACH as usize);
    for (dr, dc) in DIRECTIONS {
        for step in 1..=REACH {
            let (r, c) = (row + dr * step, col + dc * step);
            if r >= 0 && c >= 0 && r < rows && c < cols {
                out.push((r * cols + c) as usize);
            }
        }
    }
    out
}

/// Which observations to reject this round: those whose residual stands out from
/// their neighbours' by more than k·σ (σ of that local deviation, robustly),
/// worst first, as long as their view keeps enough corners for a
/// homography. A corner within reach of one picked here waits for the next
/// pass ([`pick_round`]), since the outlier's residual is part of its own
/// comparison. One pass, the unit of [`pick_round`] (which the tests check it by).
#[cfg(test)]
fn pick_outliers(dataset: &Dataset, residuals: &[f64], k: f64) -> Vec<usize> {
    // In units of each corner's own noise: a corner the refinement found
    // uncertain is not an outlier for being as far off as its σ says.
    let deviations = local_deviations(dataset, &crate::model::trust::weighted(dataset, residuals));
    select_outliers(dataset, &deviations, &[], k)
}

/// [`pick_outliers`] from the observations' local deviations, among those not
/// `removed` (all when it is empty).
fn select_outliers(dataset: &Dataset, deviations: &[f64], removed: &[bool], k: f64) -> Vec<usize> {
    let kept = |i: usize| removed.is_empty() || !removed[i];
    let left: Vec<f64> = (0..deviations.len())
        .filter(|&i| kept(i))
        .map(|i| deviations[i])
        .collect();
    // Each deviation is the larger of two |coordinates|: for Gaussian noise of
    // σ_d per coordinate its median is 1.052·σ_d (P(|x| < t)² = ½).
    let sigma = robust_sigma(&left) / 1.4826 / 1.052;
    if sigma <= 0.0 {
        return Vec::new();
    }
    // Corners per view, indexed camera-major (a flat array: this runs on every
    // observation in every round).
    let frames = dataset.num_frames();
    let mut per_view = vec![0usize; dataset.cameras.len() * frames];
    for (i, o) in dataset.observations.iter().enumerate() {
        if kept(i) {
            per_view[o.camera * frames + o.frame] += 1;
        }
    }
    let mut worst: Vec<(usize, f64)> = deviations
        .iter()
        .enumerate()
        .map(|(i, &e)| (i, e))
        .filter(|&(i, e)| kept(i) && e > k * sigma)
        .collect();
    worst.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut taken: std::collections::HashSet<(usize, usize, usize)> = Default::default();
    let mut out = Vec::new();
    for (i, _) in worst {
        let o = &dataset.observations[i];
        if within_reach(o.corner, &dataset.target)
            .into_iter()
            .any(|c| taken.contains(&(o.camera, o.frame, c)))
        {
            continue;
        }
        let n = &mut per_view[o.camera * frames + o.frame];
        if *n > MIN_VIEW_CORNERS {
            *n -= 1;
            taken.insert((o.camera, o.frame, o.corner));
            out.push(i);
        }
    }
    out.sort_unstable();
    out
}

/// Which observations to reject this round: [`pick_outliers`], then again
/// without those picked until it picks none. A corner that waited for an
/// outlier within its reach is so judged in the same round, without the
/// outlier, rather than after a re-solve: dropping a few corners among
/// thousands barely moves the others' residuals, while each re-solve costs
/// Jacobians and linear solves over all the data (at 10 000 `t2` images
/// `full` took a second round for them: 11 s of 31). Only the views that lost
/// a corner are compared again; the others' deviations stay as they were.
fn pick_round(dataset: &Dataset, residuals: &[f64], k: f64) -> Vec<usize> {
    let weighted = crate::model::trust::weighted(dataset, residuals);
    let mut deviations = local_deviations(dataset, &weighted);
    let mut removed = vec![false; deviations.len()];
    let mut picked = select_outliers(dataset, &deviations, &[], k);
    let mut all = Vec::new();
    while !picked.is_empty() {
        let mut touched = std::collections::HashSet::new();
        for &i in &picked {
            removed[i] = true;
            let o = &dataset.observations[i];
            touched.insert((o.camera, o.frame));
        }
        all.append(&mut picked);
        // The touched views without what was removed, and where each came from.
        let index: Vec<usize> = (0..removed.len())
            .filter(|&i| {
                let o = &dataset.observations[i];
                !removed[i] && touched.contains(&(o.camera, o.frame))
            })
            .collect();
        let views = Dataset {
            target: dataset.target,
            cameras: dataset.cameras.clone(),
            frame_ids: dataset.frame_ids.clone(),
            observations: index.iter().map(|&i| dataset.observations[i]).collect(),
        };
        let r: Vec<f64> = index
            .iter()
            .flat_map(|&i| [weighted[2 * i], weighted[2 * i + 1]])
            .collect();
        for (&i, d) in index.iter().zip(local_deviations(&views, &r)) {
            deviations[i] = d;
        }
        picked = select_outliers(dataset, &deviations, &removed, k);
    }
    all.sort_unstable();
    all
}

/// Corners a view keeps at least (a homography needs four; the pipeline's
/// `MIN_CORNERS_PER_IMAGE`, restated to keep this module below the pipeline).
const MIN_VIEW_CORNERS: usize = 4;

/// mrcal's outlier rejection: after the robust solve, drop the observations with a
/// coordinate beyond `settings.outlier_k`·σ (σ estimated robustly), re-solve from
/// the current state, and repeat until no observation is dropped.
pub fn reject_outliers(
    problem: Problem<'_>,
    state: &mut State,
    settings: &SolverSettings,
    residuals: Vec<f64>,
) -> Result<Rejection> {
    let mut dataset = problem.dataset.clone();
    let mut out = Rejection {
        dataset: dataset.clone(),
        residuals,
        frozen: problem.frozen.clone(),
        reports: Vec::new(),
        rejected: Vec::new(),
    };
    if settings.outlier_k <= 0.0 {
        return Ok(out);
    }
    for _ in 0..MAX_REJECTION_ROUNDS {
        let drop = pick_round(&dataset, &out.residuals, settings.outlier_k);
        if drop.is_empty() {
            break;
        }
        let mut keep = vec![true; dataset.observations.len()];
        for &i in &drop {
            keep[i] = false;
            let r = &out.residuals[2 * i..2 * i + 2];
            out.rejected.push(Rejected {
                observation: dataset.observations[i],
                residual_px: r[0].hypot(r[1]),
            });
        }
        let mut it = keep.iter();
        dataset
            .observations
            .retain(|_| *it.next().expect("one flag per observation"));
        // A corner that lost its views keeps its correction, like one never seen.
        let mut frozen = problem.frozen.clone();
        if problem.method.has_correction() {
            for c in crate::solver::problem::underobserved_corners(&dataset) {
                if !frozen.contains(&c) && !problem.gauge.contains(&c) {
                    frozen.push(c);
                }
            }
        }
        let p = Problem {
            dataset: &dataset,
            method: problem.method,
            gauge: problem.gauge.clone(),
            frozen: frozen.clone(),
            hold: problem.hold,
        };
        let report = p.resolve(state, settings, SETTLE_COST_CHANGE)?;
        check_stage(problem.method, &report, false)?;
        out.residuals = report.residuals.clone();
        out.frozen = frozen;
        out.reports.push(report);
    }
    out.dataset = dataset;
    Ok(out)
}

/// Views whose board spans less than this fraction of its distance in depth show
/// almost no perspective: the focal length then trades off against the distance.
const MIN_PERSPECTIVE: f64 = 0.05;

/// Warns when no view shows enough perspective to determine a camera's focal
/// length (a small board far away): the fit can be excellent and the intrinsics
/// wrong by tens of pixels.
pub fn weak_intrinsics_warnings(dataset: &Dataset, state: &State, warnings: &mut Vec<String>) {
    let t = &dataset.target;
    for (k, cam) in dataset.cameras.iter().enumerate() {
        let mut frames: Vec<usize> = dataset
            .observations
            .iter()
            .filter(|o| o.camera == k)
            .map(|o| o.frame)
            .collect();
        frames.sort_unstable();
        frames.dedup();
        let best = frames
            .iter()
            .map(|&j| {
                let pose = state.camera_poses[k].compose(&state.frame_poses[j]);
                let depths: Vec<f64> = [0, t.cols - 1, (t.rows - 1) * t.cols, t.num_corners() - 1]
                    .iter()
                    .map(|&i| pose.transform(&t.nominal(i)).z)
                    .collect();
                let (lo, hi) = depths
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), &z| (a.min(z), b.max(z)));
                let mean = depths.iter().sum::<f64>() / depths.len() as f64;
                (hi - lo) / mean.abs().max(1e-12)
            })
            .fold(0.0, f64::max);
        if best < MIN_PERSPECTIVE {
            warnings.push(format!(
                "{}: the intrinsics are poorly determined: in no view does the board span more than {:.1}% of its distance in depth \
                 (at least {:.0}% is needed), so the focal length trades off against the distance; \
                 bring the board closer or tilt it more",
                cam.name,
                100.0 * best,
                100.0 * MIN_PERSPECTIVE
            ));
        }
    }
}

#[cfg(test)]
#[path = "robust_tests.rs"]
mod tests;
