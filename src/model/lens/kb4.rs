//! `kb4`: Kannala-Brandt equidistant fisheye, OpenCV `fisheye`, ROS
//! `equidistant`, Kalibr `pinhole-equi` (`cpp/lens/kb4.h` is its C++ side).
use super::info::{ColmapForm, KalibrForm, LensInfo, OpenCvForm};
use super::projection::Projection;
use nalgebra::{Vector2, Vector3};

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

/// The angle θ ∈ [0, π) with θd(θ) = `target` on the increasing branch.
fn theta_of(p: &[f64], target: f64) -> Option<f64> {
    let slope = |t: f64| {
        let t2 = t * t;
        1.0 + t2 * (3.0 * p[4] + t2 * (5.0 * p[5] + t2 * (7.0 * p[6] + t2 * 9.0 * p[7])))
    };
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
    projection: Projection::Central { project, unproject },
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
