//! A fit's second part, from the warm start on: the method's solve, the noise
//! that weights the priors, outlier rejection and the result.
use super::method::{solve_method, with_auto_priors, Solved};
use super::types::{Assessment, Calibration, Request, Stage, Suspect};
use super::warm::{lens_prior_reweighted, WarmStart};
use crate::error::Result;
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::model::uncertainty::UncertaintyError;
use crate::solver::problem::{rmse, Hold, Problem, SolveReport, State};
use crate::solver::robust;
use std::time::Instant;

/// [`fit`]'s second part: the method's own solve from the warm start, the
/// priors, outlier rejection and the warnings.
pub(super) fn fit_from(warm: WarmStart, request: &Request) -> Result<Calibration> {
    let start = Instant::now();
    // The noise the user gave, before the pipeline estimates one for the priors.
    let detector_noise_px = request.settings.board.noise_px;
    let WarmStart {
        dataset,
        mut state,
        init_fallback,
        initial_intrinsics,
        mut warnings,
        mut stages,
        report,
        seconds: warm_seconds,
        ..
    } = warm;
    let (request, kept, (gauge, frozen, residuals)) = solve_requested(
        &dataset,
        &mut state,
        request,
        report,
        &mut stages,
        &mut warnings,
    )?;
    let request = &request;
    let before_rejection = stages.len();
    let (dataset, residuals, frozen, rejected) = finish_robustly(
        dataset,
        &mut state,
        request,
        gauge.clone(),
        frozen,
        residuals,
        kept.converged,
        &mut stages,
        &mut warnings,
    )?;
    // A rejection re-solve, where there was one, gives the result kept.
    let last = if stages.len() > before_rejection {
        stages.last().unwrap_or(&kept)
    } else {
        &kept
    };
    let converged = last.converged;
    if !converged {
        warnings.push(format!(
            "the {} solve did not converge: {}",
            request.method, last.message
        ));
    }
    Ok(Calibration {
        method: request.method,
        rmse_px: rmse(&residuals),
        residuals,
        dataset,
        state,
        converged,
        initial_intrinsics,
        init_fallback,
        stages,
        gauge,
        frozen,
        warnings,
        seconds: warm_seconds + start.elapsed().as_secs_f64(),
        settings: request.settings.clone(),
        rejected,
        detector_noise_px,
        selection: None,
        covariance: Err(UncertaintyError::Jacobian("not computed".into())),
        assessment: Assessment::pending(),
    })
}

/// The requested method's own solve from the warm start (`report`, its state in
/// `state`). Returns the request with the noise that weights the priors, the
/// stage whose result is kept (not always the last one recorded: a second start
/// that was not kept comes after the first start's), and the method's gauge,
/// frozen corners and residuals.
fn solve_requested(
    dataset: &Dataset,
    state: &mut State,
    request_in: &Request,
    report: SolveReport,
    stages: &mut Vec<Stage>,
    warnings: &mut Vec<String>,
) -> Result<(Request, Stage, Solved)> {
    let mut request = with_prior_noise(request_in, dataset, &report.residuals);
    let mut kept = Stage::new(Method::Standard, &report);
    if request.method == Method::Standard {
        let residuals = if lens_prior_reweighted(request_in, dataset) {
            // The lens prior weighted by the estimated noise, not the provisional
            // one: a polish from the optimum, which may take no step at all.
            let report = Problem::standard(dataset).solve(state, &request.settings)?;
            robust::check_stage(Method::Standard, &report, false)?;
            kept = Stage::new(Method::Standard, &report);
            stages.push(kept.clone());
            report.residuals
        } else {
            report.residuals
        };
        return Ok((request, kept, (Vec::new(), Vec::new(), residuals)));
    }
    let solved = solve_method(dataset, state, &mut request, true, stages, warnings)?;
    let solved = with_auto_priors(dataset, state, &mut request, solved, stages, warnings)?;
    // The method's last solve is the one kept.
    if let Some(last) = stages.last() {
        kept = last.clone();
    }
    Ok((request, kept, solved))
}

/// The request with the noise that weights the board priors: the configured one,
/// else estimated from `standard`'s residuals of neighbouring corners (which a
/// smooth model error hardly touches, see `trust::noise_from_neighbours`), by
/// their median: `standard` can leave a few corners far off (the rational model
/// has poles), and a prior weighted by their noise would hold everything flat.
fn with_prior_noise(request: &Request, dataset: &Dataset, residuals: &[f64]) -> Request {
    let mut r = request.clone();
    let models: Vec<_> = dataset.cameras.iter().map(|c| c.model).collect();
    let priors = r.settings.board.any() || r.settings.lens_prior_on(&models);
    if priors && r.settings.board.noise_px.is_none() {
        let noise = crate::model::trust::noise_from_neighbours_median(dataset, residuals)
            .unwrap_or_else(|| rmse(residuals) / std::f64::consts::SQRT_2);
        r.settings.board.noise_px = Some(noise);
    }
    r
}

/// What [`finish_robustly`] hands back: the data kept, their residuals, the frozen
/// corners and the rejected observations.
type Finished = (Dataset, Vec<f64>, Vec<usize>, Vec<Suspect>);

/// After the method's solve: outlier rejection with re-solves (see
/// [`robust::reject_outliers`]) and the warnings about what the data cannot show.
/// `converged`: whether the solve whose result is kept converged (if not,
/// nothing is rejected).
#[allow(clippy::too_many_arguments)] // the pipeline's state, passed through once
fn finish_robustly(
    dataset: Dataset,
    state: &mut State,
    request: &Request,
    gauge: Vec<usize>,
    frozen: Vec<usize>,
    residuals: Vec<f64>,
    converged: bool,
    stages: &mut Vec<Stage>,
    warnings: &mut Vec<String>,
) -> Result<Finished> {
    let total = dataset.observations.len();
    let problem = Problem {
        dataset: &dataset,
        method: request.method,
        gauge,
        frozen,
        hold: Hold::default(),
    };
    // The residuals of a solve that stopped short are not the model's: what
    // stands out there is where the solve had yet to go, not a bad detection.
    // The result fails the guard rails as not converged, with its data whole.
    let mut settings = request.settings.clone();
    if !converged {
        settings.outlier_k = 0.0;
    }
    let r = robust::reject_outliers(problem, state, &settings, residuals)?;
    for report in &r.reports {
        stages.push(Stage::new(request.method, report));
    }
    let fraction = r.rejected.len() as f64 / total.max(1) as f64;
    if fraction > robust::WARN_REJECTED_FRACTION {
        warnings.push(format!(
            "{} of {total} observations ({:.0}%) were rejected as outliers (beyond {}σ): \
             the detections are unreliable; check the corner detector and the data",
            r.rejected.len(),
            100.0 * fraction,
            request.settings.outlier_k
        ));
    }
    robust::weak_intrinsics_warnings(&r.dataset, state, warnings);
    let rejected = r
        .rejected
        .iter()
        .map(|x| Suspect {
            camera: r.dataset.cameras[x.observation.camera].name.clone(),
            frame: r.dataset.frame_ids[x.observation.frame],
            corner: x.observation.corner,
            u: x.observation.uv[0],
            v: x.observation.uv[1],
            residual_px: x.residual_px,
            weight: 0.0,
            status: "rejected",
        })
        .collect();
    Ok((r.dataset, r.residuals, r.frozen, rejected))
}
