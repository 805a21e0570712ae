//! `kb4`: Kannala-Brandt equidistant fisheye, OpenCV `fisheye`, ROS
//! `equidistant`, Kalibr `pinhole-equi` (`cpp/lens/kb4.h` is its C++ side).
use super::info::{ColmapForm, KalibrForm, LensInfo, OpenCvForm};
use super::projection::{PointDerivatives, Projection, MAX_DISTORTION};
use nalgebra::{Matrix2x3, Vector2, Vector3};

/// m = (x, y) θd(θ) / r with θ = atan2(r, z); (x, y) / z on the axis.
fn project(p: &[f64], xc: &Vector3<f64>) -> Option<Vector2<f64>> {
    let r2 = xc.x * xc.x + xc.y * xc.y;
    if r2 < 1e-30 * xc.z * xc.z {
        if xc.z <= 0.0 {
            return None;
        }
        Some(Vector2::new(xc.x / xc.z, xc.y / xc.z))
    } else {
        let r = r2.sqrt();
        let theta = r.atan2(xc.z);
        let s = theta_d(p, theta) / r;
        Some(Vector2::new(xc.x * s, xc.y * s))
    }
}

/// The ray at θ(|m|) in the direction of m.
/// [`project`] with its derivatives. m = (x, y) s with s = θd(θ)/r, θ = atan2(r, z):
/// ∇s = θd′(θ) ∇θ / r − θd ∇r / r², ∇r = (x, y, 0)/r, ∇θ = (z x/r, z y/r, −r)/ρ²
/// (ρ² = r² + z²). The (x, y) parts of the two terms nearly cancel close to the
/// axis; their difference times x or y stays within a few ulps of s.
fn derivatives(p: &[f64], xc: &Vector3<f64>) -> Option<PointDerivatives> {
    let mut d_params = [[0.0; MAX_DISTORTION]; 2];
    let r2 = xc.x * xc.x + xc.y * xc.y;
    if r2 < 1e-30 * xc.z * xc.z {
        if xc.z <= 0.0 {
            return None;
        }
        // The pinhole's derivatives: θd's higher terms vanish to third order.
        let value = Vector2::new(xc.x / xc.z, xc.y / xc.z);
        let iz = 1.0 / xc.z;
        let d_input = Matrix2x3::new(iz, 0.0, -value.x * iz, 0.0, iz, -value.y * iz);
        return Some(PointDerivatives {
            value,
            d_input,
            d_params,
        });
    }
    let r = r2.sqrt();
    let theta = r.atan2(xc.z);
    let td = theta_d(p, theta);
    let s = td / r;
    let rho2 = r2 + xc.z * xc.z;
    let slope = theta_d_slope(p, theta);
    let a = slope * xc.z / (r2 * rho2) - td / (r2 * r);
    let grad = Vector3::new(a * xc.x, a * xc.y, -slope / rho2);
    let d_input = Matrix2x3::new(
        s + xc.x * grad.x,
        xc.x * grad.y,
        xc.x * grad.z,
        xc.y * grad.x,
        s + xc.y * grad.y,
        xc.y * grad.z,
    );
    // ∂θd/∂k_i = θ^(2i+3).
    let t2 = theta * theta;
    let mut power = theta * t2;
    let [dx, dy] = &mut d_params;
    for (ux, uy) in dx.iter_mut().zip(dy.iter_mut()).take(4) {
        [*ux, *uy] = [xc.x * power / r, xc.y * power / r];
        power *= t2;
    }
    Some(PointDerivatives {
        value: Vector2::new(xc.x * s, xc.y * s),
        d_input,
        d_params,
    })
}

fn unproject(p: &[f64], m: &Vector2<f64>) -> Option<Vector3<f64>> {
    let theta_d = m.norm();
    if theta_d < 1e-15 {
        return Some(Vector3::new(m.x, m.y, 1.0));
    }
    let theta = theta_of(p, theta_d)?;
    let s = theta.sin() / theta_d;
    Some(Vector3::new(m.x * s, m.y * s, theta.cos()))
}

/// θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸).
fn theta_d(p: &[f64], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7]))))
}

/// dθd/dθ.
fn theta_d_slope(p: &[f64], theta: f64) -> f64 {
    let t2 = theta * theta;
    1.0 + t2 * (3.0 * p[4] + t2 * (5.0 * p[5] + t2 * (7.0 * p[6] + t2 * 9.0 * p[7])))
}

/// The angle θ ∈ [0, π) with θd(θ) = `target` on the increasing branch.
fn theta_of(p: &[f64], target: f64) -> Option<f64> {
    let slope = |t: f64| theta_d_slope(p, t);
    let mut theta = target.min(3.0);
    for _ in 0..100 {
        let g = slope(theta);
        if g <= 0.0 {
            return None;
        }
        let step = (theta_d(p, theta) - target) / g;
        theta -= step;
        if !(0.0..std::f64::consts::PI).contains(&theta) {
            return None;
        }
        if step.abs() < 1e-16 * (1.0 + theta) {
            break;
        }
    }
    ((theta_d(p, theta) - target).abs() < 1e-12 && slope(theta) > 0.0).then_some(theta)
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "kb4",
    params: &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
    help: "Kannala-Brandt equidistant fisheye (OpenCV fisheye)",
    pinhole_like: false,
    projection: Projection::Central {
        project,
        unproject,
        derivatives,
    },
    undistorted: &[0.0; 4],
    // A fisheye whose image corners lie about 95° off axis.
    synthetic: &[690.0, 689.2, 971.6, 606.4, 0.02, -0.012, 0.004, -6e-4],
    prior_params: &[],
    second_start: None,
    opencv: Some(OpenCvForm {
        distortion_model: "fisheye",
        coefficients: &["k1", "k2", "k3", "k4"],
        fisheye: true,
    }),
    ros: Some("equidistant"),
    kalibr: Some(KalibrForm {
        name: "pinhole-equi",
        camera_model: "pinhole",
        intrinsics: &["fx", "fy", "cx", "cy"],
        distortion_model: "equidistant",
        coefficients: &["k1", "k2", "k3", "k4"],
        requires_zero: &[],
    }),
    colmap: &[ColmapForm {
        model: "OPENCV_FISHEYE",
        params: &["k1", "k2", "k3", "k4"],
        requires_zero: &[],
    }],
    mrcal: None,
    mrcal_via: None,
};

#[cfg(test)]
mod tests {
    #[test]
    fn unproject_inverts_project() {
        super::super::tests::round_trips(
            super::INFO.name,
            &[400.0, 401.0, 640.0, 480.0, 0.02, -0.01, 0.003, -5e-4],
        );
    }
}
