//! The warm start every method shares: the data checked, the initialisation
//! and the first `standard` solve, with stray frames re-posed and the lens
//! registry's second start tried.
use super::init::{coverage_warnings, initialise};
use super::types::{Request, Stage};
use crate::error::Result;
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::metrics::mapping_error;
use crate::solver::problem::{Problem, SolveReport, SolverSettings, State};
use crate::solver::{repose, robust};
use std::time::Instant;

/// Relative tolerance of the `standard` warm start before a deformation method.
const WARM_START_TOLERANCE: f64 = 1e-3;
/// A second start whose loose solve ends this close to the converged first
/// solve (mapping error, px) ends where the first did (`ends_alike`).
const SAME_END_PX: f64 = 0.03;
/// Tolerances of that loose solve. At 1e-3 (a warm start's) it stopped after one
/// robust iteration on the `ds` bench set, 0.07 px from where both starts end; at
/// 1e-5 it stops 0.003 px from there, a third of the iterations short of a full solve.
const PROBE_TOLERANCE: f64 = 1e-5;

/// The settings of the first `standard` solve: the request's where its result is
/// the answer, loose where a later solve polishes it: a deformation method's
/// stage, or `standard` again once the noise that weights the lens prior is
/// estimated.
pub(super) fn warm_start_settings(request: &Request, dataset: &Dataset) -> SolverSettings {
    if warm_start_is_loose(request, dataset) {
        // A warm start only needs to be close: the final stage polishes it.
        loose(&request.settings, WARM_START_TOLERANCE)
    } else {
        request.settings.clone()
    }
}

/// Whether a later solve polishes the first `standard` solve (see
/// [`warm_start_settings`]), which is then loose and the same for every method.
pub(super) fn warm_start_is_loose(request: &Request, dataset: &Dataset) -> bool {
    request.method != Method::Standard || lens_prior_reweighted(request, dataset)
}

/// `settings` with function and parameter tolerances no tighter than `tolerance`.
pub(super) fn loose(settings: &SolverSettings, tolerance: f64) -> SolverSettings {
    SolverSettings {
        function_tolerance: settings.function_tolerance.max(tolerance),
        parameter_tolerance: settings.parameter_tolerance.max(tolerance),
        ..settings.clone()
    }
}

/// Whether the lens prior is weighted by a noise estimated after the first
/// `standard` solve (it acts, and no noise is configured; see
/// [`with_prior_noise`]): that solve is then polished by a second one.
pub(super) fn lens_prior_reweighted(request: &Request, dataset: &Dataset) -> bool {
    let models: Vec<_> = dataset.cameras.iter().map(|c| c.model).collect();
    request.settings.lens_prior_on(&models) && request.settings.board.noise_px.is_none()
}

/// The first solve again from the lens registry's second start of each camera
/// that has one (`LensInfo::second_start`) and fixes none of the values it moves,
/// keeping whichever of the two ends at the lower cost; `first` when no camera
/// has one, the second solve fails, or its loose solve comes close to where the
/// converged first one ended (`ends_alike`: the work of converging it again is
/// saved). Every solve that returns a report is recorded as a stage.
pub(super) fn from_second_start(
    problem: &Problem,
    start: &State,
    state: &mut State,
    first: SolveReport,
    request: &Request,
    stages: &mut Vec<Stage>,
) -> Result<SolveReport> {
    let mut other = start.clone();
    let mut any = false;
    for (k, camera) in other.intrinsics.iter_mut().zip(&problem.dataset.cameras) {
        let Some(second) = k.model().info().second_start else {
            continue;
        };
        let moved = second(k);
        // A parameter the user fixed keeps its initial value: no second start
        // that would move it.
        let names = k.model().info().params;
        let holds_fixed = names
            .iter()
            .zip(k.params().iter().zip(moved.params()))
            .all(|(name, (a, b))| a == b || !camera.fix.iter().any(|f| f == name));
        if holds_fixed {
            *k = moved;
            any = true;
        }
    }
    if !any {
        return Ok(first);
    }
    let warm = warm_start_settings(request, problem.dataset);
    // A looser solve first tells whether the second start ends where the first
    // did; only a start that heads elsewhere is converged.
    let probe = loose(&warm, PROBE_TOLERANCE);
    let Ok(report) = problem.solve(&mut other, &probe) else {
        return Ok(first);
    };
    // Recorded either way: the stages list every solve.
    stages.push(Stage::new(Method::Standard, &report));
    if robust::check_stage(Method::Standard, &report, true).is_err() {
        return Ok(first);
    }
    let converge = probe.function_tolerance > warm.function_tolerance
        || probe.parameter_tolerance > warm.parameter_tolerance;
    // Only a converged first solve is compared: two loose solves may stop at
    // costs apart by tens of per cent where their intrinsics agree.
    if converge && ends_alike(problem, state, &other) {
        return Ok(first);
    }
    let report = if converge {
        let Ok(report) = problem.solve(&mut other, &warm) else {
            return Ok(first);
        };
        stages.push(Stage::new(Method::Standard, &report));
        if robust::check_stage(Method::Standard, &report, false).is_err() {
            return Ok(first);
        }
        report
    } else {
        report
    };
    let Ok(report) = with_stray_frames_reposed(problem, &mut other, report, &warm, stages) else {
        return Ok(first);
    };
    if report.final_cost.partial_cmp(&first.final_cost) != Some(std::cmp::Ordering::Less) {
        return Ok(first);
    }
    *state = other;
    Ok(report)
}

/// Whether a loose solve from the second start (`other`) has come within
/// [`SAME_END_PX`] of the converged first solve (`first`) on every camera.
/// On 576 `ds` calibrations (three true lenses, rigid and bent boards; README,
/// "Lens models") the loose solves that went on to the first's end stopped at most
/// 0.020 px from it; those that went elsewhere were 0.09 px or more away.
fn ends_alike(problem: &Problem, first: &State, other: &State) -> bool {
    first
        .intrinsics
        .iter()
        .zip(&other.intrinsics)
        .zip(&problem.dataset.cameras)
        .all(|((a, b), cam)| mapping_error(a, b, cam.width, cam.height) < SAME_END_PX)
}

/// At most this many rounds of re-posing frames and repeating the first solve.
/// A round poses only the frames that the intrinsics of the round before unproject
/// well enough; with those frames back, the next intrinsics pose the rest (a bent
/// `ds` set needed four rounds).
const REPOSE_ROUNDS: usize = 5;

/// The `standard` solve repeated after the frames it left in a wrong pose basin
/// get a pose from its solved intrinsics (`solver::repose`); `report` when no
/// frame is re-posed. Every repeat is recorded as a stage.
fn with_stray_frames_reposed(
    problem: &Problem,
    state: &mut State,
    mut report: SolveReport,
    settings: &SolverSettings,
    stages: &mut Vec<Stage>,
) -> Result<SolveReport> {
    for _ in 0..REPOSE_ROUNDS {
        if repose::repose_stray_frames(problem, state, &report.residuals, settings)? == 0 {
            break;
        }
        report = problem.solve(state, settings)?;
        robust::check_stage(Method::Standard, &report, false)?;
        stages.push(Stage::new(Method::Standard, &report));
    }
    Ok(report)
}

/// What a calibration has once its first `standard` solve is done: the data
/// kept, the initialisation, and that solve from one or two starts. Every
/// deformation method computes the same one from the same data (see
/// [`warm_start_settings`]), so [`SharedWarmStart`] computes it once for them.
#[derive(Debug, Clone)]
pub(super) struct WarmStart {
    /// The dataset and settings it was computed from, to recognise its users.
    pub(super) input: Dataset,
    pub(super) settings: SolverSettings,
    pub(super) dataset: Dataset,
    pub(super) state: State,
    pub(super) init_fallback: bool,
    pub(super) initial_intrinsics: Vec<Intrinsics>,
    pub(super) warnings: Vec<String>,
    pub(super) stages: Vec<Stage>,
    pub(super) report: SolveReport,
    pub(super) seconds: f64,
}

/// [`fit`]'s first part: the data checked, the initialisation and the first
/// `standard` solve (stray frames re-posed, a second start where the lens has one).
pub(super) fn warm_start(input: &Dataset, request: &Request) -> Result<WarmStart> {
    let start = Instant::now();
    let mut warnings = Vec::new();
    let dataset = robust::drop_outside_image(input, &mut warnings)?;
    let dataset = robust::drop_inconsistent_views(&dataset, &mut warnings)?;
    let (dataset, mut state, init_fallback) = initialise(&dataset, &mut warnings)?;
    coverage_warnings(&dataset, &mut warnings);
    crate::solver::identifiable::check(&dataset, Method::Standard, &request.settings, &[])?;
    let initial_intrinsics = state.intrinsics.clone();

    let mut stages = Vec::new();
    let standard = Problem::standard(&dataset);
    let initial = state.clone();
    let warm = warm_start_settings(request, &dataset);
    let report = standard.solve(&mut state, &warm)?;
    robust::check_stage(Method::Standard, &report, true)?;
    stages.push(Stage::new(Method::Standard, &report));
    let report = with_stray_frames_reposed(&standard, &mut state, report, &warm, &mut stages)?;
    let report = from_second_start(
        &standard,
        &initial,
        &mut state,
        report,
        request,
        &mut stages,
    )?;
    Ok(WarmStart {
        input: input.clone(),
        settings: warm,
        dataset,
        state,
        init_fallback,
        initial_intrinsics,
        warnings,
        stages,
        report,
        seconds: start.elapsed().as_secs_f64(),
    })
}
