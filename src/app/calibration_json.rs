//! The `calibration.json` schema (docs/conventions.md §5): what a calibration writes and what
//! `export`, `sfm` and `compare` read back (one reader, [`CalibrationJson::load`],
//! which refuses what cannot be used).
use crate::model::board::Paraboloid;
use crate::model::lens::{Intrinsics, LensModel};
use crate::model::selection::Selection;
use crate::model::uncertainty::CameraUncertainty;
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
    /// This camera's RMSE over its own observations (docs/conventions.md §3's `rmse_px`, per camera).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub rmse_px: Option<f64>,
    /// What the noise alone leaves uncertain (docs/conventions.md §3a); absent when unavailable
    /// (the reason is in `uncertainty_note`).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub uncertainty: Option<UncertaintyJson>,
}

/// One camera's uncertainty in `calibration.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UncertaintyJson {
    /// σ of each estimated lens parameter, in the parameter's unit; parameters
    /// held at their values (`fix`) are not listed.
    pub intrinsics_std: NamedValues,
    #[serde(deserialize_with = "nan_if_null")]
    pub expected_mapping_error_px: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub expected_mapping_error_rot_px: f64,
}

impl From<&CameraUncertainty> for UncertaintyJson {
    fn from(u: &CameraUncertainty) -> Self {
        UncertaintyJson {
            intrinsics_std: NamedValues(
                u.intrinsics_std
                    .iter()
                    .map(|(n, v)| (n.to_string(), *v))
                    .collect(),
            ),
            expected_mapping_error_px: u.expected_mapping_error_px,
            expected_mapping_error_rot_px: u.expected_mapping_error_rot_px,
        }
    }
}

/// A JSON object of numbers that keeps its keys in the order written (the lens
/// parameters' order), unlike a map type.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NamedValues(pub Vec<(String, f64)>);

impl NamedValues {
    /// The value of `name`, if listed.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| *v)
    }
}

impl Serialize for NamedValues {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (name, v) in &self.0 {
            map.serialize_entry(name, v)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for NamedValues {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = NamedValues;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object of numbers")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<Self::Value, A::Error> {
                let mut out = Vec::new();
                while let Some((name, v)) = map.next_entry::<String, Option<f64>>()? {
                    if out.iter().any(|(n, _): &(String, f64)| *n == name) {
                        return Err(serde::de::Error::custom(format!("`{name}` is given twice")));
                    }
                    out.push((name, v.unwrap_or(f64::NAN)));
                }
                Ok(NamedValues(out))
            }
        }
        d.deserialize_map(Visitor)
    }
}

/// Largest image side `calibration.json` may give, pixels: several times the
/// largest single sensors, and small enough that a grid over the image stays cheap.
pub const MAX_IMAGE_SIDE: u32 = 100_000;

impl CalibrationJson {
    /// Reads a `calibration.json` deformcal wrote for use (export, sfm, compare):
    /// refuses a failed calibration and cameras whose size or intrinsics cannot
    /// describe a camera, naming the file (see [`CalibrationJson::check`]).
    pub fn load(path: &std::path::Path) -> crate::Result<CalibrationJson> {
        let text = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_DATA_BYTES)?;
        let json: CalibrationJson =
            serde_json::from_slice(&text).map_err(|e| crate::Error::Data {
                path: path.to_path_buf(),
                line: e.line() as u64,
                message: format!("not a deformcal calibration.json: {e}"),
            })?;
        // A whole-file problem has no line to name, so the file alone is named.
        json.check().map_err(|message| crate::Error::Config {
            path: path.to_path_buf(),
            message,
        })?;
        Ok(json)
    }

    /// Whether the calibration can be used: it did not fail its guard rails, has
    /// a camera, and every camera has a size and intrinsics of its model that are
    /// finite with positive focal lengths.
    pub fn check(&self) -> std::result::Result<(), String> {
        if let Some(f) = &self.failure {
            return Err(format!(
                "this calibration FAILED its guard rails ({}); it cannot be used",
                f.reasons.join("; ")
            ));
        }
        if self.cameras.is_empty() {
            return Err("`cameras` is empty: no camera to use".into());
        }
        self.check_models()?;
        for (k, cam) in self.cameras.iter().enumerate() {
            let at = format!("cameras[{k}] `{}`", crate::app::text::short(&cam.name));
            for (key, side) in [("width", cam.width), ("height", cam.height)] {
                if !(1..=MAX_IMAGE_SIDE).contains(&side) {
                    return Err(format!(
                        "{at}: {key} must be 1 to {MAX_IMAGE_SIDE} pixels (got {side})"
                    ));
                }
            }
            for (name, v) in cam.intrinsics.named() {
                if !v.is_finite() {
                    return Err(format!("{at}: intrinsics.{name} is not finite ({v})"));
                }
            }
            for (name, v) in [("fx", cam.intrinsics.fx()), ("fy", cam.intrinsics.fy())] {
                if v <= 0.0 {
                    return Err(format!(
                        "{at}: intrinsics.{name} must be positive (got {v})"
                    ));
                }
            }
        }
        Ok(())
    }

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
    /// The degree-3 and -4 bend coefficients (x³, x²y, xy², y³, x⁴, x³y, x²y², xy³,
    /// y⁴; zero beyond the order) of `bend_order` 3 or 4.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub higher_bend: Option<Vec<f64>>,
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
    /// σ̂, the detector noise per coordinate (docs/conventions.md §3a), and where it came from.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub noise_px: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub noise_source: Option<String>,
    /// The share of the residual that the noise does not explain (docs/conventions.md §3a).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub bias_ratio: Option<f64>,
    /// Geometric AIC, pixels² (docs/conventions.md §3a).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub g_aic: Option<f64>,
    /// Free parameters after the gauge.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub parameters: Option<usize>,
    /// Why the cameras have no `uncertainty` (a singular problem, no noise estimate).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub uncertainty_note: Option<String>,
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
    /// With `method = "auto"`: every candidate's figures and why `method` was chosen.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub auto: Option<Selection>,
    /// Why the calibration failed its guard rails; such a file is written as
    /// `FAILED-calibration.json` and its models are not exported.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub failure: Option<crate::app::guard::Failure>,
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

/// The cameras of a calibration, with their uncertainty where there is one.
fn cameras_json(
    c: &Calibration,
    uncertainty: Option<&Vec<CameraUncertainty>>,
    rmse: &[Option<f64>],
) -> Vec<CameraJson> {
    c.dataset
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
            rmse_px: rmse[k],
            uncertainty: uncertainty
                .and_then(|u| u.get(k))
                .map(UncertaintyJson::from),
        })
        .collect()
}

impl From<&Calibration> for CalibrationJson {
    fn from(c: &Calibration) -> Self {
        let d = &c.dataset;
        let (mut sq, mut n) = (vec![0.0; d.num_frames()], vec![0usize; d.num_frames()]);
        let (mut cam_sq, mut cam_n) = (vec![0.0; d.cameras.len()], vec![0usize; d.cameras.len()]);
        for v in c.view_residuals() {
            sq[v.frame] += v.sum_sq_px2;
            n[v.frame] += v.observations;
            cam_sq[v.camera] += v.sum_sq_px2;
            cam_n[v.camera] += v.observations;
        }
        let bends = c.method.has_paraboloid();
        let trust = c.assessment.trust;
        let uncertainty = &c.assessment.uncertainty;
        let camera_rmse: Vec<Option<f64>> = cam_sq
            .iter()
            .zip(&cam_n)
            .map(|(sq, &n)| (n > 0).then(|| (sq / n as f64).sqrt()))
            .collect();
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
            uncertainty_note: uncertainty
                .as_ref()
                .err()
                .map(|e| format!("uncertainty unavailable: {e}")),
            converged: c.converged,
            iterations: c.iterations(),
            seconds: c.seconds,
            cameras: cameras_json(c, uncertainty.as_ref().ok(), &camera_rmse),
            frames: (0..d.num_frames())
                .map(|j| {
                    let pose = c.state.frame_poses[j];
                    let bend = c.state.deformations[j];
                    FrameJson {
                        frame: d.frame_ids[j],
                        rotation: pose.rotation,
                        translation: pose.translation,
                        deformation: bends.then_some(bend),
                        higher_bend: (c.method.bend_order() > 2)
                            .then(|| c.state.higher_bends[j].to_vec()),
                        max_out_of_plane_m: bends.then(|| {
                            crate::model::board::max_bend(
                                &d.target,
                                &bend,
                                &c.state.higher_bends[j],
                            )
                        }),
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
            auto: c.selection.clone(),
            failure: None,
        }
    }
}
