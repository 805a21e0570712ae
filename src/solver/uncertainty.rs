//! The uncertainty of a finished calibration (docs/conventions.md §3a): its intrinsics'
//! covariance, computed after every solve (`solver::covariance`) at unit noise,
//! scaled to the noise σ̂ its trust figures use, and the figures in pixels that
//! `model::uncertainty` derives from it.
use crate::model::trust::Trust;
use crate::model::uncertainty::{
    camera_uncertainty, CameraUncertainty, UncertaintyError, UnitCovariance,
};
use crate::solver::calibrate::Calibration;
use nalgebra::DMatrix;

/// Σ_θ of every camera of `c` at unit noise, from the Jacobian at its optimum,
/// and the board's σ where the normal matrix keeps the corrections (what
/// [`Calibration::covariance`] holds).
pub fn unit_covariance(c: &Calibration) -> Result<UnitCovariance, UncertaintyError> {
    crate::solver::covariance::unit_covariance(&c.problem(), &c.state, &c.settings)
}

impl Calibration {
    /// Σ_θ of every camera at the noise σ̂ of `trust`; rows and columns of held
    /// parameters are zero.
    pub fn intrinsics_covariance_at(
        &self,
        trust: Option<&Trust>,
    ) -> Result<Vec<DMatrix<f64>>, UncertaintyError> {
        let noise = trust.ok_or(UncertaintyError::NoNoise)?.noise_px;
        let unit = self.covariance.as_ref().map_err(Clone::clone)?;
        Ok(unit
            .cameras
            .iter()
            .map(|c| &c.unit * (noise * noise))
            .collect())
    }

    /// Every camera's uncertainty figures (docs/conventions.md §3a) at the noise
    /// σ̂ of `trust`.
    pub fn uncertainty_at(
        &self,
        trust: Option<&Trust>,
    ) -> Result<Vec<CameraUncertainty>, UncertaintyError> {
        let sigma = self.intrinsics_covariance_at(trust)?;
        let unit = self.covariance.as_ref().map_err(Clone::clone)?;
        let cameras = self.dataset.cameras.iter().zip(&self.state.intrinsics);
        cameras
            .zip(unit.cameras.iter().zip(&sigma))
            .map(|((cam, k), (cov, sigma))| {
                camera_uncertainty(k, &cov.free, sigma, cam.width, cam.height).ok_or_else(|| {
                    UncertaintyError::Jacobian(format!(
                        "no pixel of camera {} has a ray to measure the mapping error on",
                        cam.name
                    ))
                })
            })
            .collect()
    }

    /// [`Calibration::uncertainty_at`] computed afresh at `detector_noise_px`
    /// (for an analysis that changes it; the pipeline's figures are in
    /// [`Calibration::assessment`]).
    pub fn uncertainty(&self) -> Result<Vec<CameraUncertainty>, UncertaintyError> {
        self.uncertainty_at(self.trust(self.detector_noise_px).as_ref())
    }

    /// Computes [`Calibration::assessment`] from the residuals, the covariance and
    /// `detector_noise_px`. The pipeline does this once, last; a caller that
    /// changes any of them afterwards (a test, an analysis) calls it again.
    pub fn assess(&mut self) {
        let trust = self.trust(self.detector_noise_px);
        let uncertainty = self.uncertainty_at(trust.as_ref());
        self.assessment = crate::solver::calibrate::Assessment { trust, uncertainty };
    }
}
