//! The board priors' σ from the data (`static_prior_mm = "auto"`,
//! `bend_prior_mm = "auto"`; empirical Bayes).
//!
//! A fixed prior σ either does nothing (far above the values' estimation noise)
//! or biases real deformations (below their size). The estimates' own spread
//! says which: their mean square, less the part their estimation variance
//! explains, is the variance of the true values. On a rigid, well printed board
//! that is near zero, so the prior holds the values and the method keeps close
//! to `standard`'s variance; on a bending or misprinted one it is the
//! deformation's size, and the prior hardly pulls. This module reads a finished
//! solve without the prior and returns each prior's σ; the pipeline
//! (`calibrate`) solves again with it, and drops it if it fits clearly worse.
use crate::model::board::{bend_reach, BoardPriors, Method};
use crate::model::state::{State, POSE_PARAMS};
use crate::solver::covariance::unit_correction_information;
use crate::solver::problem::{Problem, SolverSettings};
use nalgebra::{DMatrix, DVector};

/// The smallest bend σ the estimate returns, metres: the prior never pins a
/// bend tighter than a hundredth of a millimetre at the board's corner.
pub const MIN_BEND_SIGMA_M: f64 = 1e-5;

/// The smallest static σ the estimate returns, metres: a micrometre, the
/// floor a measured board's σ has too (`MIN_GEOMETRY_STD_M`).
pub const MIN_STATIC_SIGMA_M: f64 = 1e-6;

/// A board prior whose σ can be estimated from the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AutoPrior {
    /// The prior on every static correction value (`static_prior_mm`).
    Static,
    /// The prior on every bend term (`bend_prior_mm`).
    Bend,
}

/// An estimated σ, and how many estimated values it rests on (the values the
/// prior then holds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub sigma: f64,
    pub values: usize,
}

impl AutoPrior {
    /// Both, in the order the pipeline adds them.
    pub const ALL: [AutoPrior; 2] = [AutoPrior::Static, AutoPrior::Bend];

    /// The config key.
    pub fn key(self) -> &'static str {
        match self {
            AutoPrior::Static => "static_prior_mm",
            AutoPrior::Bend => "bend_prior_mm",
        }
    }

    /// Whether `board` asks for this σ to be estimated and `method` has the values.
    pub fn wanted(self, board: &BoardPriors, method: Method) -> bool {
        match self {
            AutoPrior::Static => {
                board.static_sigma_auto && board.static_sigma_m.is_none() && method.has_correction()
            }
            AutoPrior::Bend => {
                board.bend_sigma_auto && board.bend_sigma_m.is_none() && method.has_paraboloid()
            }
        }
    }

    /// Sets this prior's σ, metres (`None`: off).
    pub fn set(self, board: &mut BoardPriors, sigma: Option<f64>) {
        match self {
            AutoPrior::Static => board.static_sigma_m = sigma,
            AutoPrior::Bend => board.bend_sigma_m = sigma,
        }
    }

    /// The σ (metres) that the values of the solve at `state` show beyond their
    /// noise `noise_px`; `None` when no value has a variance.
    pub fn estimate(
        self,
        problem: &Problem,
        state: &State,
        settings: &SolverSettings,
        noise_px: f64,
    ) -> Option<Estimate> {
        match self {
            AutoPrior::Static => estimate_static_sigma(problem, state, settings, noise_px),
            AutoPrior::Bend => estimate_bend_sigma(problem, state, settings, noise_px),
        }
    }
}

/// The σ of zero-mean true values from unbiased estimates Δ of them whose
/// errors have covariance C, by the moments: over n values and with P = C⁻¹,
/// E[ΔᵀPΔ] = σ²·tr P + n, so σ² = (ΔᵀPΔ − n) / tr P, at least `floor`. For a
/// diagonal C this is the precision-weighted mean of Δ² − var, so that a barely
/// determined value cannot drown the others; for a full C the same holds for
/// barely determined directions, which a diagonal would smear over every value.
fn excess_sigma(quadratic: f64, trace: f64, values: usize, floor: f64) -> Option<Estimate> {
    (trace > 0.0 && trace.is_finite() && quadratic.is_finite()).then(|| Estimate {
        sigma: ((quadratic - values as f64) / trace)
            .max(0.0)
            .sqrt()
            .max(floor),
        values,
    })
}

/// The static prior's σ: over every free correction value Δ, with P its
/// marginal information (intrinsics, poses and bends free, at the noise). The
/// information given the intrinsics would be far too large: the correction
/// trades off against them, which is why `static` is weakly determined at all,
/// and the excess over a too small variance would read noise as print error.
/// The marginal variances alone (P's inverse's diagonal) would not do either:
/// most of the estimates' error lies along the few directions the intrinsics
/// take up, so their Δ²/var scatter by 0.4–2.2 around 1 from set to set, and
/// one T2 set of 25 images gave σ = 0 against a true 0.07 mm.
pub fn estimate_static_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    let values = problem.layout().pack(state)?;
    let (params, info) = unit_correction_information(problem, state, settings).ok()?;
    let delta = DVector::from_iterator(params.len(), params.iter().map(|&p| values[p]));
    let n2 = noise_px * noise_px;
    let quadratic = delta.dot(&(&info * &delta)) / n2;
    excess_sigma(
        quadratic,
        info.trace() / n2,
        params.len(),
        MIN_STATIC_SIGMA_M,
    )
}

/// The bend prior's σ (Δz of each term at the board's corner) over every frame
/// and term, each with its own variance (P diagonal). A bend's estimation
/// variance is taken given the intrinsics (its
/// frame's pose and bend from that frame's observations alone): cheap, and a
/// slight underestimate that leaves the prior a little looser than it could be.
pub fn estimate_bend_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    let layout = problem.layout();
    let stride = layout.frame_stride;
    let terms = stride.checked_sub(POSE_PARAMS).filter(|&t| t > 0)?;
    let info = frame_information(problem, state, settings)?;
    let values = layout.pack(state)?;
    let reach = bend_reach(&problem.dataset.target, terms);
    let (mut quadratic, mut trace, mut count) = (0.0, 0.0, 0);
    for (j, info) in info.into_iter().enumerate() {
        let Some(cov) = info.try_inverse() else {
            continue;
        };
        for (i, r) in reach.iter().enumerate() {
            let slot = POSE_PARAMS + i;
            let dz = values[layout.frames + j * stride + slot] * r;
            let variance = noise_px * noise_px * cov[(slot, slot)] * r * r;
            if variance.is_finite() && variance > 0.0 {
                quadratic += dz * dz / variance;
                trace += 1.0 / variance;
                count += 1;
            }
        }
    }
    excess_sigma(quadratic, trace, count, MIN_BEND_SIGMA_M)
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
