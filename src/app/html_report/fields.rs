//! The numbers behind the calibration report's figures, computed from a
//! [`Calibration`]: the views worst first, the residual arrows to draw (every
//! k-th when there are too many), the lens's displacement from its own pinhole over
//! the image, and contour lines of a field. No drawing here (`figures` draws).
use crate::model::lens::Intrinsics;
use crate::solver::calibrate::Calibration;
use crate::solver::residuals::ViewResidual;
use nalgebra::{Vector2, Vector3};

/// Every view's residual, worst first (ties in frame order).
pub fn views_worst_first(c: &Calibration) -> Vec<ViewResidual> {
    let mut out = c.view_residuals();
    out.sort_by(|a, b| {
        b.rmse_px()
            .total_cmp(&a.rmse_px())
            .then(a.frame.cmp(&b.frame))
    });
    out
}

/// Most residual arrows drawn per camera: beyond it every k-th is drawn, so a
/// 400-image run still gives a report of a few megabytes at most.
pub const MAX_ARROWS: usize = 2500;

/// A camera's residual arrows: (observed pixel, residual observed − projected).
#[derive(Debug, Clone, PartialEq)]
pub struct Arrows {
    /// The arrows drawn: (observed pixel, residual).
    pub arrows: Vec<([f64; 2], [f64; 2])>,
    /// The camera's observations.
    pub total: usize,
    /// Every `stride`-th observation is drawn (1: all).
    pub stride: usize,
    /// RMS of all the camera's residuals, pixels.
    pub rms_px: f64,
}

/// The residual arrows of camera `k`, every k-th beyond [`MAX_ARROWS`].
pub fn residual_arrows(c: &Calibration, camera: usize) -> Arrows {
    let all: Vec<([f64; 2], [f64; 2])> = c
        .dataset
        .observations
        .iter()
        .zip(c.residuals.chunks(2))
        .filter(|(o, _)| o.camera == camera)
        .map(|(o, r)| (o.uv, [r[0], r[1]]))
        .collect();
    let total = all.len();
    let stride = total.div_ceil(MAX_ARROWS).max(1);
    let rms_px = (all
        .iter()
        .map(|(_, r)| r[0] * r[0] + r[1] * r[1])
        .sum::<f64>()
        / total.max(1) as f64)
        .sqrt();
    Arrows {
        arrows: all.into_iter().step_by(stride).collect(),
        total,
        stride,
        rms_px,
    }
}

/// Values on a regular grid of cell centres over an image, row-major (x fastest).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid<T> {
    /// Cells across.
    pub nx: usize,
    /// Cells down.
    pub ny: usize,
    /// Cell size in pixels.
    pub dx: f64,
    /// Cell height in pixels.
    pub dy: f64,
    /// One value per cell, row-major.
    pub values: Vec<T>,
}

impl<T> Grid<T> {
    /// The pixel at the centre of cell (i, j).
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            (i as f64 + 0.5) * self.dx - 0.5,
            (j as f64 + 0.5) * self.dy - 0.5,
        )
    }

    /// The pixel at fractional cell coordinates (as [`crate::app::plots::contour_segments`] returns).
    pub fn pixel(&self, (gx, gy): (f64, f64)) -> (f64, f64) {
        ((gx + 0.5) * self.dx - 0.5, (gy + 0.5) * self.dy - 0.5)
    }
}

/// Where the lens moves each pixel's ray relative to a distortion-free pinhole
/// with the same fx, fy, cx, cy: `pixel − pinhole(unproject(pixel))`, over an
/// `nx × ny` grid of the `width × height` image. `None` where the pixel has no ray
/// or the ray is 90° or more off axis (a pinhole has no image of it).
pub fn distortion_field(
    k: &Intrinsics,
    width: u32,
    height: u32,
    nx: usize,
    ny: usize,
) -> Grid<Option<[f64; 2]>> {
    let (dx, dy) = (width as f64 / nx as f64, height as f64 / ny as f64);
    let mut grid = Grid {
        nx,
        ny,
        dx,
        dy,
        values: Vec::with_capacity(nx * ny),
    };
    for j in 0..ny {
        for i in 0..nx {
            let (u, v) = grid.centre(i, j);
            grid.values.push(displacement(k, u, v));
        }
    }
    grid
}

/// `pixel − pinhole(ray)` of one pixel; see [`distortion_field`].
pub fn displacement(k: &Intrinsics, u: f64, v: f64) -> Option<[f64; 2]> {
    let ray: Vector3<f64> = k.unproject(&Vector2::new(u, v))?;
    if ray.z <= 1e-9 {
        return None;
    }
    let pu = k.fx() * ray.x / ray.z + k.cx();
    let pv = k.fy() * ray.y / ray.z + k.cy();
    Some([u - pu, v - pv])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pinhole_has_no_displacement_and_barrel_distortion_points_inward() {
        let pinhole = Intrinsics::pinhole(800.0, 800.0, 320.0, 240.0);
        let d = displacement(&pinhole, 600.0, 400.0).unwrap();
        assert!(d[0].abs() < 1e-9 && d[1].abs() < 1e-9);
        // Closed form: the ray (0.3, 0.2, 1) lands at f·x'·d + c with d = 1 + k1·r²,
        // its pinhole image at f·x' + c; their difference is f·x'·k1·r².
        let barrel = Intrinsics::radial3([800.0, 800.0, 320.0, 240.0, -0.2, 0.0, 0.0]);
        let d_r = -0.2 * 0.13;
        let (u, v) = (
            800.0 * 0.3 * (1.0 + d_r) + 320.0,
            800.0 * 0.2 * (1.0 + d_r) + 240.0,
        );
        let d = displacement(&barrel, u, v).unwrap();
        assert!((d[0] - 800.0 * 0.3 * d_r).abs() < 1e-9, "{d:?}");
        assert!((d[1] - 800.0 * 0.2 * d_r).abs() < 1e-9, "{d:?}");
    }
}
