//! The test error: a calibration's intrinsics held on the reference set while
//! only the board poses are refitted (the paper's test RMSE).
use crate::error::{Error, Result};
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::state::State;
use crate::solver::calibrate::Calibration;
use crate::solver::problem::{rmse, Hold, PreparedRefit, Problem, SolverSettings};

/// `test_rmse_px` of camera `k`: its views of the reference set refitted with only
/// the board poses free, the given intrinsics and the reference static correction
/// held.  The refit is plain least squares: the reference set is clean, and the
/// RMSE is a least-squares figure.  With `settings.per_corner_blocks` it runs on
/// the previous path (one Ceres problem over all frames), which converges to the
/// same optimum within its solver tolerances.  The protocol prepares the refit
/// once per camera instead ([`TestError`]).
pub fn test_rmse(
    reference: &Calibration,
    k: usize,
    intrinsics: &Intrinsics,
    settings: &SolverSettings,
) -> Result<f64> {
    if !settings.per_corner_blocks {
        return TestError::new(reference, k, settings)?.rmse_px(intrinsics);
    }
    let settings = &refit_settings(settings);
    let dataset = reference_views(reference, k)?;
    let mut state = refit_start(reference, k, intrinsics);
    let problem = refit_problem(reference, &dataset);
    let report = problem.solve(&mut state, settings)?;
    if report.usable && !report.residuals.is_empty() {
        return Ok(rmse(&report.residuals));
    }
    Ok(rmse(&problem.evaluate(&state, settings, false)?.residuals))
}

/// The test error of one reference camera, its refit prepared once and run for
/// every calibration measured against it: only the board poses are free and
/// there is no loss, so every frame is its own 6-parameter problem, refitted on
/// its own from the reference's pose (the joint Ceres solve of
/// [`test_rmse`]'s previous path is what it is tested against).
pub struct TestError {
    refit: PreparedRefit,
}

impl TestError {
    /// Prepares camera `k`'s refit on the reference set.
    pub fn new(reference: &Calibration, k: usize, settings: &SolverSettings) -> Result<Self> {
        let dataset = reference_views(reference, k)?;
        let state = refit_start(reference, k, &reference.state.intrinsics[k]);
        let refit = refit_problem(reference, &dataset)
            .prepare_pose_refit(&state, &refit_settings(settings))?;
        Ok(TestError { refit })
    }

    /// `test_rmse_px` under `intrinsics`.
    pub fn rmse_px(&self, intrinsics: &Intrinsics) -> Result<f64> {
        self.refit.rmse_px(std::slice::from_ref(intrinsics))
    }
}

/// The refit's settings: plain least squares.
fn refit_settings(settings: &SolverSettings) -> SolverSettings {
    SolverSettings {
        loss: crate::solver::problem::Loss::None,
        ..settings.clone()
    }
}

/// Camera `k`'s views of the reference set, as a one-camera dataset.
fn reference_views(reference: &Calibration, k: usize) -> Result<Dataset> {
    let r = &reference.dataset;
    let dataset = Dataset {
        cameras: vec![r.cameras[k].clone()],
        observations: r
            .observations
            .iter()
            .filter(|o| o.camera == k)
            .map(|o| crate::model::dataset::Observation { camera: 0, ..*o })
            .collect(),
        ..r.clone()
    };
    if dataset.observations.is_empty() {
        return Err(Error::Degenerate(format!(
            "camera {} has no reference observations",
            r.cameras[k].name
        )));
    }
    Ok(dataset)
}

/// The refit's start: the reference's board poses seen from camera `k`.
fn refit_start(reference: &Calibration, k: usize, intrinsics: &Intrinsics) -> State {
    let pi = reference.state.camera_poses[k];
    State {
        intrinsics: vec![*intrinsics],
        camera_poses: vec![crate::model::pose::Pose::identity()],
        frame_poses: reference
            .state
            .frame_poses
            .iter()
            .map(|p| pi.compose(p))
            .collect(),
        ..reference.state.clone()
    }
}

/// Everything but the board poses held, the reference's static correction among it.
fn refit_problem<'a>(reference: &Calibration, dataset: &'a Dataset) -> Problem<'a> {
    Problem {
        dataset,
        method: Method::Static,
        gauge: reference.gauge.clone(),
        frozen: reference.frozen.clone(),
        hold: Hold {
            intrinsics: true,
            camera_poses: true,
            corrections: true,
            deformations: true,
        },
    }
}
