//! A camera as the user describes it: name, image size, lens model and the
//! parameters held at their initial values.
use crate::model::lens::LensModel;

/// A camera of the rig.
#[derive(Debug, Clone, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub name: String,
    pub width: u32,
    pub height: u32,
    #[serde(default)]
    pub model: LensModel,
    /// Lens parameters held at their initial values (OpenCV's `CALIB_FIX_*`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fix: Vec<String>,
}

impl CameraSpec {
    /// A camera with the given name, size and lens model, nothing held.
    pub fn new(name: impl Into<String>, width: u32, height: u32, model: LensModel) -> Self {
        CameraSpec {
            name: name.into(),
            width,
            height,
            model,
            fix: Vec::new(),
        }
    }

    /// Per lens parameter: held at its initial value.
    pub fn held(&self) -> Vec<bool> {
        self.model
            .param_names()
            .iter()
            .map(|p| self.fix.iter().any(|f| f == p))
            .collect()
    }

    /// The first name in `fix` that the lens model does not have.
    pub fn unknown_fixed(&self) -> Option<&str> {
        self.fix
            .iter()
            .find(|f| self.model.param_index(f).is_none())
            .map(String::as_str)
    }
}
