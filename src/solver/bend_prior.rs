//! The bend prior's σ from the data (`bend_prior_mm = "auto"`, empirical Bayes).
//!
//! A fixed prior σ either does nothing (far above the bends' estimation noise)
//! or biases real bends (below their size). The bends' own spread says which:
//! the mean square of the estimated Δz at the board's corner, less the part
//! their estimation variance explains, is the true bends' variance. On a rigid
//! board that is near zero, so the prior holds the bends and `dynamic` keeps
//! close to `standard`'s variance; on a bending one it is the bends' size, and
//! the prior hardly pulls. This module reads a finished solve and returns the
//! σ; the pipeline (`calibrate`) solves again with it.
use crate::model::board::bend_reach;
use crate::model::state::{State, POSE_PARAMS};
use crate::solver::problem::{Problem, SolverSettings};
use nalgebra::DMatrix;

/// The smallest σ the estimate returns, metres: the prior never pins a bend
/// tighter than a hundredth of a millimetre at the board's corner.
pub const MIN_BEND_SIGMA_M: f64 = 1e-5;

/// The σ (metres, Δz of each term at the board's corner) that the bends of the
/// solve at `state` show beyond their noise `noise_px`, at least
/// [`MIN_BEND_SIGMA_M`]; `None` for a method without bends or when no frame's
/// bend has a variance.
///
/// The variance is a precision-weighted mean of Δz² less its estimation
/// variance over every frame and term, so that a barely determined bend cannot
/// drown the others. A bend's estimation variance is taken given the intrinsics
/// (its frame's pose and bend from that frame's observations alone): cheap, and
/// a slight underestimate that leaves the prior a little looser than it could be.
pub fn estimate_bend_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<f64> {
    let layout = problem.layout();
    let stride = layout.frame_stride;
    let terms = stride.checked_sub(POSE_PARAMS).filter(|&t| t > 0)?;
    let info = frame_information(problem, state, settings)?;
    let values = layout.pack(state)?;
    let reach = bend_reach(&problem.dataset.target, terms);
    let (mut excess, mut precision) = (0.0, 0.0);
    for (j, info) in info.into_iter().enumerate() {
        let Some(cov) = info.try_inverse() else {
            continue;
        };
        for (i, r) in reach.iter().enumerate() {
            let slot = POSE_PARAMS + i;
            let dz = values[layout.frames + j * stride + slot] * r;
            let variance = noise_px * noise_px * cov[(slot, slot)] * r * r;
            if variance.is_finite() && variance > 0.0 {
                excess += (dz * dz - variance) / variance;
                precision += 1.0 / variance;
            }
        }
    }
    (precision > 0.0).then(|| (excess / precision).max(0.0).sqrt().max(MIN_BEND_SIGMA_M))
}

/// Per frame, JᵀJ of its pose and bend values from its own observations' rows
/// (weighted residuals, so in units of a weight-1 corner's noise).
fn frame_information(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
) -> Option<Vec<DMatrix<f64>>> {
    let layout = problem.layout();
    let stride = layout.frame_stride;
    let e = problem.jacobian(state, settings).ok()?;
    if e.jacobian_rows != 2 * problem.dataset.observations.len() {
        return None;
    }
    let frames = layout.frames..layout.frames + stride * layout.num_frames;
    let slot: Vec<Option<(usize, usize)>> = e
        .jacobian_col_param
        .iter()
        .map(|&p| {
            let p = p as usize;
            frames
                .contains(&p)
                .then(|| ((p - frames.start) / stride, (p - frames.start) % stride))
        })
        .collect();
    let mut info = vec![DMatrix::<f64>::zeros(stride, stride); layout.num_frames];
    let mut entries = Vec::new();
    for r in 0..e.jacobian_rows {
        entries.clear();
        for i in e.jacobian_row_ptr[r] as usize..e.jacobian_row_ptr[r + 1] as usize {
            if let Some((j, s)) = slot[e.jacobian_col_idx[i] as usize] {
                entries.push((j, s, e.jacobian_values[i]));
            }
        }
        for &(j, a, va) in &entries {
            for &(k, b, vb) in &entries {
                if j == k {
                    info[j][(a, b)] += va * vb;
                }
            }
        }
    }
    Some(info)
}
