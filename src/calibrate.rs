//! The calibration pipeline: Zhang initialisation → `standard` → the chosen method.
use crate::camera::{Intrinsics, Pose};
use crate::deformation::Method;
use crate::error::{Error, Result};
use crate::observations::Dataset;
use crate::problem::{
    choose_gauge, rmse, underobserved_corners, Hold, Problem, SolveReport, SolverSettings, State,
};
use crate::zhang;
use nalgebra::{Matrix3, Vector2};
use std::time::Instant;

/// Fewest corners an image needs to enter the calibration (a homography needs four).
pub const MIN_CORNERS_PER_IMAGE: usize = 4;
/// Fewest images a calibration accepts.
pub const MIN_IMAGES: usize = 3;

/// Relative tolerance of the `standard` warm start before a deformation method.
const WARM_START_TOLERANCE: f64 = 1e-6;

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
    fn new(method: Method, r: &SolveReport) -> Self {
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
}

impl Calibration {
    /// Total iterations over all solver stages.
    pub fn iterations(&self) -> i32 {
        self.stages.iter().map(|s| s.iterations).sum()
    }

    /// Largest per-image out-of-plane deformation.
    pub fn max_out_of_plane(&self) -> f64 {
        self.state
            .deformations
            .iter()
            .map(|d| d.max_out_of_plane(&self.dataset.target))
            .fold(0.0, f64::max)
    }
}

/// Drops images with fewer than [`MIN_CORNERS_PER_IMAGE`] corners, with a warning each.
fn usable_frames(dataset: &Dataset, warnings: &mut Vec<String>) -> Vec<usize> {
    let counts = dataset.counts_per_frame();
    let mut keep = Vec::new();
    for (j, &n) in counts.iter().enumerate() {
        if n >= MIN_CORNERS_PER_IMAGE {
            keep.push(j);
        } else {
            warnings.push(format!(
                "frame {} skipped: {n} corner(s), at least {MIN_CORNERS_PER_IMAGE} needed",
                dataset.frame_ids[j]
            ));
        }
    }
    keep
}

/// Homography of each frame seen by camera 0, `None` where it is degenerate.
fn homographies(dataset: &Dataset) -> Vec<Option<Matrix3<f64>>> {
    let mut board = vec![Vec::new(); dataset.num_frames()];
    let mut image = vec![Vec::new(); dataset.num_frames()];
    for o in dataset.observations.iter().filter(|o| o.camera == 0) {
        let p = dataset.target.nominal(o.corner);
        board[o.frame].push(Vector2::new(p.x, p.y));
        image[o.frame].push(Vector2::new(o.uv[0], o.uv[1]));
    }
    board
        .iter()
        .zip(&image)
        .map(|(b, i)| zhang::homography(b, i))
        .collect()
}

/// Zhang's initialisation of a single camera: intrinsics and one pose per frame.
fn initialise(dataset: &Dataset, warnings: &mut Vec<String>) -> Result<(Dataset, State, bool)> {
    let keep = usable_frames(dataset, warnings);
    let dataset = dataset.subset(&keep);
    let hs = homographies(&dataset);
    let mut good = Vec::new();
    for (j, h) in hs.iter().enumerate() {
        match h {
            Some(_) => good.push(j),
            None => warnings.push(format!(
                "frame {} skipped: its corners are collinear or degenerate",
                dataset.frame_ids[j]
            )),
        }
    }
    if good.len() < MIN_IMAGES {
        return Err(Error::Degenerate(format!(
            "{} usable image(s); a calibration needs at least {MIN_IMAGES}",
            good.len()
        )));
    }
    let dataset = dataset.subset(&good);
    let hs: Vec<Matrix3<f64>> = good.iter().map(|&j| hs[j].expect("kept")).collect();
    let cam = &dataset.cameras[0];
    let (k, fallback) = zhang::initial_intrinsics(&hs, cam.width, cam.height)?;
    if fallback {
        warnings.push(
            "Zhang's closed form was ill-conditioned; started from a centred principal point"
                .into(),
        );
    }
    let poses = hs
        .iter()
        .map(|h| zhang::pose_from_homography(h, &k))
        .collect::<Option<Vec<Pose>>>()
        .ok_or_else(|| {
            Error::Init("a board pose could not be recovered from its homography".into())
        })?;
    let state = State::rigid(vec![k], vec![Pose::identity()], poses, &dataset.target);
    Ok((dataset, state, fallback))
}

/// Runs the whole pipeline on one dataset.
pub fn calibrate(dataset: &Dataset, request: &Request) -> Result<Calibration> {
    let start = Instant::now();
    if dataset.cameras.len() != 1 {
        return Err(Error::Invalid(format!(
            "{} cameras given; this version calibrates one camera at a time",
            dataset.cameras.len()
        )));
    }
    let mut warnings = Vec::new();
    let (dataset, mut state, init_fallback) = initialise(dataset, &mut warnings)?;
    let initial_intrinsics = state.intrinsics.clone();

    let mut stages = Vec::new();
    let standard = Problem {
        dataset: &dataset,
        method: Method::Standard,
        gauge: Vec::new(),
        frozen: Vec::new(),
        hold: Hold::default(),
    };
    // A warm start only needs to be close: the final stage polishes it.
    let warm = if request.method == Method::Standard {
        request.settings.clone()
    } else {
        SolverSettings {
            function_tolerance: request
                .settings
                .function_tolerance
                .max(WARM_START_TOLERANCE),
            parameter_tolerance: request
                .settings
                .parameter_tolerance
                .max(WARM_START_TOLERANCE),
            ..request.settings.clone()
        }
    };
    let report = standard.solve(&mut state, &warm)?;
    stages.push(Stage::new(Method::Standard, &report));

    let (gauge, frozen) = if request.method == Method::Standard {
        (Vec::new(), Vec::new())
    } else {
        let gauge = choose_gauge(&dataset, request.method, request.gauge.as_deref())?;
        let frozen = if request.method.has_correction() {
            underobserved_corners(&dataset)
        } else {
            Vec::new()
        };
        if !frozen.is_empty() {
            warnings.push(format!(
                "{} corner(s) seen in fewer than two images keep a zero correction",
                frozen.len()
            ));
        }
        let problem = Problem {
            dataset: &dataset,
            method: request.method,
            gauge: gauge.clone(),
            frozen: frozen.clone(),
            hold: Hold::default(),
        };
        let report = problem.solve(&mut state, &request.settings)?;
        stages.push(Stage::new(request.method, &report));
        (gauge, frozen)
    };
    let converged = stages.last().map(|s| s.converged).unwrap_or(false);
    if !converged {
        warnings.push(format!(
            "the {} solve did not converge: {}",
            request.method,
            stages.last().map(|s| s.message.as_str()).unwrap_or("")
        ));
    }
    let final_problem = Problem {
        dataset: &dataset,
        method: request.method,
        gauge: gauge.clone(),
        frozen: frozen.clone(),
        hold: Hold::default(),
    };
    let residuals = final_problem
        .evaluate(&state, &request.settings, false)?
        .residuals;
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
        seconds: start.elapsed().as_secs_f64(),
    })
}
