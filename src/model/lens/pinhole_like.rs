//! What the pinhole-like models share: the inversion of their distortion by
//! Newton's method.
use super::projection::DistortionDerivatives;
use nalgebra::Vector2;

/// A distortion of normalised coordinates with its closed-form derivatives:
/// parameters in solver order, (x', y').
pub(super) type Derivatives = fn(&[f64], f64, f64) -> DistortionDerivatives;

/// Normalised coordinates whose distortion is `m`, by Newton's method with the
/// distortion's closed-form Jacobian (one evaluation per step; the central
/// differences it replaced cost four more and gave the same fixed point);
/// `None` where it does not converge or the map folds.
pub(super) fn undistort(
    derivatives: Derivatives,
    p: &[f64],
    m: &Vector2<f64>,
) -> Option<Vector2<f64>> {
    let mut x = *m;
    let mut at = derivatives(p, x.x, x.y);
    for _ in 0..100 {
        let j = at.d_input;
        let det = j.determinant();
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        let r = at.value - m;
        // The 2×2 inverse in closed form: J⁻¹ = [[j11, −j01], [−j10, j00]] / det.
        let step = Vector2::new(
            (j[(1, 1)] * r.x - j[(0, 1)] * r.y) / det,
            (j[(0, 0)] * r.y - j[(1, 0)] * r.x) / det,
        );
        x -= step;
        if !x.x.is_finite() || !x.y.is_finite() {
            return None;
        }
        at = derivatives(p, x.x, x.y);
        if step.norm() < 1e-16 * (1.0 + x.norm()) {
            break;
        }
    }
    ((at.value - m).norm() < 1e-12 && at.d_input.determinant() > 0.0).then_some(x)
}
