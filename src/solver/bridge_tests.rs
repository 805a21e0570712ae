//! Invalid values reaching the C++ core come back as errors, never as aborts.
use super::ffi::{self as bridge, LossKind, ProblemData, SolveOptions};
use crate::model::lens::LensModel;
use crate::model::state::Layout;

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
        per_corner_blocks: false,
        compress_view_rows: true,
        warm_up_share: 0.5,
        settle_cost_change: 0.0,
        warm_up_scale_factor: 0.0,
    }
}

/// A tiny valid problem: one camera, two frames, a 2×2 board seen head-on.
fn tiny(model: &str) -> ProblemData {
    let board = vec![
        -0.05, -0.05, 0.0, 0.05, -0.05, 0.0, -0.05, 0.05, 0.0, 0.05, 0.05, 0.0,
    ];
    let method = crate::Method::parse(model).unwrap();
    let layout = Layout::new(&[LensModel::Radial3], 2, method.info().frame_params, 4);
    let extra = layout.frame_stride - 6;
    let mut params = vec![1000.0, 1000.0, 320.0, 240.0, 0.0, 0.0, 0.0];
    params.extend([0.0; 6]);
    params.extend([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    params.extend(vec![0.0; extra]);
    params.extend([0.1, 0.0, 0.0, 0.0, 0.0, 1.2]);
    params.extend(vec![0.0; extra]);
    params.extend([0.0; 12]);
    assert_eq!(params.len(), layout.len);
    let mut d = ProblemData {
        board_model: model.into(),
        num_cameras: 1,
        num_frames: 2,
        num_corners: 4,
        board: board.clone(),
        lens_models: vec!["radial3".into()],
        params,
        intrinsics_offsets: vec![0],
        intrinsics_held: vec![false; 7],
        camera_poses_offset: layout.camera_poses as u32,
        frames_offset: layout.frames as u32,
        frame_stride: layout.frame_stride as u32,
        corrections_offset: layout.corrections as u32,
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
    let mut d = tiny("standard");
    let r = bridge::solve(&mut d, &options()).unwrap();
    assert!(r.usable);
}

#[test]
fn nan_initial_guess_is_an_error() {
    let mut d = tiny("standard");
    d.params[0] = f64::NAN;
    assert!(error_of(&mut d, &options()).contains("params[0] is not finite"));
    let mut d = tiny("dynamic");
    // The second frame's b of the paraboloid.
    let i = d.frames_offset as usize + d.frame_stride as usize + 6 + 1;
    d.params[i] = f64::INFINITY;
    assert!(error_of(&mut d, &options()).contains(&format!("params[{i}]")));
    let mut d = tiny("standard");
    d.obs_uv[3] = f64::NAN;
    assert!(error_of(&mut d, &options()).contains("obs_uv[3]"));
}

#[test]
fn empty_and_inconsistent_problems_are_errors() {
    let mut d = ProblemData::default();
    assert!(error_of(&mut d, &options()).contains("no camera"));
    let mut d = tiny("standard");
    d.obs_uv.clear();
    d.obs_camera.clear();
    d.obs_frame.clear();
    d.obs_corner.clear();
    assert!(error_of(&mut d, &options()).contains("no observation"));
    let mut d = tiny("standard");
    d.obs_corner[2] = 99;
    assert!(error_of(&mut d, &options()).contains("outside the problem"));
    let mut d = tiny("standard");
    d.params.pop();
    let expected = format!("params has {} values", d.params.len());
    assert!(error_of(&mut d, &options()).contains(&expected));
    let mut d = tiny("standard");
    d.frames_offset += 1;
    assert!(error_of(&mut d, &options()).contains("frames_offset does not follow the layout"));
    let mut d = tiny("standard");
    d.lens_models = vec!["pinhole9".into()];
    assert!(error_of(&mut d, &options()).contains("unknown lens model `pinhole9`"));
    let mut d = tiny("standard");
    d.board_model = "wobbly".into();
    assert!(error_of(&mut d, &options()).contains("unknown board model `wobbly`"));
    let mut d = tiny("static");
    d.gauge_corners = vec![0, 0, 1];
    assert!(error_of(&mut d, &options()).contains("distinct"));
    let mut d = tiny("full");
    d.gauge_corners = vec![0];
    assert!(error_of(&mut d, &options()).contains("needs 2 gauge corners"));
}

#[test]
fn invalid_options_are_errors() {
    let mut d = tiny("standard");
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
    let mut d = tiny("standard");
    // The board sits in the camera centre: division by zero.
    d.params[d.frames_offset as usize + 5] = 0.0;
    match bridge::solve(&mut d, &options()) {
        Ok(r) => assert!(!r.usable, "{r:?}"),
        Err(e) => assert!(!e.what().is_empty()),
    }
    assert!(bridge::evaluate(&d, &options(), false).is_err());
}

/// Camera-frame points spread over a wide field of view (up to about 100° off axis
/// for the fisheye models), with a few on and near the optical axis.
fn test_points(fisheye: bool) -> Vec<[f64; 3]> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut out = vec![[0.0, 0.0, 1.0], [1e-9, -1e-9, 2.0], [0.0, 1e-6, 0.5]];
    for _ in 0..500 {
        let max = if fisheye { 1.75_f64 } else { 0.6_f64 };
        let theta: f64 = rng.gen_range(0.0..max);
        let phi: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
        let d: f64 = rng.gen_range(0.3..5.0);
        out.push([
            d * theta.sin() * phi.cos(),
            d * theta.sin() * phi.sin(),
            d * theta.cos(),
        ]);
    }
    out
}

#[test]
fn rust_and_cpp_lens_registries_agree() {
    use crate::model::lens::Intrinsics;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for model in LensModel::ALL {
        assert_eq!(
            bridge::lens_num_params(model.name()).unwrap(),
            model.num_params(),
            "{model}"
        );
        let fisheye = !model.info().pinhole_like;
        for _ in 0..20 {
            // Random but plausible parameters of the model.
            let mut p: Vec<f64> = vec![
                rng.gen_range(300.0..3000.0),
                rng.gen_range(300.0..3000.0),
                rng.gen_range(300.0..1000.0),
                rng.gen_range(200.0..800.0),
            ];
            let rest = model.num_params() - 4;
            for k in 0..rest {
                p.push(match (model, k) {
                    (LensModel::DoubleSphere, 0) => rng.gen_range(-0.4..0.4),
                    (LensModel::DoubleSphere, _) => rng.gen_range(0.4..0.7),
                    _ => rng.gen_range(-0.05..0.05),
                });
            }
            let k = Intrinsics::from_params(model, &p).unwrap();
            let points = test_points(fisheye);
            let flat: Vec<f64> = points.iter().flatten().copied().collect();
            let cpp = bridge::project_points(model.name(), &p, &flat).unwrap();
            let mut compared = 0;
            for (x, uv) in points.iter().zip(cpp.chunks(2)) {
                let Some(rust) = k.project(&Vector3::from(*x)) else {
                    continue;
                };
                compared += 1;
                for (a, b) in [(rust.x, uv[0]), (rust.y, uv[1])] {
                    assert!(
                        (a - b).abs() <= 1e-12 * a.abs().max(1.0),
                        "{model} at {x:?}: Rust {a} vs C++ {b}"
                    );
                }
            }
            assert!(compared > 400, "{model}: only {compared} points projected");
        }
    }
    assert!(bridge::lens_num_params("pinhole9").is_err());
}

#[test]
fn rust_and_cpp_board_registries_agree() {
    use crate::model::board::{board_point, Paraboloid};
    use nalgebra::Vector3;
    for method in crate::Method::REGISTRY {
        let info = method.info();
        let sizes = bridge::board_model_sizes(info.name).unwrap();
        assert_eq!(
            sizes,
            vec![info.frame_params, info.corner_params, info.gauge_corners],
            "{method}"
        );
        let nominal = [0.21, -0.14, 0.0];
        let bend = Paraboloid {
            a: 0.3,
            b: -0.7,
            c: 0.2,
        };
        let correction = [1e-3, -2e-3, 5e-4];
        let higher = [0.9, -0.4, 0.25, 0.6, -1.1, 0.3, 0.8, -0.2, 0.5];
        let all: Vec<f64> = bend.to_array().into_iter().chain(higher).collect();
        let extra = &all[..info.frame_params];
        let cpp = bridge::board_point(info.name, &nominal, extra, &correction).unwrap();
        let rust = board_point(method, &Vector3::from(nominal), &correction, &bend, &higher);
        for i in 0..3 {
            assert!(
                (cpp[i] - rust[i]).abs() <= 1e-15,
                "{method}: {cpp:?} vs {rust}"
            );
        }
    }
    assert!(bridge::board_model_sizes("wobbly").is_err());
}

#[test]
fn malformed_priors_are_errors() {
    let mut d = tiny("static");
    d.correction_prior_weight = vec![1.0; 5];
    assert!(error_of(&mut d, &options()).contains("correction_prior_weight"));
    let mut d = tiny("dynamic4");
    d.bend_smoothness_weight = vec![-1.0; 12];
    assert!(error_of(&mut d, &options()).contains("must not be negative"));
    let mut d = tiny("dynamic");
    d.bend_smoothness_weight = vec![1.0; 3];
    d.bend_smoothness_loss = f64::NAN;
    assert!(error_of(&mut d, &options()).contains("bend_smoothness_loss"));
    let mut d = tiny("standard");
    d.lens_prior_weight = vec![1.0; 6];
    assert!(error_of(&mut d, &options()).contains("lens_prior_weight"));
    d.lens_prior_weight = vec![-1.0; 7];
    assert!(error_of(&mut d, &options()).contains("must not be negative"));
}

#[test]
fn a_tight_lens_prior_holds_its_parameters_at_zero() {
    // Four corners leave k1 of radial3 undetermined: it stays where it starts
    // without the prior, and goes to the prior's zero with it.
    let solved_k1 = |weight: Vec<f64>| {
        let mut d = tiny("standard");
        d.params[4] = 0.01;
        d.lens_prior_weight = weight;
        bridge::solve(&mut d, &options()).unwrap();
        d.params[4]
    };
    let mut weight = vec![0.0; 7];
    weight[4] = 1e6;
    let (free, held) = (solved_k1(Vec::new()), solved_k1(weight));
    assert!(free.abs() > 1e-4 && held.abs() < 1e-9, "{free} {held}");
}

#[test]
fn a_tight_bend_prior_holds_the_bend_and_the_smoothness_ties_frames() {
    // Two frames, a 2×2 board seen head-on: a strong zero-mean prior keeps the
    // bend at zero; a strong smoothness prior makes the two frames' bends equal.
    let mut d = tiny("dynamic");
    // Each frame's bend follows its pose; the frames follow the intrinsics (7)
    // and camera 0's pose (6), 9 values each.
    let (f0, f1) = (7 + 6 + 6, 7 + 6 + 9 + 6);
    d.params[f0] = 1e-3;
    d.params[f1] = -2e-3;
    d.bend_prior_weight = vec![1e6; 3];
    bridge::solve(&mut d, &options()).unwrap();
    assert!(d.params[f0].abs() < 1e-9 && d.params[f1].abs() < 1e-9);
    let mut d = tiny("dynamic");
    d.params[f0] = 1e-3;
    d.params[f1] = -2e-3;
    d.bend_smoothness_weight = vec![1e6; 3];
    bridge::solve(&mut d, &options()).unwrap();
    assert!((d.params[f0] - d.params[f1]).abs() < 1e-9);
}

/// A bundle adjustment of one free pose against held points, noise-free pixels
/// of the kb4 fisheye (any registry model works): the pose comes back exactly.
fn bundle(model: LensModel) -> bridge::BundleData {
    let cam = crate::model::synthetic::true_intrinsics_of(model);
    let truth = crate::model::pose::Pose {
        rotation: [0.05, -0.1, 0.02],
        translation: [0.3, -0.2, 0.1],
    };
    let points: Vec<nalgebra::Vector3<f64>> = (0..20)
        .map(|i| {
            let f = i as f64;
            nalgebra::Vector3::new(
                (f * 0.9).sin(),
                (f * 1.7).cos() * 0.6,
                4.0 + (f * 0.3).sin(),
            )
        })
        .collect();
    let mut d = bridge::BundleData {
        lens_model: model.name().into(),
        intrinsics: cam.params().to_vec(),
        poses: vec![0.0; 6],
        loss_scale_px: 1.0,
        max_iterations: 50,
        held_frames: vec![false],
        ..Default::default()
    };
    for (i, x) in points.iter().enumerate() {
        let uv = cam.project(&truth.transform(x)).unwrap();
        d.points.extend(x.iter());
        d.held_points.push(true);
        d.obs_frame.push(0);
        d.obs_point.push(i as u32);
        d.obs_uv.extend([uv.x, uv.y]);
    }
    d
}

#[test]
fn bundle_adjustment_recovers_a_pose_with_any_lens_model() {
    for model in [LensModel::Radial3, LensModel::Kb4, LensModel::DoubleSphere] {
        let mut d = bundle(model);
        let r = bridge::solve_bundle(&mut d).unwrap();
        assert!(r.usable && r.final_cost < 1e-12, "{model}: {r:?}");
        let want = [0.05, -0.1, 0.02, 0.3, -0.2, 0.1];
        for (a, b) in d.poses.iter().zip(want) {
            assert!((a - b).abs() < 1e-7, "{model}: {:?}", d.poses);
        }
    }
}

#[test]
fn bad_bundle_input_is_an_error() {
    let mut d = bundle(LensModel::Radial3);
    d.obs_point[3] = 99;
    assert!(bridge::solve_bundle(&mut d).is_err());
    let mut d = bundle(LensModel::Radial3);
    d.points[0] = f64::NAN;
    assert!(bridge::solve_bundle(&mut d).is_err());
    let mut d = bundle(LensModel::Radial3);
    d.lens_model = "pinhole9".into();
    assert!(bridge::solve_bundle(&mut d).is_err());
    let mut d = bundle(LensModel::Radial3);
    d.intrinsics.pop();
    assert!(bridge::solve_bundle(&mut d).is_err());
}

#[test]
fn the_correction_prior_is_blind_to_a_similarity_of_the_whole_correction() {
    // Closed form: the prior minimised over its similarity is the weighted
    // least-squares residual of the correction against the similarity directions
    // (translation, rotation ω × x, scale x; in-plane for `full`), built here
    // independently of the C++ functor's Jacobian.
    use nalgebra::{DMatrix, DVector, Vector3};
    let board: Vec<Vector3<f64>> = (0..20)
        .map(|i| Vector3::new(0.03 * (i % 5) as f64, 0.03 * (i / 5) as f64, 0.0))
        .collect();
    let flat: Vec<f64> = board.iter().flat_map(|x| x.iter().copied()).collect();
    let wobble = |i: usize, k: usize| 1e-4 * ((7 * i + 3 * k) as f64 * 0.9).sin();
    let delta: Vec<f64> = (0..60).map(|j| wobble(j / 3, j % 3)).collect();
    let weight: Vec<f64> = (0..60).map(|j| 1500.0 + 40.0 * (j % 7) as f64).collect();
    for (model, dims) in [("static", 3), ("full", 2), ("full4", 2)] {
        let (e0, e1, e2) = (Vector3::x(), Vector3::y(), Vector3::z());
        let directions = |x: &Vector3<f64>| -> Vec<Vector3<f64>> {
            if dims == 3 {
                vec![e0, e1, e2, e0.cross(x), e1.cross(x), e2.cross(x), *x]
            } else {
                vec![e0, e1, e2.cross(x), *x]
            }
        };
        let g = directions(&board[0]).len();
        let mut b = DMatrix::<f64>::zeros(dims * board.len(), g);
        let mut r = DVector::<f64>::zeros(dims * board.len());
        for (i, x) in board.iter().enumerate() {
            for (c, v) in directions(x).iter().enumerate() {
                for k in 0..dims {
                    b[(dims * i + k, c)] = weight[3 * i + k] * v[k];
                }
            }
            for k in 0..dims {
                r[dims * i + k] = weight[3 * i + k] * delta[3 * i + k];
            }
        }
        let s = b.clone().svd(true, true).solve(&r, 1e-14).unwrap();
        let expected = (&r - &b * s).norm_squared();
        let minimum =
            |d: &[f64]| bridge::correction_prior_minimum(model, &flat, d, &weight).unwrap();
        let plain = minimum(&delta);
        assert!(
            (plain - expected).abs() < 1e-9 * expected,
            "{model}: {plain} vs closed form {expected}"
        );
        // Adding a similarity to every corner's correction changes nothing.
        let t = [2e-4, -1e-4, 3e-4, 1e-3, -2e-3, 1.5e-3, 2e-3];
        let mut moved = delta.clone();
        for (i, x) in board.iter().enumerate() {
            let v: Vector3<f64> = directions(x).iter().zip(&t).map(|(d, a)| d * *a).sum();
            for k in 0..dims {
                moved[3 * i + k] += v[k];
            }
        }
        let after = minimum(&moved);
        assert!(
            (after - plain).abs() < 1e-9 * plain,
            "{model}: {after} vs {plain}"
        );
        // Anything else is seen: one corner moved alone.
        moved[3 * 7] += 1e-4;
        assert!(minimum(&moved) > plain * 1.01, "{model}");
    }
    assert!(bridge::correction_prior_minimum("standard", &flat, &delta, &weight).is_err());
}

#[test]
fn the_correction_priors_similarity_stays_out_of_the_jacobian() {
    // The similarity block lives outside the parameter buffer: the Jacobian that
    // Rust reads (covariance, board.json) has the same columns with the prior.
    for model in ["static", "full"] {
        let plain = tiny(model);
        let mut with = tiny(model);
        with.correction_prior_weight = vec![100.0; 12];
        for direct in [false, true] {
            let columns = |d: &ProblemData| -> Vec<u32> {
                if direct {
                    bridge::jacobian(d, &options())
                        .unwrap()
                        .column_parameters()
                        .to_vec()
                } else {
                    bridge::evaluate(d, &options(), true)
                        .unwrap()
                        .jacobian_col_param
                }
            };
            assert_eq!(columns(&with), columns(&plain), "{model}, direct {direct}");
        }
    }
}
