//! What the pinhole-like models share: the inversion of their distortion by
//! Newton's method.
use nalgebra::{Matrix2, Vector2};

/// A distortion of normalised coordinates: parameters in solver order, (x', y').
pub(super) type Distort = fn(&[f64], f64, f64) -> Vector2<f64>;

/// Normalised coordinates whose distortion is `m`, by Newton's method with the
/// distortion's Jacobian; `None` where it does not converge or the map folds.
pub(super) fn undistort(distort: Distort, p: &[f64], m: &Vector2<f64>) -> Option<Vector2<f64>> {
    let mut x = *m;
    for _ in 0..100 {
        let j = jacobian(distort, p, &x);
        if j.determinant() <= 0.0 {
            return None;
        }
        let step = j.lu().solve(&(distort(p, x.x, x.y) - m))?;
        x -= step;
        if !x.x.is_finite() || !x.y.is_finite() {
            return None;
        }
        if step.norm() < 1e-16 * (1.0 + x.norm()) {
            break;
        }
    }
    ((distort(p, x.x, x.y) - m).norm() < 1e-12 && jacobian(distort, p, &x).determinant() > 0.0)
        .then_some(x)
}

/// ∂distort/∂(x', y') by central differences: exact enough for Newton's
/// direction, whose fixed point does not depend on it.
fn jacobian(distort: Distort, p: &[f64], x: &Vector2<f64>) -> Matrix2<f64> {
    let h = 1e-7 * (1.0 + x.norm());
    let dx = (distort(p, x.x + h, x.y) - distort(p, x.x - h, x.y)) / (2.0 * h);
    let dy = (distort(p, x.x, x.y + h) - distort(p, x.x, x.y - h)) / (2.0 * h);
    Matrix2::new(dx.x, dy.x, dx.y, dy.y)
}
