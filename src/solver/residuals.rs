//! The residual of every view (camera × frame) of a finished calibration: the one
//! place per-image figures (`calibration.json`'s per-frame RMSE, the report's
//! bars) come from.
use crate::solver::calibrate::Calibration;

/// The residual of one view: what one camera saw in one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewResidual {
    /// Camera index.
    pub camera: usize,
    /// Dense frame index into the dataset's `frame_ids`.
    pub frame: usize,
    /// Observations of the view.
    pub observations: usize,
    /// Σ‖u − p‖² over the view's observations, pixels².
    pub sum_sq_px2: f64,
}

impl ViewResidual {
    /// √(Σ‖u − p‖² / n), pixels.
    pub fn rmse_px(&self) -> f64 {
        (self.sum_sq_px2 / self.observations.max(1) as f64).sqrt()
    }
}

impl Calibration {
    /// Every view with at least one observation, camera by camera in frame order.
    pub fn view_residuals(&self) -> Vec<ViewResidual> {
        let frames = self.dataset.num_frames();
        let cameras = self.dataset.cameras.len();
        let mut sums = vec![(0usize, 0.0f64); frames * cameras];
        for (o, r) in self
            .dataset
            .observations
            .iter()
            .zip(self.residuals.chunks(2))
        {
            let s = &mut sums[o.camera * frames + o.frame];
            s.0 += 1;
            s.1 += r[0] * r[0] + r[1] * r[1];
        }
        sums.iter()
            .enumerate()
            .filter(|(_, s)| s.0 > 0)
            .map(|(i, &(n, sq))| ViewResidual {
                camera: i / frames,
                frame: i % frames,
                observations: n,
                sum_sq_px2: sq,
            })
            .collect()
    }
}
