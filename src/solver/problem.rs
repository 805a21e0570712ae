//! Problem assembly: turns a dataset, a method and a parameter state into the
//! Ceres problem behind the bridge, and the solution back into typed values.
use crate::error::{Error, Result};
use crate::model::board::{BoardPriors, Method};
use crate::model::dataset::Dataset;
use crate::model::lens::{Intrinsics, LensModel};
use crate::model::state::Layout;
pub use crate::model::state::State;
use crate::model::target::Target;
use crate::solver::bridge::ffi::{self, LossKind, ProblemData, SolveOptions};

pub use crate::solver::bridge::ffi::{Evaluation, SolveReport};

/// Robust loss choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Loss {
    /// Plain least squares.
    None,
    /// Cauchy loss with `loss_scale_px`.
    Cauchy,
}

/// Which parameter groups are held at their current values.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Hold {
    pub intrinsics: bool,
    pub camera_poses: bool,
    pub corrections: bool,
    pub deformations: bool,
}

/// Solver settings, from `[calibration]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSettings {
    pub loss: Loss,
    pub loss_scale_px: f64,
    pub threads: usize,
    pub max_iterations: u32,
    pub function_tolerance: f64,
    pub gradient_tolerance: f64,
    pub parameter_tolerance: f64,
    /// Hold the gauge corners (always, except to demonstrate the rank defect).
    pub fix_gauge: bool,
    pub verbose: bool,
    /// Differentiate the whole residual in one autodiff piece (slower; the reference
    /// the default chained Jacobian is tested against).
    pub reference_jacobian: bool,
    /// Solve the way deformcal did before its per-view blocks and loss-free
    /// warm-up: one residual block per corner, Ceres' Cauchy loss throughout (slower;
    /// the reference the faster path is checked against).
    pub per_corner_blocks: bool,
    /// Hand each view block to Ceres as one row per Jacobian column and one for
    /// the residual (the same steps on fewer rows); off only to check that.
    pub compress_view_rows: bool,
    /// When a robust solve first runs a warm-up, and with which loss.
    pub warm_up: WarmUp,
    /// Outlier rejection threshold in noise standard deviations (0: off); see
    /// `calibrate::reject_outliers`.
    pub outlier_k: f64,
    /// Priors on the board model and a measured board (all off by default).
    pub board: BoardPriors,
    /// 1σ of the lens prior on the registry's `prior_params` (`[calibration]
    /// lens_prior`; `None`: off). On by default: see [`DEFAULT_LENS_PRIOR`].
    pub lens_prior_sigma: Option<f64>,
}

/// A robust solve's warm-up: far from the optimum the loss down-weights exactly
/// the corners that would pull the parameters in, and the robust solve crawls.
/// The warm-up runs first, with a wider loss or none, when more than `share` of
/// the corners lie beyond the loss's scale; the answer is still the robust
/// solve's from there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmUp {
    /// Share of the corners beyond the loss's scale above which it runs.
    pub share: f64,
    /// Its loss scale as a multiple of the loss's (0: plain least squares).
    pub scale_factor: f64,
}

impl WarmUp {
    /// Most corners far off: a start from Zhang's intrinsics. Plain least squares.
    pub const FAR_START: WarmUp = WarmUp {
        share: 0.5,
        scale_factor: 0.0,
    };
    /// A `dynamic` stage from unbent boards: 5 % of the corners beyond the scale
    /// (those its bends move most). A loss ten times wider, not none, so that a
    /// gross outlier, which the warm-up of a fit already close cannot outweigh,
    /// does not pull it away (plain least squares did, on a kb4 rig). Measured on
    /// 25 `t2` images per lens model (`cargo bench --bench methods -- models`):
    /// `dynamic` takes 2–18 fewer iterations with every model; `static` and
    /// `full`, whose iterations cost 4–8 times more, lost more to the warm-up's
    /// iterations than they saved, so they keep [`WarmUp::FAR_START`].
    pub const FRESH_BENDS: WarmUp = WarmUp {
        share: 0.05,
        scale_factor: 10.0,
    };
}

/// The lens prior's default σ. Weak: at the typical noise it costs about what one
/// corner's residual does, so it only acts where the data leave a parameter free
/// (`opencv8`'s k4–k6: 32 synthetic sets, README "Lens models").
pub const DEFAULT_LENS_PRIOR: f64 = 0.1;

/// The pixel noise that weights the lens prior before the pipeline has estimated
/// it (the first `standard` solve): a typical sub-pixel corner detector's.
pub const PROVISIONAL_NOISE_PX: f64 = 0.1;

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            loss: Loss::Cauchy,
            loss_scale_px: 1.0,
            threads: 1,
            max_iterations: 100,
            function_tolerance: 1e-8,
            gradient_tolerance: 1e-10,
            parameter_tolerance: 1e-6,
            fix_gauge: true,
            verbose: false,
            reference_jacobian: false,
            per_corner_blocks: false,
            compress_view_rows: true,
            warm_up: WarmUp::FAR_START,
            outlier_k: 4.0,
            board: BoardPriors::default(),
            lens_prior_sigma: Some(DEFAULT_LENS_PRIOR),
        }
    }
}

impl SolverSettings {
    /// The settings a config without `[calibration]` keys gets: the defaults
    /// with the board priors estimated from the data ([`BoardPriors::estimated`]).
    pub fn recommended() -> Self {
        SolverSettings {
            board: BoardPriors::estimated(),
            ..SolverSettings::default()
        }
    }

    /// The weight the loss gives an observation whose weighted residual has norm
    /// `r` pixels: ρ'(r²) of Ceres' Cauchy ρ(s) = a²·ln(1 + s/a²), 1 without a loss.
    /// At a robust optimum these are the weights of the equivalent least squares.
    pub fn loss_weight(&self, r: f64) -> f64 {
        match self.loss {
            Loss::None => 1.0,
            Loss::Cauchy => 1.0 / (1.0 + (r / self.loss_scale_px).powi(2)),
        }
    }

    /// Whether the lens prior acts on some camera of `models`.
    pub fn lens_prior_on(&self, models: &[LensModel]) -> bool {
        self.lens_prior_sigma.is_some() && models.iter().any(|m| !m.info().prior_params.is_empty())
    }

    fn options(&self) -> SolveOptions {
        SolveOptions {
            loss: match self.loss {
                Loss::None => LossKind::None,
                Loss::Cauchy => LossKind::Cauchy,
            },
            loss_scale_px: self.loss_scale_px,
            num_threads: self.threads.min(i32::MAX as usize) as i32,
            max_iterations: self.max_iterations.min(i32::MAX as u32) as i32,
            function_tolerance: self.function_tolerance,
            gradient_tolerance: self.gradient_tolerance,
            parameter_tolerance: self.parameter_tolerance,
            fix_gauge: self.fix_gauge,
            verbose: self.verbose,
            reference_jacobian: self.reference_jacobian,
            per_corner_blocks: self.per_corner_blocks,
            compress_view_rows: self.compress_view_rows,
            warm_up_share: self.warm_up.share,
            warm_up_scale_factor: self.warm_up.scale_factor,
            settle_cost_change: 0.0,
        }
    }
}

#[cfg(test)]
thread_local! {
    /// Jacobians evaluated through the bridge on this thread ([`Problem::jacobian`]),
    /// so that a test can see what a step evaluates (per thread: tests run in parallel).
    pub(crate) static JACOBIANS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// One calibration problem: data, method, gauge and what is held fixed.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    pub dataset: &'a Dataset,
    pub method: Method,
    /// Corners whose correction carries the gauge (see [`choose_gauge`]).
    pub gauge: Vec<usize>,
    /// Corners whose correction stays at its value: seen in too few images.
    pub frozen: Vec<usize>,
    pub hold: Hold,
}

impl<'a> Problem<'a> {
    /// The rigid-board problem over `dataset`, nothing held: the first solve of
    /// every method.
    pub fn standard(dataset: &'a Dataset) -> Self {
        Problem {
            dataset,
            method: Method::Standard,
            gauge: Vec::new(),
            frozen: Vec::new(),
            hold: Hold::default(),
        }
    }
}

/// Images observing each corner (any camera counted once per frame).
pub fn frames_per_corner(dataset: &Dataset) -> Vec<usize> {
    // A flag per (frame, corner) rather than a hash set: at 10 000 images this
    // runs on 1.7 M observations in every outlier-rejection round.
    let corners = dataset.target.num_corners();
    let mut seen = vec![false; dataset.num_frames() * corners];
    let mut n = vec![0; corners];
    for o in &dataset.observations {
        let flag = &mut seen[o.frame * corners + o.corner];
        if !*flag {
            *flag = true;
            n[o.corner] += 1;
        }
    }
    n
}

/// Minimum number of images a corner needs for its correction to be estimated.
pub const MIN_VIEWS_PER_CORRECTION: usize = 2;

/// Corners whose correction cannot be estimated (seen in fewer than two images).
pub fn underobserved_corners(dataset: &Dataset) -> Vec<usize> {
    frames_per_corner(dataset)
        .iter()
        .enumerate()
        .filter(|(_, &n)| n < MIN_VIEWS_PER_CORRECTION)
        .map(|(i, _)| i)
        .collect()
}

/// The gauge corners: the requested ones, else the defaults of docs/conventions.md §2, each replaced by
/// the nearest well-observed corner when the default is seen in fewer than two images.
pub fn choose_gauge(
    dataset: &Dataset,
    method: Method,
    requested: Option<&[usize]>,
) -> Result<Vec<usize>> {
    let need = method.gauge_corners();
    if need == 0 {
        return Ok(Vec::new());
    }
    let t = dataset.target;
    let views = frames_per_corner(dataset);
    if let Some(req) = requested {
        let req = &req[..need.min(req.len())];
        if let Some(&bad) = req
            .iter()
            .find(|&&c| c >= t.num_corners() || views[c] < MIN_VIEWS_PER_CORRECTION)
        {
            return Err(Error::Degenerate(format!(
                "gauge corner {bad} is seen in fewer than {MIN_VIEWS_PER_CORRECTION} images; choose others in calibration.gauge_corners"
            )));
        }
        check_gauge_geometry(&t, req)?;
        return Ok(req.to_vec());
    }
    let mut chosen: Vec<usize> = Vec::with_capacity(need);
    for &d in &t.default_gauge()[..need] {
        let (dr, dc) = ((d / t.cols) as i64, (d % t.cols) as i64);
        let best = (0..t.num_corners())
            .filter(|&c| views[c] >= MIN_VIEWS_PER_CORRECTION && !chosen.contains(&c))
            .min_by_key(|&c| {
                let (r, col) = ((c / t.cols) as i64, (c % t.cols) as i64);
                ((r - dr).pow(2) + (col - dc).pow(2), c)
            })
            .ok_or_else(|| {
                Error::Degenerate(
                    "too few corners are seen in two or more images to fix the gauge".into(),
                )
            })?;
        chosen.push(best);
    }
    check_gauge_geometry(&t, &chosen)?;
    Ok(chosen)
}

fn check_gauge_geometry(t: &Target, corners: &[usize]) -> Result<()> {
    let p: Vec<_> = corners.iter().map(|&c| t.nominal(c)).collect();
    for i in 0..p.len() {
        for k in 0..i {
            if corners[i] == corners[k] {
                return Err(Error::Degenerate(format!(
                    "gauge corner {} is given twice",
                    corners[i]
                )));
            }
        }
    }
    if p.len() == 3 && (p[1] - p[0]).cross(&(p[2] - p[0])).norm() < 1e-12 {
        return Err(Error::Degenerate(format!(
            "gauge corners {corners:?} are collinear; the static gauge needs three non-collinear corners"
        )));
    }
    Ok(())
}

impl Problem<'_> {
    /// The buffer layout of this problem's parameters.
    pub fn layout(&self) -> Layout {
        let d = self.dataset;
        let lenses: Vec<LensModel> = d.cameras.iter().map(|c| c.model).collect();
        Layout::new(
            &lenses,
            d.num_frames(),
            self.method.info().frame_params,
            d.target.num_corners(),
        )
    }

    fn data(
        &self,
        state: &State,
        layout: &Layout,
        settings: &SolverSettings,
    ) -> Result<ProblemData> {
        let d = self.dataset;
        let t = d.target;
        let params = layout
            .pack(state)
            .ok_or_else(|| Error::Invalid("parameter state does not match the dataset".into()))?;
        let held: Vec<bool> = d.cameras.iter().flat_map(|c| c.held()).collect();
        let n = d.observations.len();
        let mut data = ProblemData {
            board_model: self.method.name().into(),
            num_cameras: d.cameras.len(),
            num_frames: d.num_frames(),
            num_corners: t.num_corners(),
            board: settings
                .board
                .board_points(&t)
                .iter()
                .flat_map(|p| [p.x, p.y, p.z])
                .collect(),
            obs_camera: Vec::with_capacity(n),
            obs_frame: Vec::with_capacity(n),
            obs_corner: Vec::with_capacity(n),
            obs_uv: Vec::with_capacity(2 * n),
            obs_weight: Vec::new(),
            lens_models: layout.lens_models.iter().map(|m| m.name().into()).collect(),
            params,
            intrinsics_offsets: layout
                .intrinsics_offsets
                .iter()
                .map(|&o| o as u32)
                .collect(),
            intrinsics_held: held,
            camera_poses_offset: layout.camera_poses as u32,
            frames_offset: layout.frames as u32,
            frame_stride: layout.frame_stride as u32,
            corrections_offset: layout.corrections as u32,
            gauge_corners: self.gauge.iter().map(|&c| c as u32).collect(),
            frozen_corners: self.frozen.iter().map(|&c| c as u32).collect(),
            hold_intrinsics: self.hold.intrinsics,
            hold_camera_poses: self.hold.camera_poses,
            hold_corrections: self.hold.corrections,
            hold_deformations: self.hold.deformations,
            ..self.priors(settings)
        };
        for o in &d.observations {
            data.obs_camera.push(o.camera as u32);
            data.obs_frame.push(o.frame as u32);
            data.obs_corner.push(o.corner as u32);
            data.obs_uv.extend_from_slice(&o.uv);
        }
        if d.observations.iter().any(|o| o.weight != 1.0) {
            data.obs_weight = d.observations.iter().map(|o| o.weight).collect();
        }
        Ok(data)
    }

    /// The priors' part of the problem data (`cpp/priors.h`; empty where off).
    fn priors(&self, settings: &SolverSettings) -> ProblemData {
        let b = &settings.board;
        let t = self.dataset.target;
        let info = self.method.info();
        let mut d = ProblemData {
            lens_prior_weight: self.lens_prior_weights(settings),
            ..ProblemData::default()
        };
        if b.noise_px.is_none() || !b.any() {
            return d;
        }
        if info.corner_params > 0 {
            d.correction_prior_weight = b.correction_weights(t.num_corners());
        }
        if info.frame_params > 0 {
            d.bend_prior_weight = b.bend_weights(&t, info.frame_params, b.bend_sigma_m);
            d.bend_smoothness_weight = b.bend_weights(&t, info.frame_params, b.smoothness_sigma_m);
            // Robust: a change of more than about 1σ (shuffled stills, a cut in
            // the video) is not pulled towards its neighbour.
            d.bend_smoothness_loss = b.noise_px.unwrap_or(0.0);
        }
        d
    }

    /// Weights σ_noise/σ of the lens prior per value of the intrinsics section
    /// (empty: no camera's model has one, or it is off). Before the noise is
    /// estimated, [`PROVISIONAL_NOISE_PX`] stands in for it.
    pub fn lens_prior_weights(&self, settings: &SolverSettings) -> Vec<f64> {
        let Some(sigma) = settings.lens_prior_sigma else {
            return Vec::new();
        };
        let models = &self.layout().lens_models;
        if models.iter().all(|m| m.info().prior_params.is_empty()) {
            return Vec::new();
        }
        let w = settings.board.noise_px.unwrap_or(PROVISIONAL_NOISE_PX) / sigma;
        models
            .iter()
            .flat_map(|m| {
                let prior = m.info().prior_params;
                m.param_names()
                    .iter()
                    .map(move |p| if prior.contains(p) { w } else { 0.0 })
            })
            .collect()
    }

    /// Refines `state` in place; an unusable solve is an error, a non-converged one is reported.
    pub fn solve(&self, state: &mut State, settings: &SolverSettings) -> Result<SolveReport> {
        self.solve_settling(state, settings, 0.0)
    }

    /// [`Problem::solve`] from next to the optimum (a re-solve after outlier
    /// rejection): it stops, converged, after a successful step that changed
    /// the cost by at most `settle` of it (see `SolveOptions::settle_cost_change`).
    pub fn resolve(
        &self,
        state: &mut State,
        settings: &SolverSettings,
        settle: f64,
    ) -> Result<SolveReport> {
        self.solve_settling(state, settings, settle)
    }

    fn solve_settling(
        &self,
        state: &mut State,
        settings: &SolverSettings,
        settle: f64,
    ) -> Result<SolveReport> {
        let what = format!("{} method", self.method);
        let settings = SolverSettings {
            function_tolerance: settings.function_tolerance
                * self.method.info().function_tolerance_scale,
            ..settings.clone()
        };
        let options = SolveOptions {
            settle_cost_change: settle,
            ..settings.options()
        };
        self.run(state, &settings, options, ffi::solve, &what)
    }

    /// The same as [`Problem::solve`] for a pose-only refit (everything but the
    /// board poses held, no loss, as the protocol's test error): each frame's pose
    /// solved on its own to round-off, without a Ceres problem; several times faster.
    /// Other problems are refused.
    pub fn refit_poses(&self, state: &mut State, settings: &SolverSettings) -> Result<SolveReport> {
        self.run(
            state,
            settings,
            settings.options(),
            ffi::refit_poses,
            "the pose refit",
        )
    }

    /// Prepares [`Problem::refit_poses`] from `state` for refits under many
    /// intrinsics ([`PreparedRefit`]); refused where `refit_poses` is.
    pub fn prepare_pose_refit(
        &self,
        state: &State,
        settings: &SolverSettings,
    ) -> Result<PreparedRefit> {
        let layout = self.layout();
        let data = self.data(state, &layout, settings)?;
        let refit = ffi::prepare_pose_refit(&data, &settings.options())
            .map_err(|e| Error::Problem(e.what().to_string()))?;
        Ok(PreparedRefit { refit })
    }

    /// Runs one of the bridge's solvers on this problem from `state` and unpacks
    /// the result into it; `what` names the solve in the error of an unusable one.
    fn run(
        &self,
        state: &mut State,
        settings: &SolverSettings,
        options: SolveOptions,
        solver: fn(
            &mut ProblemData,
            &SolveOptions,
        ) -> std::result::Result<SolveReport, cxx::Exception>,
        what: &str,
    ) -> Result<SolveReport> {
        let layout = self.layout();
        let mut data = self.data(state, &layout, settings)?;
        let mut report = solver(&mut data, &options).map_err(|e| {
            Error::Problem(format!(
                "{}{}",
                e.what(),
                self.likely_input(e.what(), settings)
            ))
        })?;
        if !report.usable {
            return Err(Error::Solver(format!(
                "{what} failed: {}{}",
                report.message,
                self.likely_input(&report.message, settings)
            )));
        }
        self.unweight(&mut report.residuals);
        layout.unpack(&data.params, state);
        Ok(report)
    }

    /// Where a solve that could not evaluate its residuals most likely got the
    /// values that broke them (appended to Ceres' message, which names no
    /// input): a measured board first, as it is the only input read whole
    /// into the board points. Empty for other failures.
    fn likely_input(&self, message: &str, settings: &SolverSettings) -> String {
        if !message.contains("evaluation failed") && !message.contains("could not be evaluated") {
            return String::new();
        }
        let board = if settings.board.geometry.is_some() {
            "the measured board of [target] geometry (board.json), "
        } else {
            ""
        };
        format!(
            "; a residual was not finite: check {board}target.spacing ({} m) and the observations' pixels",
            self.dataset.target.spacing
        )
    }

    /// Residuals in pixels (observed − projected, per observation u then v, weights
    /// undone) and optionally the Jacobian of the weighted residuals.
    pub fn evaluate(
        &self,
        state: &State,
        settings: &SolverSettings,
        with_jacobian: bool,
    ) -> Result<Evaluation> {
        let data = self.data(state, &self.layout(), settings)?;
        let mut e = ffi::evaluate(&data, &settings.options(), with_jacobian)
            .map_err(|e| Error::Problem(e.what().to_string()))?;
        self.unweight(&mut e.residuals);
        Ok(e)
    }

    /// The weighted residuals' Jacobian over the free parameters, rows in
    /// observation order (two per observation), and the residuals in pixels (weights
    /// undone). The same numbers as [`Problem::evaluate`]'s, several times faster; `cost` is NaN.
    pub fn jacobian(&self, state: &State, settings: &SolverSettings) -> Result<Evaluation> {
        #[cfg(test)]
        JACOBIANS.with(|n| n.set(n.get() + 1));
        let data = self.data(state, &self.layout(), settings)?;
        let j = ffi::jacobian(&data, &settings.options())
            .map_err(|e| Error::Problem(e.what().to_string()))?;
        let mut e = Evaluation {
            cost: f64::NAN,
            residuals: j.residual_values().to_vec(),
            jacobian_rows: j.row_offsets().len().saturating_sub(1),
            jacobian_cols: j.num_cols(),
            jacobian_row_ptr: j.row_offsets().to_vec(),
            jacobian_col_idx: j.column_indices().to_vec(),
            jacobian_values: j.entries().to_vec(),
            jacobian_col_param: j.column_parameters().to_vec(),
        };
        self.unweight(&mut e.residuals);
        Ok(e)
    }

    /// Residuals in pixels from weighted ones.
    fn unweight(&self, residuals: &mut [f64]) {
        for (r, o) in residuals.chunks_mut(2).zip(&self.dataset.observations) {
            r[0] /= o.weight;
            r[1] /= o.weight;
        }
    }
}

/// A pose-only refit prepared once ([`Problem::prepare_pose_refit`]): the
/// frames' corners and held board points are kept in C++ with each frame's
/// optimum under the prepared intrinsics, and every refit starts from those
/// optima moved to first order by its intrinsics, so one serves many threads.
pub struct PreparedRefit {
    refit: cxx::UniquePtr<ffi::PoseRefit>,
}

impl PreparedRefit {
    /// The RMSE of the unweighted residuals (as [`rmse`] of a refit's
    /// residuals) after every frame's pose is refitted under `intrinsics`.
    pub fn rmse_px(&self, intrinsics: &[Intrinsics]) -> Result<f64> {
        let params: Vec<f64> = intrinsics
            .iter()
            .flat_map(|k| k.params().to_vec())
            .collect();
        self.refit
            .rmse_px(&params)
            .map_err(|e| Error::Solver(format!("the pose refit failed: {}", e.what())))
    }
}

/// RMSE over observations of per-point Euclidean residuals (docs/conventions.md §3 `rmse_px`).
pub fn rmse(residuals: &[f64]) -> f64 {
    let n = residuals.len() / 2;
    if n == 0 {
        return f64::NAN;
    }
    (residuals.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt()
}
