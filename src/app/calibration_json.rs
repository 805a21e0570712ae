//! The `calibration.json` schema (SPEC §5): what a calibration writes and what
//! `export` and the C API read back.
use crate::model::board::Paraboloid;
use crate::model::lens::{Intrinsics, LensModel};
use crate::solver::calibrate::{Calibration, Stage};
use serde::{Deserialize, Deserializer, Serialize};

/// serde_json writes a NaN as `null`; read it back as NaN so a file deformcal wrote
/// can always be exported again.
fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// One camera in `calibration.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraJson {
    pub name: String,
    pub model: LensModel,
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
}

impl CalibrationJson {
    /// Every camera's intrinsics are of the model the camera names: the keys of
    /// `intrinsics` pick a model, and a file edited by hand may disagree.
    pub fn check_models(&self) -> std::result::Result<(), String> {
        for (k, cam) in self.cameras.iter().enumerate() {
            if cam.intrinsics.model() != cam.model {
                return Err(format!(
                    "cameras[{k}] `{}`: model `{}` needs the intrinsics {}, but they are those of `{}`",
                    cam.name,
                    cam.model,
                    cam.model.param_names().join(", "),
                    cam.intrinsics.model()
                ));
            }
        }
        Ok(())
    }
}

/// One frame in `calibration.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameJson {
    pub frame: i64,
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub deformation: Option<Paraboloid>,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub max_out_of_plane_m: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub rmse_px: f64,
    pub observations: usize,
}

/// The whole `calibration.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationJson {
    pub method: String,
    #[serde(deserialize_with = "nan_if_null")]
    pub rmse_px: f64,
    pub observations: usize,
    /// Observations removed by outlier rejection (listed in `outliers.csv`).
    #[serde(default)]
    pub rejected_observations: usize,
    /// σ̂, the detector noise per coordinate (SPEC §3a), and where it came from.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub noise_px: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub noise_source: Option<String>,
    /// The share of the residual that the noise does not explain (SPEC §3a).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub bias_ratio: Option<f64>,
    /// Geometric AIC, pixels² (SPEC §3a).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub g_aic: Option<f64>,
    /// Free parameters after the gauge.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub parameters: Option<usize>,
    pub converged: bool,
    pub iterations: i32,
    #[serde(deserialize_with = "nan_if_null")]
    pub seconds: f64,
    pub cameras: Vec<CameraJson>,
    pub frames: Vec<FrameJson>,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub static_correction: Option<Vec<[f64; 3]>>,
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub gauge_corners: Vec<usize>,
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub frozen_corners: Vec<usize>,
    pub initial_intrinsics: Vec<Intrinsics>,
    pub stages: Vec<StageJson>,
    pub warnings: Vec<String>,
}

/// A solver stage in `calibration.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageJson {
    pub method: String,
    pub converged: bool,
    pub iterations: i32,
    #[serde(deserialize_with = "nan_if_null")]
    pub initial_cost: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub final_cost: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub seconds: f64,
    pub linear_solver: String,
    pub message: String,
}

impl From<&Stage> for StageJson {
    fn from(s: &Stage) -> Self {
        StageJson {
            method: s.method.name().into(),
            converged: s.converged,
            iterations: s.iterations,
            initial_cost: s.initial_cost,
            final_cost: s.final_cost,
            seconds: s.seconds,
            linear_solver: s.linear_solver.clone(),
            message: s.message.clone(),
        }
    }
}

impl From<&Calibration> for CalibrationJson {
    fn from(c: &Calibration) -> Self {
        let d = &c.dataset;
        let mut sq = vec![0.0; d.num_frames()];
        let mut n = vec![0usize; d.num_frames()];
        for v in c.view_residuals() {
            sq[v.frame] += v.sum_sq_px2;
            n[v.frame] += v.observations;
        }
        let bends = c.method.has_paraboloid();
        let trust = c.trust(c.detector_noise_px);
        CalibrationJson {
            method: c.method.name().into(),
            rmse_px: c.rmse_px,
            observations: d.observations.len(),
            rejected_observations: c.rejected.len(),
            noise_px: trust.map(|t| t.noise_px),
            noise_source: trust.map(|t| t.noise_source.to_string()),
            bias_ratio: trust.map(|t| t.bias_ratio),
            g_aic: trust.map(|t| t.g_aic),
            parameters: trust.map(|t| t.parameters),
            converged: c.converged,
            iterations: c.iterations(),
            seconds: c.seconds,
            cameras: d
                .cameras
                .iter()
                .enumerate()
                .map(|(k, cam)| CameraJson {
                    name: cam.name.clone(),
                    model: cam.model,
                    width: cam.width,
                    height: cam.height,
                    intrinsics: c.state.intrinsics[k],
                    rotation: c.state.camera_poses[k].rotation,
                    translation: c.state.camera_poses[k].translation,
                })
                .collect(),
            frames: (0..d.num_frames())
                .map(|j| {
                    let pose = c.state.frame_poses[j];
                    let bend = c.state.deformations[j];
                    FrameJson {
                        frame: d.frame_ids[j],
                        rotation: pose.rotation,
                        translation: pose.translation,
                        deformation: bends.then_some(bend),
                        max_out_of_plane_m: bends.then(|| bend.max_out_of_plane(&d.target)),
                        rmse_px: if n[j] > 0 {
                            (sq[j] / n[j] as f64).sqrt()
                        } else {
                            f64::NAN
                        },
                        observations: n[j],
                    }
                })
                .collect(),
            static_correction: c
                .method
                .has_correction()
                .then(|| c.state.corrections.clone()),
            gauge_corners: c.gauge.clone(),
            frozen_corners: c.frozen.clone(),
            initial_intrinsics: c.initial_intrinsics.clone(),
            stages: c.stages.iter().map(StageJson::from).collect(),
            warnings: c.warnings.clone(),
        }
    }
}
