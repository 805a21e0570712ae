//! The advice with closed-form derivatives against the central-difference
//! version it replaced, for every lens model: the same poses, ranked the same,
//! the same figures as printed, and information within a relative 1e-6.
use super::*;
use crate::model::lens::LensModel;
use crate::model::uncertainty::jacobian_rows;

/// Step of the reference's central differences in the point's position, metres.
const POSE_STEP: f64 = 1e-6;

/// The reference: [`view_information`] with the Jacobian by central differences
/// (the intrinsics' columns from `jacobian_rows`, the point's from six projections).
fn view_information_central(
    k: &Intrinsics,
    free: &[bool],
    target: &Target,
    camera_from_board: &Pose,
    corners: &[usize],
) -> Option<DMatrix<f64>> {
    let idx = free_indices(free);
    let n = idx.len();
    let mut a = DMatrix::<f64>::zeros(n + 6, n + 6);
    let mut used = 0;
    for &c in corners {
        let xc = camera_from_board.transform(&target.nominal(c));
        let Some(jt) = jacobian_rows(k, &xc) else {
            continue;
        };
        let mut j = DMatrix::<f64>::zeros(2, n + 6);
        for (col, &i) in idx.iter().enumerate() {
            j[(0, col)] = jt[0][i];
            j[(1, col)] = jt[1][i];
        }
        let mut dx = [Vector2::zeros(); 3];
        let mut ok = true;
        for (axis, column) in dx.iter_mut().enumerate() {
            let mut d = Vector3::zeros();
            d[axis] = POSE_STEP;
            match (k.project(&(xc + d)), k.project(&(xc - d))) {
                (Some(p), Some(m)) => *column = (p - m) / (2.0 * POSE_STEP),
                _ => ok = false,
            }
        }
        if !ok {
            continue;
        }
        for axis in 0..3 {
            let w = Vector3::ith(axis, 1.0).cross(&xc);
            let rot = dx[0] * w.x + dx[1] * w.y + dx[2] * w.z;
            j.set_column(n + axis, &rot);
            j.set_column(n + 3 + axis, &dx[axis]);
        }
        a += j.transpose() * j;
        used += 1;
    }
    if used == 0 {
        return None;
    }
    let aa = a.view((0, 0), (n, n)).into_owned();
    let ab = a.view((0, n), (n, 6)).into_owned();
    let bb_inv = a.view((n, n), (6, 6)).into_owned().try_inverse()?;
    Some(&aa - &ab * bb_inv * ab.transpose())
}

/// The reference's corners of the board that a pose shows inside the image.
fn corners_in_view(kn: &Knowledge, pose: &Pose) -> Vec<usize> {
    let (w, h) = (kn.width as f64, kn.height as f64);
    (0..kn.target.num_corners())
        .filter(|&i| {
            let xc = pose.transform(&kn.target.nominal(i));
            xc.z > 0.0
                && kn.intrinsics.project(&xc).is_some_and(|uv| {
                    uv.x >= 0.0 && uv.y >= 0.0 && uv.x <= w - 1.0 && uv.y <= h - 1.0
                })
        })
        .collect()
}

/// A camera of `model` (its simulated lens) on a 13 × 13 board, with `free`
/// parameters, that has seen every seventh candidate (all tilts among them) view.
fn knowledge(model: LensModel, free: Vec<bool>) -> Knowledge {
    let intrinsics = Intrinsics::from_params(model, model.info().synthetic).unwrap();
    let target = Target {
        rows: 13,
        cols: 13,
        spacing: 0.07,
    };
    let n = free.iter().filter(|f| **f).count();
    let mut kn = Knowledge {
        intrinsics,
        width: 1936,
        height: 1216,
        free,
        target,
        noise_px: 0.3,
        information: DMatrix::zeros(n, n),
    };
    let all: Vec<usize> = (0..target.num_corners()).collect();
    let mut views = 0;
    for pose in candidates(&kn).iter().step_by(7) {
        let seen = corners_in_view(&kn, pose);
        if seen.len() < 20 {
            continue;
        }
        let central = view_information_central(&intrinsics, &kn.free, &target, pose, &seen);
        let closed = view_information(&intrinsics, &kn.free, &target, pose, &seen);
        let (central, closed) = (central.unwrap(), closed.unwrap());
        let err = (&closed - &central).norm() / central.norm();
        assert!(err < 1e-6, "{model}: information differs by {err:.1e}");
        kn.information += central;
        views += 1;
        // A view seen whole (corners outside the image included, where the
        // model projects them) is the same sum too.
        if let Some(whole) = view_information(&intrinsics, &kn.free, &target, pose, &all) {
            let reference =
                view_information_central(&intrinsics, &kn.free, &target, pose, &all).unwrap();
            assert!(
                (&whole - &reference).norm() < 1e-6 * reference.norm(),
                "{model}"
            );
        }
    }
    assert!(views >= 20, "{model}: {views} views");
    kn
}

/// The reference's candidate: its corners in view, then their information.
fn candidate_central(kn: &Knowledge, pose: &Pose) -> (usize, Option<DMatrix<f64>>) {
    let seen = corners_in_view(kn, pose);
    let info = view_information_central(&kn.intrinsics, &kn.free, &kn.target, pose, &seen);
    (seen.len(), info)
}

fn same_advice(kn: &Knowledge) {
    let model = kn.intrinsics.model();
    let closed = advise_with(kn, 3, candidate_information).expect("advice");
    let central = advise_with(kn, 3, candidate_central).expect("advice");
    assert_eq!(closed.poses.len(), 3, "{model}");
    assert_eq!(closed.current_error_px, central.current_error_px, "{model}");
    assert_eq!(closed.map, central.map, "{model}");
    for (a, b) in closed.poses.iter().zip(&central.poses) {
        assert_eq!(a.camera_from_board, b.camera_from_board, "{model}");
        assert_eq!(a.corners_in_view, b.corners_in_view, "{model}");
        assert_eq!(a.outline, b.outline, "{model}");
        let rel = (a.predicted_error_px / b.predicted_error_px - 1.0).abs();
        assert!(rel < 1e-6, "{model}: {a:?} against {b:?}");
    }
    // What the report and `deformcal advise` print.
    assert_eq!(closed.to_string(), central.to_string(), "{model}");
    assert_eq!(svg(kn, &closed), svg(kn, &central), "{model}");
}

#[test]
fn closed_form_advice_is_the_central_difference_advice() {
    for model in LensModel::ALL {
        // The parameters the lens prior holds near zero (opencv8's denominator)
        // are held: these views do not determine them.
        let prior = model.info().prior_params;
        let mut free: Vec<bool> = model
            .param_names()
            .iter()
            .map(|p| !prior.contains(p))
            .collect();
        same_advice(&knowledge(model, free.clone()));
        // A held parameter (cy) leaves its row and column out.
        free[3] = false;
        same_advice(&knowledge(model, free));
    }
}
