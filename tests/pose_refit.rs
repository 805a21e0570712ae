//! The prepared pose refit (the protocol's test error) under intrinsics other
//! than those it was prepared at: every frame starts from its optimum under the
//! prepared intrinsics moved to first order, and must end at the optimum that a
//! refit from the original poses and the joint Ceres solve reach.
use crate::protocol::{converged, held_dynamic, rig_refit_case};
use deformcal::model::lens::Intrinsics;
use deformcal::solver::problem::{rmse, Loss, SolverSettings, State};
use deformcal::LensModel;

/// `i` moved by `scale` times a few pixels of focal length and principal
/// point and a percent of every other parameter.
fn moved(i: &Intrinsics, scale: f64) -> Intrinsics {
    let mut m = *i;
    let p = m.params_mut();
    for (k, d) in [2.0, 1.5, -1.0, 0.5].iter().enumerate() {
        p[k] += scale * d;
    }
    for v in p.iter_mut().skip(4) {
        *v *= 1.0 + 0.01 * scale;
    }
    m
}

/// Every lens model, each in a 2-camera rig with the next one of the registry,
/// the refit prepared at the truth and run under intrinsics moved by 0, 1 and 5
/// steps of [`moved`] (up to several pixels of RMSE): the test error is the one
/// of a refit from the original poses, which knows nothing of the prediction,
/// and the joint Ceres solve's.  With unit weights (the protocol's) to 1e-9;
/// with a third of the corners weighted 0.5 to 1e-8, since the unweighted RMSE
/// then varies to first order with poses that minimise the weighted cost to
/// round-off (the residuals come back in pixels).
#[test]
fn prepared_refit_under_moved_intrinsics_matches_the_refit_from_scratch() {
    let all = LensModel::ALL;
    for (m, &model) in all.iter().enumerate() {
        let models = [model, all[(m + 1) % all.len()]];
        let (weighted, start) = rig_refit_case(Some(&models));
        let mut unit = weighted.clone();
        for o in &mut unit.observations {
            o.weight = 1.0;
        }
        for (data, tol) in [(&unit, 1e-9), (&weighted, 1e-8)] {
            same_test_errors(data, &start, &format!("{models:?} {tol}"), tol);
        }
    }
}

/// The prepared refit of `data` from `start` under moved intrinsics against the
/// refit from scratch and the joint solve, to `tol` relative.
fn same_test_errors(data: &deformcal::Dataset, start: &State, case: &str, tol: f64) {
    let plain = SolverSettings {
        loss: Loss::None,
        ..SolverSettings::default()
    };
    let problem = held_dynamic(data);
    let prepared = problem.prepare_pose_refit(start, &plain).unwrap();
    let mut previous = None;
    for scale in [0.0, 1.0, 5.0] {
        let intrinsics: Vec<Intrinsics> =
            start.intrinsics.iter().map(|i| moved(i, scale)).collect();
        let fast = prepared.rmse_px(&intrinsics).unwrap();
        let at = State {
            intrinsics,
            ..start.clone()
        };
        let (mut scratch, mut joint) = (at.clone(), at);
        let a = problem.refit_poses(&mut scratch, &plain).unwrap();
        assert!(a.converged, "{case} {scale}");
        let b = problem.solve(&mut joint, &converged(&plain)).unwrap();
        for other in [rmse(&a.residuals), rmse(&b.residuals)] {
            assert!(
                (fast - other).abs() <= tol * other,
                "{case} {scale}: {fast} vs {other}"
            );
        }
        // Moved intrinsics leave more than the 0.2 px noise unexplained.
        if let Some(p) = previous {
            assert!(fast > p, "{case} {scale}: {fast} vs {p}");
        }
        previous = Some(fast);
    }
}
