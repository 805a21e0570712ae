//! The trust figures of a finished calibration: how many parameters it had free
//! and how much of its residual the detector noise explains (`model::trust`).
use crate::model::trust::{self, Trust};
use crate::solver::calibrate::Calibration;

impl Calibration {
    /// p: the parameters the solve had free, the gauge and held values excluded.
    pub fn free_parameters(&self) -> usize {
        let d = &self.dataset;
        let info = self.method.info();
        let lens: usize = d
            .cameras
            .iter()
            .map(|c| c.held().iter().filter(|h| !**h).count())
            .sum();
        let rig = 6 * d.cameras.len().saturating_sub(1);
        let frames = (6 + info.frame_params) * d.num_frames();
        let corrections = if info.corner_params == 0 {
            0
        } else {
            let mut seen = vec![false; d.target.num_corners()];
            for o in &d.observations {
                seen[o.corner] = true;
            }
            let free = (0..seen.len())
                .filter(|&c| seen[c] && !self.frozen.contains(&c))
                .count();
            (info.corner_params * free).saturating_sub(info.gauge_dof)
        };
        lens + rig + frames + corrections
    }

    /// Noise, bias ratio and G-AIC computed afresh at `noise_px` (the pipeline's
    /// own, at the calibration's noise, are in [`Calibration::assessment`]);
    /// σ̂ is `noise_px` when given, else estimated
    /// from neighbouring corners' residuals. Both are in units of a weight-1
    /// corner (weighted residuals), as the covariance is. `None` without a noise
    /// estimate.
    pub fn trust(&self, noise_px: Option<f64>) -> Option<Trust> {
        let (noise, source) = match noise_px {
            Some(n) => (n, "config"),
            None => (
                trust::noise_from_neighbours(&self.dataset, &self.residuals)?,
                "neighbours",
            ),
        };
        Some(trust::assess(
            &trust::weighted(&self.dataset, &self.residuals),
            self.free_parameters(),
            noise,
            source,
        ))
    }
}
