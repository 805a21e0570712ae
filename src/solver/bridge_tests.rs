//! Invalid values reaching the C++ core come back as errors, never as aborts.
use super::ffi::{self as bridge, BoardModel, LossKind, ProblemData, SolveOptions};

fn options() -> SolveOptions {
    SolveOptions {
        loss: LossKind::Cauchy,
        loss_scale_px: 1.0,
        num_threads: 1,
        max_iterations: 50,
        function_tolerance: 1e-8,
        gradient_tolerance: 1e-10,
        parameter_tolerance: 1e-8,
        fix_gauge: true,
        verbose: false,
        reference_jacobian: false,
    }
}

/// A tiny valid problem: one camera, two frames, a 2×2 board seen head-on.
fn tiny(model: BoardModel) -> ProblemData {
    let board = vec![
        -0.05, -0.05, 0.0, 0.05, -0.05, 0.0, -0.05, 0.05, 0.0, 0.05, 0.05, 0.0,
    ];
    let mut d = ProblemData {
        model,
        num_cameras: 1,
        num_frames: 2,
        num_corners: 4,
        board: board.clone(),
        intrinsics: vec![1000.0, 1000.0, 320.0, 240.0, 0.0, 0.0, 0.0],
        camera_poses: vec![0.0; 6],
        frame_poses: vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.1, 0.0, 0.0, 0.0, 0.0, 1.2],
        deformations: vec![0.0; 6],
        corrections: vec![0.0; 12],
        gauge_corners: vec![0, 1, 2],
        ..ProblemData::default()
    };
    for f in 0..2u32 {
        for c in 0..4u32 {
            let z = if f == 0 { 1.0 } else { 1.2 };
            d.obs_camera.push(0);
            d.obs_frame.push(f);
            d.obs_corner.push(c);
            d.obs_uv.push(320.0 + 1000.0 * board[3 * c as usize] / z);
            d.obs_uv
                .push(240.0 + 1000.0 * board[3 * c as usize + 1] / z);
        }
    }
    d
}

fn error_of(d: &mut ProblemData, o: &SolveOptions) -> String {
    match bridge::solve(d, o) {
        Ok(r) => panic!("expected an error, got {r:?}"),
        Err(e) => e.what().to_string(),
    }
}

#[test]
fn valid_tiny_problem_solves() {
    let mut d = tiny(BoardModel::Standard);
    let r = bridge::solve(&mut d, &options()).unwrap();
    assert!(r.usable);
}

#[test]
fn nan_initial_guess_is_an_error() {
    let mut d = tiny(BoardModel::Standard);
    d.intrinsics[0] = f64::NAN;
    assert!(error_of(&mut d, &options()).contains("intrinsics[0] is not finite"));
    let mut d = tiny(BoardModel::Dynamic);
    d.deformations[4] = f64::INFINITY;
    assert!(error_of(&mut d, &options()).contains("deformations[4]"));
    let mut d = tiny(BoardModel::Standard);
    d.obs_uv[3] = f64::NAN;
    assert!(error_of(&mut d, &options()).contains("obs_uv[3]"));
}

#[test]
fn empty_and_inconsistent_problems_are_errors() {
    let mut d = ProblemData::default();
    assert!(error_of(&mut d, &options()).contains("no camera"));
    let mut d = tiny(BoardModel::Standard);
    d.obs_uv.clear();
    d.obs_camera.clear();
    d.obs_frame.clear();
    d.obs_corner.clear();
    assert!(error_of(&mut d, &options()).contains("no observation"));
    let mut d = tiny(BoardModel::Standard);
    d.obs_corner[2] = 99;
    assert!(error_of(&mut d, &options()).contains("outside the problem"));
    let mut d = tiny(BoardModel::Standard);
    d.frame_poses.pop();
    assert!(error_of(&mut d, &options()).contains("frame_poses has 11 values"));
    let mut d = tiny(BoardModel::Static);
    d.gauge_corners = vec![0, 0, 1];
    assert!(error_of(&mut d, &options()).contains("distinct"));
    let mut d = tiny(BoardModel::Full);
    d.gauge_corners = vec![0];
    assert!(error_of(&mut d, &options()).contains("needs 2 gauge corners"));
}

#[test]
fn invalid_options_are_errors() {
    let mut d = tiny(BoardModel::Standard);
    let o = SolveOptions {
        loss_scale_px: -1.0,
        ..options()
    };
    assert!(error_of(&mut d, &o).contains("loss_scale_px"));
    let o = SolveOptions {
        num_threads: 0,
        ..options()
    };
    assert!(error_of(&mut d, &o).contains("num_threads"));
    let o = SolveOptions {
        function_tolerance: f64::NAN,
        ..options()
    };
    assert!(error_of(&mut d, &o).contains("tolerances"));
}

#[test]
fn a_point_behind_the_camera_fails_cleanly() {
    let mut d = tiny(BoardModel::Standard);
    d.frame_poses[5] = 0.0; // the board sits in the camera centre: division by zero
    match bridge::solve(&mut d, &options()) {
        Ok(r) => assert!(!r.usable, "{r:?}"),
        Err(e) => assert!(!e.what().is_empty()),
    }
    assert!(bridge::evaluate(&d, &options(), false).is_err());
}
