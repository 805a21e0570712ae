//! The one cxx bridge between Rust and the Ceres core in `cpp/`.

#[cxx::bridge(namespace = "deformcal::ffi")]
pub mod ffi {
    /// Board model of the Ceres problem (SPEC §2).
    #[derive(Debug)]
    enum BoardModel {
        Standard,
        Static,
        Dynamic,
        Full,
    }

    /// Robust loss on the squared pixel residual.
    #[derive(Debug)]
    enum LossKind {
        None,
        Cauchy,
    }

    /// Observations and parameter tables of one problem; parameters are updated in place.
    #[derive(Debug, Clone, Default)]
    struct ProblemData {
        model: BoardModel,
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
        /// fx fy cx cy k1 k2 k3 per camera.
        intrinsics: Vec<f64>,
        /// Camera-k-from-camera-0 (angle-axis, translation) per camera; camera 0 unused.
        camera_poses: Vec<f64>,
        /// Camera-0-from-board per frame.
        frame_poses: Vec<f64>,
        /// Paraboloid (a, b, c) per frame.
        deformations: Vec<f64>,
        /// Static correction, 3 per corner (`full` uses the first two).
        corrections: Vec<f64>,
        /// Corners whose correction carries the gauge.
        gauge_corners: Vec<u32>,
        /// Corners whose correction is held at its value (too few views to estimate).
        frozen_corners: Vec<u32>,
        fix_intrinsics: bool,
        fix_camera_poses: bool,
        fix_corrections: bool,
        fix_deformations: bool,
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
    }

    unsafe extern "C++" {
        include!("deformcal/cpp/bridge.h");

        /// Solves the problem in place.
        fn solve(data: &mut ProblemData, options: &SolveOptions) -> Result<SolveReport>;

        /// Evaluates residuals and optionally the Jacobian.
        fn evaluate(
            data: &ProblemData,
            options: &SolveOptions,
            with_jacobian: bool,
        ) -> Result<Evaluation>;
    }
}

impl Default for ffi::BoardModel {
    fn default() -> Self {
        ffi::BoardModel::Standard
    }
}

#[cfg(test)]
#[path = "bridge_tests.rs"]
mod tests;
