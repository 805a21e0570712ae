//! The requested method's own solve after the warm start: its gauge and frozen
//! corners, the smoothness prior's order test, and the priors with σ = "auto".
use super::types::{Request, Stage};
use super::warm::warm_start_settings;
use crate::error::Result;
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::solver::auto_prior::{AutoPrior, Estimate};
use crate::solver::problem::{
    choose_gauge, underobserved_corners, Hold, Problem, SolverSettings, State, WarmUp,
};
use crate::solver::{auto_prior, robust};

/// The problem of `method` with its gauge and frozen corners, nothing else held.
fn method_problem<'a>(
    dataset: &'a Dataset,
    method: Method,
    gauge: &[usize],
    frozen: &[usize],
) -> Problem<'a> {
    Problem {
        dataset,
        method,
        gauge: gauge.to_vec(),
        frozen: frozen.to_vec(),
        hold: Hold::default(),
    }
}

/// What a method's solve hands back: its gauge, frozen corners and residuals.
pub(super) type Solved = (Vec<usize>, Vec<usize>, Vec<f64>);

/// With `static_prior_mm` or `bend_prior_mm = "auto"`: each such prior's σ
/// from the solve without them (`free`, at `state`), then the method solved
/// again with each in turn (static first), each kept as
/// [`with_auto_prior`] decides.
pub(super) fn with_auto_priors(
    dataset: &Dataset,
    state: &mut State,
    request: &mut Request,
    free: Solved,
    stages: &mut Vec<Stage>,
    warnings: &mut Vec<String>,
) -> Result<Solved> {
    let board = &request.settings.board;
    let wanted: Vec<AutoPrior> = AutoPrior::ALL
        .into_iter()
        .filter(|p| p.wanted(board, request.method))
        .collect();
    let Some(noise) = board.noise_px.filter(|_| !wanted.is_empty()) else {
        return Ok(free);
    };
    let problem = method_problem(dataset, request.method, &free.0, &free.1);
    let all = AutoPrior::estimate_all(&wanted, &problem, state, &request.settings, noise);
    let mut estimates = Vec::new();
    for (prior, estimate) in wanted.into_iter().zip(all) {
        match estimate {
            Some(e) => estimates.push((prior, e)),
            None => warnings.push(format!(
                "{} = \"auto\": the solve gives no estimate of the prior's σ; the prior is left off",
                prior.key()
            )),
        }
    }
    let mut solved = free;
    for estimate in estimates {
        solved = with_auto_prior(dataset, state, request, estimate, solved, stages, warnings)?;
    }
    Ok(solved)
}

/// Solves again with the estimated prior and keeps that unless it fits the
/// observations clearly worse than the solve without it (`before`). A prior
/// the values agree with costs each value it holds 1/(1 + hσ²) σ̂² of squared
/// residual on average (h its information): at most n over n values, with a
/// spread of at most √(2n) (a χ² of n degrees when σ → 0, a rigid board's
/// case, which a bound of n alone rejected every other time). A safety net: a
/// prior the data contradict (as one weighted by a wild noise estimate did,
/// holding 7 mm bends flat) is dropped and the solve without it stands.
fn with_auto_prior(
    dataset: &Dataset,
    state: &mut State,
    request: &mut Request,
    (prior, estimate): (AutoPrior, Estimate),
    before: Solved,
    stages: &mut Vec<Stage>,
    warnings: &mut Vec<String>,
) -> Result<Solved> {
    let saved = state.clone();
    prior.set(&mut request.settings.board, Some(estimate.sigma));
    let held = solve_method(dataset, state, request, false, stages, warnings)?;
    let sum_sq = |r: &[f64]| -> f64 {
        crate::model::trust::weighted(dataset, r)
            .iter()
            .map(|v| v * v)
            .sum()
    };
    let noise = request.settings.board.noise_px.unwrap_or(f64::NAN);
    let cost = (sum_sq(&held.2) - sum_sq(&before.2)) / (noise * noise);
    let n = estimate.values as f64;
    let bound = n + 4.0 * (2.0 * n).sqrt();
    if cost <= bound {
        return Ok(held);
    }
    *state = saved;
    prior.set(&mut request.settings.board, None);
    warnings.push(format!(
        "{} = \"auto\": a prior of {:.4} mm fits the observations worse by {cost:.0} σ̂² (more than the {bound:.0} its {} held values explain); the prior is left off",
        prior.key(),
        estimate.sigma * 1e3,
        estimate.values
    ));
    Ok(before)
}
/// Decides, from the frames' own bends at `state`, whether the smoothness prior
/// acts: only where those bends follow the frame order (`auto_prior::order_test`;
/// shuffled stills or a board that does not flex smoothly get no prior, whatever
/// σ was asked for), and with the σ they show for `bend_smoothness = "auto"`.
/// The outcome is written into `request` (the σ, or none), so later solves and
/// the summary use it; each dropped prior is a warning.
fn resolve_smoothness(
    problem: &Problem,
    state: &State,
    own: &SolverSettings,
    request: &mut Request,
    warnings: &mut Vec<String>,
) {
    let board = &mut request.settings.board;
    let key = "bend_smoothness";
    let test =
        auto_prior::frame_bends_at_reach(problem, state).and_then(|b| auto_prior::order_test(&b));
    let Some(test) = test else {
        if board.smoothness_auto {
            warnings.push(format!(
                "{key} = \"auto\": the frames' bends give nothing to compare (fewer than three frames, or no bend); the prior is left off"
            ));
            board.smoothness_sigma_m = None;
            board.smoothness_auto = false;
        }
        return;
    };
    if !test.in_order() {
        warnings.push(format!(
            "{key}: consecutive frames' bends differ about as much as random pairs of frames do \
             (ratio {:.2}, p = {:.2}): the frames are not in time order, or the board does not flex smoothly; \
             the smoothness prior is left off",
            test.ratio, test.p_value
        ));
        board.smoothness_sigma_m = None;
        board.smoothness_auto = false;
        return;
    }
    if board.smoothness_auto && board.smoothness_sigma_m.is_none() {
        let noise = board.noise_px.unwrap_or(f64::NAN);
        match auto_prior::estimate_smoothness_sigma(problem, state, own, noise) {
            Some(e) => board.smoothness_sigma_m = Some(e.sigma),
            None => {
                warnings.push(format!(
                    "{key} = \"auto\": the solve gives no estimate of the prior's σ; the prior is left off"
                ));
                board.smoothness_auto = false;
            }
        }
    }
}

/// Solves the requested (non-`standard`) method; returns its gauge, frozen corners, residuals.
/// `from_standard`: `state` is `standard`'s result, never the method's optimum,
/// so a stage that takes no step has failed; a repeat (with an estimated prior)
/// starts from the method's own result and may stop at once.
pub(super) fn solve_method(
    dataset: &Dataset,
    state: &mut State,
    request: &mut Request,
    from_standard: bool,
    stages: &mut Vec<Stage>,
    warnings: &mut Vec<String>,
) -> Result<Solved> {
    let gauge = choose_gauge(dataset, request.method, request.gauge.as_deref())?;
    let frozen = if request.method.has_correction() {
        underobserved_corners(dataset)
    } else {
        Vec::new()
    };
    if !frozen.is_empty() {
        warnings.push(format!(
            "{} corner(s) seen in fewer than two images keep a zero correction",
            frozen.len()
        ));
    }
    crate::solver::identifiable::check(dataset, request.method, &request.settings, &frozen)?;
    let problem = method_problem(dataset, request.method, &gauge, &frozen);
    // The first solve of a method without per-corner corrections starts from
    // unbent boards (see `WarmUp::FRESH_BENDS`).
    let fresh = |mut s: SolverSettings| {
        if !request.method.has_correction() {
            s.warm_up = WarmUp::FRESH_BENDS;
        }
        s
    };
    let mut settings = fresh(request.settings.clone());
    let mut first_stage = from_standard;
    let board = &request.settings.board;
    if request.method.has_paraboloid()
        && (board.smoothness_sigma_m.is_some() || board.smoothness_auto)
    {
        // The smoothness prior is robust, so not convex: started from unbent
        // frames (all alike, in its quadratic core) it holds bends the data want
        // apart. Each frame's own bend first, then the frames tied.
        let mut own = fresh(warm_start_settings(request, problem.dataset));
        own.board.smoothness_sigma_m = None;
        let report = problem.solve(state, &own)?;
        robust::check_stage(request.method, &report, first_stage)?;
        stages.push(Stage::new(request.method, &report));
        // A repeat keeps the first call's verdict and σ: the same order test
        // again is work twice over, and a second verdict could differ.
        if from_standard {
            resolve_smoothness(&problem, state, &own, request, warnings);
        }
        settings = request.settings.clone();
        // Tying frames whose own bends already agree may take no step.
        first_stage = false;
    }
    let report = problem.solve(state, &settings)?;
    robust::check_stage(request.method, &report, first_stage)?;
    stages.push(Stage::new(request.method, &report));
    Ok((gauge, frozen, report.residuals))
}
