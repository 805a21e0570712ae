//! Calibration quality metrics (docs/conventions.md §3): mapping error, with and without a virtual rotation.
use crate::model::lens::Intrinsics;
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};

/// Grid step of the mapping error in pixels.
pub const MAPPING_GRID_STEP_PX: u32 = 20;

/// The rays of the mapping-error grid (every [`MAPPING_GRID_STEP_PX`] px from the
/// top-left pixel) under `a`, with their pixels; pixels without a ray are left out.
pub fn grid_rays(a: &Intrinsics, width: u32, height: u32) -> Vec<(Vector2<f64>, Vector3<f64>)> {
    let mut out = Vec::new();
    for v in (0..height).step_by(MAPPING_GRID_STEP_PX as usize) {
        for u in (0..width).step_by(MAPPING_GRID_STEP_PX as usize) {
            let px = Vector2::new(u as f64, v as f64);
            if let Some(ray) = a.unproject(&px) {
                out.push((px, ray));
            }
        }
    }
    out
}

fn rms_after(rays: &[(Vector2<f64>, Vector3<f64>)], b: &Intrinsics, r: &Matrix3<f64>) -> f64 {
    let mut sum = 0.0;
    for (px, ray) in rays {
        match b.project(&(r * ray)) {
            Some(q) => sum += (q - px).norm_squared(),
            None => return f64::INFINITY,
        }
    }
    (sum / rays.len() as f64).sqrt()
}

/// `mapping_error_px`: unproject a 20 px grid with `a`, project with `b`, RMSE in pixels.
pub fn mapping_error(a: &Intrinsics, b: &Intrinsics, width: u32, height: u32) -> f64 {
    mapping_error_of(&grid_rays(a, width, height), b)
}

/// [`mapping_error`] from `a`'s [`grid_rays`], computed once where one `a` is
/// compared with many `b` (the protocol's reference and truth).
pub fn mapping_error_of(rays: &[(Vector2<f64>, Vector3<f64>)], b: &Intrinsics) -> f64 {
    if rays.is_empty() {
        return f64::NAN;
    }
    rms_after(rays, b, &Matrix3::identity())
}

/// `mapping_error_rot_px`: the mapping error after the best virtual camera rotation
/// (Gauss-Newton over 3 rotation parameters).
pub fn mapping_error_rot(a: &Intrinsics, b: &Intrinsics, width: u32, height: u32) -> f64 {
    mapping_error_rot_of(&grid_rays(a, width, height), b)
}

/// [`mapping_error_rot`] from `a`'s [`grid_rays`].
pub fn mapping_error_rot_of(rays: &[(Vector2<f64>, Vector3<f64>)], b: &Intrinsics) -> f64 {
    if rays.is_empty() {
        return f64::NAN;
    }
    let mut rot = Rotation3::identity();
    let mut best = rms_after(rays, b, rot.matrix());
    for _ in 0..20 {
        // Normal equations of the residual q(R·δR·ray) − px in the increment δ.
        let mut jtj = Matrix3::<f64>::zeros();
        let mut jtr = Vector3::<f64>::zeros();
        for (px, ray) in rays {
            let x = rot * ray;
            let Some(d) = b.project_with_derivatives(&x) else {
                return best;
            };
            // A left increment: δR·x ≈ x + δ × x, so row a of ∂q/∂δ is
            // x × ∂q_a/∂x, in closed form (forward differences cost three more
            // projections and rotations per ray).
            let r = d.uv - px;
            for a in 0..2 {
                let row = x.cross(&d.d_point.row(a).transpose());
                jtj += row * row.transpose();
                jtr += row * r[a];
            }
        }
        let Some(step) = jtj.try_inverse().map(|m| -(m * jtr)) else {
            break;
        };
        let candidate = Rotation3::from_scaled_axis(step) * rot;
        let e = rms_after(rays, b, candidate.matrix());
        if e >= best {
            break;
        }
        let gain = best - e;
        rot = candidate;
        best = e;
        if gain < 1e-12 {
            break;
        }
    }
    best
}

/// Mean and sample standard deviation of a metric.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    pub n: usize,
}

impl Stat {
    /// Statistics of the finite values; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Stat> {
        let v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = if v.len() > 1 {
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        Some(Stat {
            mean,
            std,
            n: v.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn lens() -> Intrinsics {
        Intrinsics::pinhole(1000.0, 1000.0, 320.0, 240.0)
            .with_param("k1", -0.1)
            .with_param("k2", 0.05)
    }

    #[test]
    fn zero_for_identical_intrinsics() {
        assert!(mapping_error(&lens(), &lens(), 640, 480) < 1e-9);
        assert!(mapping_error_rot(&lens(), &lens(), 640, 480) < 1e-9);
    }

    #[test]
    fn pure_focal_change_matches_hand_computation() {
        // Without distortion, scaling f by s moves pixel p to c + s (p − c): the error
        // is (s − 1)·RMS‖p − c‖ over the grid.
        let a = Intrinsics::pinhole(1000.0, 1000.0, 320.0, 240.0);
        let b = Intrinsics::pinhole(1010.0, 1010.0, 320.0, 240.0);
        let mut sum = 0.0;
        let mut n = 0.0;
        for v in (0..480).step_by(20) {
            for u in (0..640).step_by(20) {
                sum += (u as f64 - 320.0).powi(2) + (v as f64 - 240.0).powi(2);
                n += 1.0;
            }
        }
        let expected = 0.01 * (sum / n).sqrt();
        assert_relative_eq!(
            mapping_error(&a, &b, 640, 480),
            expected,
            max_relative = 1e-9
        );
    }

    #[test]
    fn symmetric_within_a_small_tolerance() {
        let a = lens();
        let b = lens()
            .with_param("fx", 1006.0)
            .with_param("cx", 323.0)
            .with_param("k1", -0.09);
        let (ab, ba) = (
            mapping_error(&a, &b, 640, 480),
            mapping_error(&b, &a, 640, 480),
        );
        assert!(ab > 1.0);
        assert!((ab - ba).abs() < 0.02 * ab, "{ab} vs {ba}");
        let (ab, ba) = (
            mapping_error_rot(&a, &b, 640, 480),
            mapping_error_rot(&b, &a, 640, 480),
        );
        assert!((ab - ba).abs() < 0.05 * ab.max(0.01), "{ab} vs {ba}");
    }

    /// The rotated mapping error by Gauss-Newton on forward differences (the
    /// form before the closed-form Jacobian): an independent path to the same
    /// minimum.
    fn rot_by_differences(rays: &[(Vector2<f64>, Vector3<f64>)], b: &Intrinsics) -> f64 {
        let mut rot = Rotation3::identity();
        let mut best = rms_after(rays, b, rot.matrix());
        for _ in 0..50 {
            let (mut jtj, mut jtr) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
            for (px, ray) in rays {
                let q0 = b.project(&(rot * ray)).unwrap();
                let mut jac = nalgebra::Matrix2x3::<f64>::zeros();
                for k in 0..3 {
                    let mut d = Vector3::zeros();
                    d[k] = 1e-7;
                    let q = b.project(&(rot * Rotation3::from_scaled_axis(d) * ray));
                    jac.set_column(k, &((q.unwrap() - q0) / 1e-7));
                }
                jtj += jac.transpose() * jac;
                jtr += jac.transpose() * (q0 - px);
            }
            let candidate = rot * Rotation3::from_scaled_axis(-(jtj.try_inverse().unwrap() * jtr));
            let e = rms_after(rays, b, candidate.matrix());
            if e >= best {
                break;
            }
            (rot, best) = (candidate, e);
        }
        best
    }

    #[test]
    fn rotated_error_is_the_minimum_forward_differences_find() {
        use crate::model::lens::LensModel;
        for m in LensModel::ALL {
            let a = Intrinsics::from_params(m, m.info().synthetic).unwrap();
            let p = a.params();
            let mut q = p.to_vec();
            // Focal length, principal point and the first distortion term moved.
            q[0] *= 1.004;
            q[2] += 3.0;
            q[3] -= 2.0;
            if q.len() > 4 {
                q[4] += 0.01;
            }
            let b = Intrinsics::from_params(m, &q).unwrap();
            let rays = grid_rays(&a, 1280, 960);
            let (closed, reference) = (
                mapping_error_rot_of(&rays, &b),
                rot_by_differences(&rays, &b),
            );
            let plain = mapping_error_of(&rays, &b);
            assert!(
                closed < 0.9 * plain,
                "{m}: {closed} against {plain} unrotated"
            );
            assert!(
                (closed - reference).abs() < 1e-7,
                "{m}: {closed} against {reference}"
            );
        }
    }

    #[test]
    fn rotation_removes_a_principal_point_shift() {
        // A small principal-point shift is nearly a rotation; the rotated error is far smaller.
        let a = lens();
        let b = a.with_param("cx", a.cx() + 2.0);
        let plain = mapping_error(&a, &b, 640, 480);
        let rot = mapping_error_rot(&a, &b, 640, 480);
        assert!(plain > 1.9, "{plain}");
        assert!(rot < 0.2 * plain, "{rot} vs {plain}");
    }
}
