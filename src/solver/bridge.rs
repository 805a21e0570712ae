//! The one cxx bridge between Rust and the Ceres core in `cpp/`.

#[cxx::bridge(namespace = "deformcal::ffi")]
pub mod ffi {
    /// Robust loss on the squared pixel residual.
    #[derive(Debug)]
    enum LossKind {
        None,
        Cauchy,
    }

    /// Observations and the parameter buffer of one problem; parameters are
    /// updated in place. The buffer's layout is `model::state::Layout`'s.
    #[derive(Debug, Clone, Default)]
    struct ProblemData {
        /// Board model name (the method), as in the board-model registry.
        board_model: String,
        num_cameras: usize,
        num_frames: usize,
        num_corners: usize,
        /// Nominal board points, 3 per corner.
        board: Vec<f64>,
        obs_camera: Vec<u32>,
        obs_frame: Vec<u32>,
        obs_corner: Vec<u32>,
        /// Observed pixels, 2 per observation.
        obs_uv: Vec<f64>,
        /// Residual weight per observation (empty: all 1).
        obs_weight: Vec<f64>,
        /// Lens model name per camera, as in the lens-model registry.
        lens_models: Vec<String>,
        /// Every parameter, in the layout's order.
        params: Vec<f64>,
        /// Start of camera k's intrinsics in `params`.
        intrinsics_offsets: Vec<u32>,
        /// Per value of the intrinsics section: held at its value.
        intrinsics_held: Vec<bool>,
        /// Start of the camera-k-from-camera-0 poses (6 per camera; camera 0 unused).
        camera_poses_offset: u32,
        /// Start of the per-frame blocks: camera-0-from-board pose, then the board
        /// model's per-frame parameters.
        frames_offset: u32,
        frame_stride: u32,
        /// Start of the per-corner corrections (3 per corner; models use a prefix).
        corrections_offset: u32,
        /// Corners whose correction carries the gauge.
        gauge_corners: Vec<u32>,
        /// Corners whose correction is held at its value (too few views to estimate).
        frozen_corners: Vec<u32>,
        hold_intrinsics: bool,
        hold_camera_poses: bool,
        hold_corrections: bool,
        hold_deformations: bool,
        /// Prior on the static correction (`cpp/priors.h`): weight σ_noise/σ_prior
        /// per correction value (3 per corner; empty: no prior, 0: none on that value).
        correction_prior_weight: Vec<f64>,
        /// The prior's mean, 3 per corner (empty: zero).
        correction_prior_mean: Vec<f64>,
        /// Zero-mean prior on each per-frame bend coefficient (empty: none).
        bend_prior_weight: Vec<f64>,
        /// Prior on the change of each bend coefficient from frame j−1 to j (empty: none).
        bend_smoothness_weight: Vec<f64>,
        /// Cauchy scale of the smoothness prior, pixels (0: Gaussian): a jump
        /// between frames that are not consecutive in time costs little.
        bend_smoothness_loss: f64,
        /// Zero-mean prior on each value of the intrinsics section, weight
        /// σ_noise/σ_prior (empty: none; 0: none on that value).
        lens_prior_weight: Vec<f64>,
    }

    /// Solver settings passed to Ceres.
    #[derive(Debug, Clone)]
    struct SolveOptions {
        loss: LossKind,
        loss_scale_px: f64,
        num_threads: i32,
        max_iterations: i32,
        function_tolerance: f64,
        gradient_tolerance: f64,
        parameter_tolerance: f64,
        fix_gauge: bool,
        verbose: bool,
        /// Use the single-piece autodiff functor (the reference for the chained Jacobian).
        reference_jacobian: bool,
        /// The path before issue 17, kept as the reference the faster one is
        /// checked against: one residual block per corner, Ceres' Cauchy loss
        /// from the first iteration.
        per_corner_blocks: bool,
        /// Hand view blocks to Ceres as one row per column of their Jacobian
        /// and one for the residual (`CompressedRows` in `cpp/residuals.h`): the
        /// same steps, fewer rows. Off only to check that claim.
        compress_view_rows: bool,
        /// Share of the corners beyond the loss's scale above which a robust
        /// solve first runs a warm-up (see `problem::WarmUp`).
        warm_up_share: f64,
        /// The warm-up's loss scale as a multiple of `loss_scale_px` (0: no loss).
        warm_up_scale_factor: f64,
        /// A solve that starts next to its optimum (a re-solve after outlier
        /// rejection) stops, converged, after a successful step that changed
        /// the cost by at most this fraction of it, without the linear solve
        /// whose step the tolerances would refuse (0: off).
        settle_cost_change: f64,
    }

    /// What Ceres reported about one solve.
    #[derive(Debug, Clone)]
    struct SolveReport {
        usable: bool,
        converged: bool,
        iterations: i32,
        initial_cost: f64,
        final_cost: f64,
        message: String,
        linear_solver: String,
        seconds: f64,
        /// Final residuals in observation order, weighted, loss not applied (empty if unusable).
        residuals: Vec<f64>,
    }

    /// Residuals, weighted (loss not applied) and, if asked, the CRS Jacobian over the free parameters.
    #[derive(Debug, Clone, Default)]
    struct Evaluation {
        cost: f64,
        residuals: Vec<f64>,
        jacobian_rows: usize,
        jacobian_cols: usize,
        jacobian_row_ptr: Vec<u32>,
        jacobian_col_idx: Vec<u32>,
        jacobian_values: Vec<f64>,
        /// Per Jacobian column: the index in `ProblemData::params` of the value it
        /// differentiates (held values have no column).
        jacobian_col_param: Vec<u32>,
    }

    /// A bundle adjustment of the structure-from-motion experiment: camera-from-world
    /// poses and world points against pixels, intrinsics held (`solver::sfm`).
    #[derive(Debug, Clone, Default)]
    struct BundleData {
        /// Lens model name, as in the lens-model registry.
        lens_model: String,
        /// The calibration under test, held constant.
        intrinsics: Vec<f64>,
        /// Camera-from-world pose per frame, 6 each (angle-axis, translation); updated in place.
        poses: Vec<f64>,
        /// World points, 3 each; updated in place.
        points: Vec<f64>,
        obs_frame: Vec<u32>,
        obs_point: Vec<u32>,
        /// Observed pixels, 2 per observation.
        obs_uv: Vec<f64>,
        /// Per frame: pose held at its value.
        held_frames: Vec<bool>,
        /// Per point: held at its value.
        held_points: Vec<bool>,
        /// Cauchy loss scale in pixels; 0 for plain least squares.
        loss_scale_px: f64,
        max_iterations: i32,
    }

    /// What Ceres reported about one bundle adjustment.
    #[derive(Debug, Clone, Default)]
    struct BundleReport {
        usable: bool,
        converged: bool,
        iterations: i32,
        initial_cost: f64,
        final_cost: f64,
        message: String,
    }

    unsafe extern "C++" {
        include!("deformcal/cpp/bridge.h");

        /// Solves the problem in place.
        fn solve(data: &mut ProblemData, options: &SolveOptions) -> Result<SolveReport>;

        /// Solves a pose-only refit (everything but the board poses held, no
        /// loss) frame by frame, in place (`cpp/pose_refit.h`).
        fn refit_poses(data: &mut ProblemData, options: &SolveOptions) -> Result<SolveReport>;

        /// A pose-only refit prepared once and run under many intrinsics
        /// (`cpp/bridge.h`); it keeps no state between refits.
        type PoseRefit;
        /// The RMSE of the unweighted residuals after every frame's pose is
        /// refitted under `intrinsics` (every camera's, in camera order).
        fn rmse_px(self: &PoseRefit, intrinsics: &[f64]) -> Result<f64>;
        /// Prepares the pose-only refit of `data` (checked as `refit_poses` checks it).
        fn prepare_pose_refit(
            data: &ProblemData,
            options: &SolveOptions,
        ) -> Result<UniquePtr<PoseRefit>>;

        /// Evaluates residuals and optionally the Jacobian.
        fn evaluate(
            data: &ProblemData,
            options: &SolveOptions,
            with_jacobian: bool,
        ) -> Result<Evaluation>;

        /// A Jacobian held in C++ (CRS over the free parameters, rows in observation order).
        type Jacobian;
        /// The weighted residuals, loss not applied.
        fn residual_values(self: &Jacobian) -> &[f64];
        fn num_cols(self: &Jacobian) -> usize;
        fn row_offsets(self: &Jacobian) -> &[u32];
        fn column_indices(self: &Jacobian) -> &[u32];
        fn entries(self: &Jacobian) -> &[f64];
        /// Per column: the index in `ProblemData::params` of the value it differentiates.
        fn column_parameters(self: &Jacobian) -> &[u32];

        /// The Jacobian straight from the cost functions.
        fn jacobian(data: &ProblemData, options: &SolveOptions) -> Result<UniquePtr<Jacobian>>;

        /// Solves a bundle adjustment in place (`cpp/sfm.h`).
        fn solve_bundle(data: &mut BundleData) -> Result<BundleReport>;

        // Only the cross-language registry tests call this.
        #[allow(dead_code)]
        /// The C++ registry's parameter count of a lens model (an error if unknown).
        fn lens_num_params(model: &str) -> Result<usize>;

        // Only the cross-language registry tests call this.
        #[allow(dead_code)]
        /// The C++ projection of camera-frame points (3 each) to pixels (2 each);
        /// NaN where the model has no image of a point.
        fn project_points(model: &str, params: &[f64], points: &[f64]) -> Result<Vec<f64>>;

        // Only the cross-language registry tests call this.
        #[allow(dead_code)]
        /// The C++ registry's sizes of a board model: per-frame parameters,
        /// per-corner correction values and gauge corners.
        fn board_model_sizes(model: &str) -> Result<Vec<usize>>;

        // Only the cross-language registry tests call this.
        #[allow(dead_code)]
        /// The C++ board point of a nominal point under a board model.
        fn board_point(
            model: &str,
            nominal: &[f64],
            frame_extra: &[f64],
            correction: &[f64],
        ) -> Result<Vec<f64>>;

        // Only the prior's invariance test calls this.
        #[allow(dead_code)]
        /// The static-correction prior's sum of squares (`cpp/priors.h`, zero mean)
        /// over corners at `board` (3 each) with `corrections` and `weight` (3 each),
        /// minimised over its similarity.
        fn correction_prior_minimum(
            model: &str,
            board: &[f64],
            corrections: &[f64],
            weight: &[f64],
        ) -> Result<f64>;
    }
}

// SAFETY: a PoseRefit is not changed after it is prepared; `rmse_px` is a
// const method that keeps all of its working state on its own stack and heap,
// so the object may move between threads and be shared by several at once.
unsafe impl Send for ffi::PoseRefit {}
unsafe impl Sync for ffi::PoseRefit {}

#[cfg(test)]
#[path = "bridge_tests.rs"]
mod tests;
