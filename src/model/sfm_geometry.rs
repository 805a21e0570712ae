//! Multi-view geometry of the structure-from-motion experiment, on rays (pixels
//! unprojected with the calibration under test, so any lens model works): linear
//! triangulation, the two-view relative pose from the essential matrix, and the
//! paper's loop-closure error. Pure Rust (nalgebra); no solver.
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use nalgebra::{DMatrix, Matrix3, Rotation3, Vector2, Vector3};

/// The point minimising the algebraic error of `ray × (R x + t) = 0` over the
/// views (camera-from-world pose, unit ray); `None` for fewer than two views or
/// a degenerate system.
pub fn triangulate(views: &[(Pose, Vector3<f64>)]) -> Option<Vector3<f64>> {
    if views.len() < 2 {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(3 * views.len(), 4);
    for (n, (pose, ray)) in views.iter().enumerate() {
        let r = pose.rotation_matrix().into_inner();
        let t = pose.translation_vector();
        // [d]_× (R x + t) = 0: three rows, two independent.
        let d = ray.normalize();
        let dx = d.cross_matrix();
        let m = dx * r;
        let c = dx * t;
        for i in 0..3 {
            for j in 0..3 {
                a[(3 * n + i, j)] = m[(i, j)];
            }
            a[(3 * n + i, 3)] = c[i];
        }
    }
    let h = null_vector(&a)?;
    (h[3].abs() > 1e-12).then(|| Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]))
}

/// The right singular vector of `a`'s smallest singular value (nalgebra does
/// not promise an order).
fn null_vector(a: &DMatrix<f64>) -> Option<nalgebra::DVector<f64>> {
    let svd = a.clone().svd(false, true);
    let vt = svd.v_t?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    Some(vt.row(imin).transpose())
}

/// The largest angle between two of the views' rays to `x`, degrees: the
/// triangulation's parallax.
pub fn parallax_deg(views: &[(Pose, Vector3<f64>)], x: &Vector3<f64>) -> f64 {
    let centres: Vec<Vector3<f64>> = views
        .iter()
        .map(|(p, _)| p.inverse().translation_vector())
        .collect();
    let mut best: f64 = 0.0;
    for a in &centres {
        for b in &centres {
            let (u, v) = ((x - a).normalize(), (x - b).normalize());
            best = best.max(u.dot(&v).clamp(-1.0, 1.0).acos());
        }
    }
    best.to_degrees()
}

/// Whether `x` lies in front of every view (positive depth along the ray).
pub fn in_front(views: &[(Pose, Vector3<f64>)], x: &Vector3<f64>) -> bool {
    views.iter().all(|(p, d)| p.transform(x).dot(d) > 0.0)
}

/// The essential matrix E (x1ᵀ E x0 = 0) from eight or more ray pairs by the
/// normalised eight-point algorithm, projected onto the essential manifold.
pub fn essential(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<Matrix3<f64>> {
    if pairs.len() < 8 {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(pairs.len(), 9);
    for (n, (x0, x1)) in pairs.iter().enumerate() {
        let (x0, x1) = (x0.normalize(), x1.normalize());
        for i in 0..3 {
            for j in 0..3 {
                a[(n, 3 * i + j)] = x1[i] * x0[j];
            }
        }
    }
    let e = null_vector(&a)?;
    let e = Matrix3::from_row_slice(&e.iter().copied().collect::<Vec<_>>());
    let svd = e.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    Some(u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)) * vt)
}

/// Camera-1-from-camera-0 pose (unit baseline) of the essential matrix of
/// `pairs`: of its four decompositions, the one with most points in front of both.
pub fn relative_pose(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> Option<Pose> {
    let e = essential(pairs)?;
    let svd = e.svd(true, true);
    let (mut u, mut vt) = (svd.u?, svd.v_t?);
    if u.determinant() < 0.0 {
        u = -u;
    }
    if vt.determinant() < 0.0 {
        vt = -vt;
    }
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let t = u.column(2).into_owned();
    let candidates = [
        (u * w * vt, t),
        (u * w * vt, -t),
        (u * w.transpose() * vt, t),
        (u * w.transpose() * vt, -t),
    ];
    candidates
        .iter()
        .map(|(r, t)| {
            let pose = Pose::from_parts(&Rotation3::from_matrix_unchecked(*r), t);
            let good = pairs
                .iter()
                .filter(|(x0, x1)| {
                    let views = [(Pose::identity(), *x0), (pose, *x1)];
                    triangulate(&views).is_some_and(|x| in_front(&views, &x))
                })
                .count();
            (good, pose)
        })
        .max_by_key(|(good, _)| *good)
        .map(|(_, pose)| pose)
}

/// The paper's loop-closure error: the RMSE (pixels, per point Euclidean) between
/// the features of the first image and their reconstructed 3D points projected
/// with the estimated pose of the last image (the first image again) through the
/// calibration under test. `None` without any projectable point.
pub fn loop_closure_rmse(
    camera: &Intrinsics,
    last_pose: &Pose,
    first_features: &[(Vector2<f64>, Vector3<f64>)],
) -> Option<f64> {
    let sq: Vec<f64> = first_features
        .iter()
        .filter_map(|(uv, x)| {
            camera
                .project(&last_pose.transform(x))
                .map(|p| (p - uv).norm_squared())
        })
        .collect();
    (!sq.is_empty()).then(|| (sq.iter().sum::<f64>() / sq.len() as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::sfm_scene::look_at;

    fn ray(p: &Pose, x: &Vector3<f64>) -> Vector3<f64> {
        p.transform(x).normalize()
    }

    #[test]
    fn triangulation_recovers_the_point_exactly_without_noise() {
        let x = Vector3::new(1.0, -2.0, 5.0);
        let a = look_at(&Vector3::new(20.0, 0.0, 1.0), &Vector3::zeros());
        let b = look_at(&Vector3::new(18.0, 6.0, 2.0), &Vector3::zeros());
        let views = [(a, ray(&a, &x)), (b, ray(&b, &x))];
        let y = triangulate(&views).unwrap();
        assert!((y - x).norm() < 1e-9, "{y} vs {x}");
        assert!(in_front(&views, &y));
        let want = (x - Vector3::new(20.0, 0.0, 1.0))
            .normalize()
            .dot(&(x - Vector3::new(18.0, 6.0, 2.0)).normalize())
            .acos()
            .to_degrees();
        assert!((parallax_deg(&views, &x) - want).abs() < 1e-9);
    }

    #[test]
    fn relative_pose_recovers_rotation_and_baseline_direction() {
        let c0 = Vector3::new(40.0, 0.0, 1.7);
        let c1 = Vector3::new(39.0, 4.0, 1.9);
        let p0 = look_at(&c0, &Vector3::new(0.0, 0.0, 6.0));
        let p1 = look_at(&c1, &Vector3::new(1.0, 0.5, 6.0));
        let truth = p1.compose(&p0.inverse());
        let pts: Vec<Vector3<f64>> = (0..60)
            .map(|i| {
                let f = i as f64;
                Vector3::new(
                    10.0 * (f * 0.7).sin(),
                    8.0 * (f * 1.3).cos(),
                    12.0 * ((f * 0.37).sin() + 1.0) / 2.0,
                )
            })
            .collect();
        let pairs: Vec<_> = pts.iter().map(|x| (ray(&p0, x), ray(&p1, x))).collect();
        let est = relative_pose(&pairs).unwrap();
        let dr = est.rotation_matrix().inverse() * truth.rotation_matrix();
        assert!(dr.angle() < 1e-8, "rotation off by {}", dr.angle());
        let t = truth.translation_vector().normalize();
        assert!((est.translation_vector() - t).norm() < 1e-8);
    }

    #[test]
    fn loop_closure_is_zero_at_the_true_pose_and_grows_with_a_shift() {
        let cam = crate::model::synthetic::true_intrinsics();
        let p = look_at(&Vector3::new(30.0, 0.0, 1.7), &Vector3::new(0.0, 0.0, 5.0));
        let feats: Vec<_> = [Vector3::new(0.0, 1.0, 3.0), Vector3::new(0.5, -2.0, 8.0)]
            .iter()
            .map(|x| (cam.project(&p.transform(x)).unwrap(), *x))
            .collect();
        assert!(loop_closure_rmse(&cam, &p, &feats).unwrap() < 1e-9);
        // The camera turned by 1 mrad about its y axis: about fx · 1e-3 ≈ 2.9 px.
        let turn = Pose {
            rotation: [0.0, 1e-3, 0.0],
            translation: [0.0; 3],
        };
        let q = turn.compose(&p);
        let e = loop_closure_rmse(&cam, &q, &feats).unwrap();
        assert!((e - 2.9).abs() < 0.2, "{e}");
        assert!(loop_closure_rmse(&cam, &p, &[]).is_none());
    }
}
