//! A pixel's closed-form derivatives by the intrinsics and by the camera-frame
//! point, for any registered model: the chain through the model's own
//! derivatives (`Projection`) and the last, affine step (fx mx + cx, fy my + cy).
//! What uses them (the advice's information sums) is the caller's.
use super::intrinsics::Intrinsics;
use super::model::MAX_PARAMS;
use super::projection::{PointDerivatives, Projection};
use nalgebra::{Matrix2x3, Vector2, Vector3};

/// A pixel and its derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelDerivatives {
    /// The pixel, [`Intrinsics::project`]'s to the bit.
    pub uv: Vector2<f64>,
    /// ∂uv/∂θ (the first `num_params` columns of each row hold them).
    pub d_params: [[f64; MAX_PARAMS]; 2],
    /// ∂uv/∂x_c.
    pub d_point: Matrix2x3<f64>,
}

impl Intrinsics {
    /// Projects a camera-frame point with the pixel's derivatives, in closed
    /// form; `None` where [`Intrinsics::project`] has no image.
    pub fn project_with_derivatives(&self, xc: &Vector3<f64>) -> Option<PixelDerivatives> {
        let p = self.params();
        let m = match self.model().info().projection {
            Projection::PinholeLike { derivatives, .. } => {
                if xc.z <= 0.0 {
                    return None;
                }
                let (x, y) = (xc.x / xc.z, xc.y / xc.z);
                let d = derivatives(p, x, y);
                // ∂(x, y)/∂x_c of the pinhole image (x/z, y/z).
                let iz = 1.0 / xc.z;
                let pinhole = Matrix2x3::new(iz, 0.0, -x * iz, 0.0, iz, -y * iz);
                PointDerivatives {
                    value: d.value,
                    d_input: d.d_input * pinhole,
                    d_params: d.d_params,
                }
            }
            Projection::Central { derivatives, .. } => derivatives(p, xc)?,
        };
        let (fx, fy) = (p[0], p[1]);
        let mut d_params = [[0.0; MAX_PARAMS]; 2];
        [d_params[0][0], d_params[0][2]] = [m.value.x, 1.0];
        [d_params[1][1], d_params[1][3]] = [m.value.y, 1.0];
        for i in 0..p.len() - 4 {
            d_params[0][4 + i] = fx * m.d_params[0][i];
            d_params[1][4 + i] = fy * m.d_params[1][i];
        }
        let mut d_point = m.d_input;
        d_point.row_mut(0).scale_mut(fx);
        d_point.row_mut(1).scale_mut(fy);
        Some(PixelDerivatives {
            uv: Vector2::new(fx * m.value.x + p[2], fy * m.value.y + p[3]),
            d_params,
            d_point,
        })
    }
}

#[cfg(test)]
#[path = "derivatives_tests.rs"]
mod tests;
