//! What a calibration is asked for and what it gives back: the request, the
//! solver stages, the result and its suspect observations. No computation beyond
//! reading the result.
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::selection::Selection;
use crate::model::trust::Trust;
use crate::model::uncertainty::{CameraUncertainty, UncertaintyError, UnitCovariance};
use crate::solver::problem::{Hold, Problem, SolveReport, SolverSettings, State};

/// What the user asks of one calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub method: Method,
    pub settings: SolverSettings,
    pub gauge: Option<Vec<usize>>,
}

/// Summary of one solver stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Stage {
    pub method: Method,
    pub converged: bool,
    pub iterations: i32,
    pub initial_cost: f64,
    pub final_cost: f64,
    pub seconds: f64,
    pub linear_solver: String,
    pub message: String,
}

impl Stage {
    pub(super) fn new(method: Method, r: &SolveReport) -> Self {
        Stage {
            method,
            converged: r.converged,
            iterations: r.iterations,
            initial_cost: r.initial_cost,
            final_cost: r.final_cost,
            seconds: r.seconds,
            linear_solver: r.linear_solver.clone(),
            message: r.message.clone(),
        }
    }
}

/// The result of a calibration.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub method: Method,
    /// The data actually used (images with too few corners removed).
    pub dataset: Dataset,
    pub state: State,
    pub rmse_px: f64,
    /// Residuals u, v per observation of `dataset`, loss not applied.
    pub residuals: Vec<f64>,
    pub converged: bool,
    /// Zhang's intrinsics, and whether the centred fallback was needed.
    pub initial_intrinsics: Vec<Intrinsics>,
    pub init_fallback: bool,
    pub stages: Vec<Stage>,
    pub gauge: Vec<usize>,
    pub frozen: Vec<usize>,
    pub warnings: Vec<String>,
    pub seconds: f64,
    /// The solver settings used (for the loss behind [`Calibration::suspects`]).
    pub settings: SolverSettings,
    /// Observations removed by outlier rejection (not in `dataset`).
    pub rejected: Vec<Suspect>,
    /// The detector noise the user gave (`[calibration] detector_noise_px`, which
    /// the request carries as `settings.board.noise_px`), for
    /// [`Calibration::trust`]; `None` estimates it.
    pub detector_noise_px: Option<f64>,
    /// With `method = "auto"`: why this method was chosen, and every candidate's figures.
    pub selection: Option<Selection>,
    /// Σ_θ of each camera at unit noise (see `solver::uncertainty`) and, when
    /// the corrections stayed in the normal matrix, the board's σ from the same
    /// pass (what `board.json` reads), or why there is none.
    pub covariance: std::result::Result<UnitCovariance, UncertaintyError>,
    /// The trust and uncertainty figures every writer reports, computed once when
    /// the calibration is done ([`Calibration::assess`]).
    pub assessment: Assessment,
}

/// What a finished calibration's residuals and covariance say at its detector
/// noise: computed once by the pipeline, read by the summary, the files and the
/// reports alike, so that they cannot disagree.
#[derive(Debug, Clone, PartialEq)]
pub struct Assessment {
    /// Noise, bias ratio and G-AIC (`None` without a noise estimate).
    pub trust: Option<Trust>,
    /// Each camera's uncertainty figures at the noise of `trust`, or why there are none.
    pub uncertainty: std::result::Result<Vec<CameraUncertainty>, UncertaintyError>,
}

impl Assessment {
    /// The figures of a calibration not assessed yet.
    pub(super) fn pending() -> Self {
        Assessment {
            trust: None,
            uncertainty: Err(UncertaintyError::Jacobian("not computed".into())),
        }
    }
}

/// An observation the robust loss down-weighted, or (without a loss) one far off.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Suspect {
    pub camera: String,
    pub frame: i64,
    pub corner: usize,
    pub u: f64,
    pub v: f64,
    pub residual_px: f64,
    /// The weight the loss gave it (1 without a loss, 0 when rejected).
    pub weight: f64,
    /// `rejected` (removed by outlier rejection) or `downweighted` (by the loss).
    pub status: &'static str,
}

impl Calibration {
    /// The problem this calibration solved: its data, method, gauge and frozen corners.
    pub fn problem(&self) -> Problem<'_> {
        Problem {
            dataset: &self.dataset,
            method: self.method,
            gauge: self.gauge.clone(),
            frozen: self.frozen.clone(),
            hold: Hold::default(),
        }
    }

    /// Total iterations over all solver stages.
    pub fn iterations(&self) -> i32 {
        self.stages.iter().map(|s| s.iterations).sum()
    }

    /// Observations the Cauchy loss weighted below one half (residual above its
    /// scale), or without a loss those beyond three times the RMSE; worst first.
    pub fn suspects(&self) -> Vec<Suspect> {
        let cauchy = self.settings.loss == crate::solver::problem::Loss::Cauchy;
        let mut out: Vec<Suspect> = self
            .dataset
            .observations
            .iter()
            .zip(self.residuals.chunks(2))
            .filter_map(|(o, r)| {
                let e = (r[0] * r[0] + r[1] * r[1]).sqrt();
                let weight = self.settings.loss_weight(e * o.weight);
                let suspect = if cauchy {
                    weight < 0.5
                } else {
                    e > 3.0 * self.rmse_px
                };
                suspect.then(|| Suspect {
                    camera: self.dataset.cameras[o.camera].name.clone(),
                    frame: self.dataset.frame_ids[o.frame],
                    corner: o.corner,
                    u: o.uv[0],
                    v: o.uv[1],
                    residual_px: e,
                    weight,
                    status: "downweighted",
                })
            })
            .collect();
        out.sort_by(|a, b| b.residual_px.total_cmp(&a.residual_px));
        // The rejected first: they are what outlier rejection removed.
        let mut all = self.rejected.clone();
        all.sort_by(|a, b| b.residual_px.total_cmp(&a.residual_px));
        all.extend(out);
        all
    }

    /// Largest per-image out-of-plane deformation.
    pub fn max_out_of_plane(&self) -> f64 {
        self.frame_bends().into_iter().fold(0.0, f64::max)
    }

    /// Each frame's largest out-of-plane bend over the board's corners, metres.
    pub fn frame_bends(&self) -> Vec<f64> {
        let t = &self.dataset.target;
        self.state
            .deformations
            .iter()
            .zip(&self.state.higher_bends)
            .map(|(d, h)| crate::model::board::max_bend(t, d, h))
            .collect()
    }
}
