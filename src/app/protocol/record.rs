//! What a protocol run records: the header a merge checks, one row per
//! subset × method task with its per-camera figures, the reference's summary.
use crate::app::board_json::BoardJson;
use crate::app::config::MAX_SUBSETS;
use crate::error::{Error, Result};
use crate::model::board::{HigherBend, Method, Paraboloid};
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::selection::Selection;
use crate::model::target::Target;
use serde::{Deserialize, Serialize};

/// What a merge needs to know about the run that produced a set of rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The dataset's name (preset name or CSV file).
    pub dataset: String,
    pub subsets: usize,
    pub images_per_subset: usize,
    pub seed: u64,
    pub methods: Vec<Method>,
    pub target: Target,
    pub cameras: Vec<CameraSpec>,
    pub dataset_images: usize,
    pub reference: Option<ReferenceInfo>,
    /// True intrinsics per camera (synthetic data).
    pub truth: Option<Vec<Intrinsics>>,
    /// How `auto` chose per subset, when the run records its choice.
    #[serde(default)]
    pub auto: Option<AutoRun>,
    /// The fingerprint of the data the run saw ([`data_fingerprint`]): shards
    /// computed on other data (another seed, an edited CSV) are not one run.
    pub data: String,
}

/// A fingerprint of the observations a run calibrates from and of its reference
/// set: taken from the loaded data rather than the files, so every source is
/// covered alike (a synthetic preset's seed and image count, CSV or corners.vnl
/// bytes, the detections in photos) and the fingerprint changes exactly when
/// what the calibrations see changes. 64-bit FNV-1a: shards of one run are
/// compared, not guarded against forgery.
pub fn data_fingerprint(dataset: &Dataset, reference: Option<&Dataset>) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for d in std::iter::once(dataset).chain(reference) {
        eat(&(d.frame_ids.len() as u64).to_le_bytes());
        for id in &d.frame_ids {
            eat(&id.to_le_bytes());
        }
        eat(&(d.observations.len() as u64).to_le_bytes());
        for o in &d.observations {
            for n in [o.camera, o.frame, o.corner] {
                eat(&(n as u64).to_le_bytes());
            }
            for x in [o.uv[0], o.uv[1], o.weight] {
                eat(&x.to_bits().to_le_bytes());
            }
        }
    }
    format!(
        "{} observations, fnv1a64 {h:016x}",
        dataset.observations.len()
    )
}

/// `auto`'s settings in a protocol run: every subset gets one more task, which
/// cross-validates these candidates and records the method it keeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoRun {
    pub candidates: Vec<Method>,
    pub folds: usize,
    pub seed: u64,
}

/// What task `t` of the grid runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    /// Calibrate subset `.0` with a fixed method.
    Fixed(usize, Method),
    /// Let `auto` choose a method for subset `.0`.
    Auto(usize),
}

impl Header {
    /// Tasks per subset: the fixed methods, then `auto` if it is recorded.
    fn per_subset(&self) -> usize {
        self.methods.len() + usize::from(self.auto.is_some())
    }

    /// Number of subset × method tasks.
    pub fn tasks(&self) -> usize {
        self.subsets.saturating_mul(self.per_subset())
    }

    /// What task `t` runs (fixed methods first within a subset, `auto` last).
    pub fn task(&self, t: usize) -> Task {
        let per = self.per_subset();
        let (subset, slot) = (t / per, t % per);
        match self.methods.get(slot) {
            Some(&m) => Task::Fixed(subset, m),
            None => Task::Auto(subset),
        }
    }

    /// The task a row answers, if it lies inside this run's grid.
    pub(super) fn slot_of(&self, row: &Row) -> Option<usize> {
        let slot = if row.auto {
            self.auto.as_ref().map(|_| self.methods.len())?
        } else {
            self.methods.iter().position(|&x| x == row.method)?
        };
        let t = row
            .subset
            .checked_mul(self.per_subset())?
            .checked_add(slot)?;
        (t < self.tasks()).then_some(t)
    }

    /// Refuses a header whose sizes are out of bounds (a hand-edited or corrupt
    /// shard file) before anything is allocated from them.
    pub fn check(&self) -> Result<()> {
        if self.subsets == 0 || self.subsets > MAX_SUBSETS {
            return Err(Error::TooLarge(format!(
                "the run claims {} subsets; 1 to {MAX_SUBSETS} are possible",
                self.subsets
            )));
        }
        if (self.methods.is_empty() && self.auto.is_none())
            || self.methods.len() > Method::ALL.len()
        {
            return Err(Error::Invalid(format!(
                "the run claims {} methods; 1 to {} are possible",
                self.methods.len(),
                Method::ALL.len()
            )));
        }
        for (i, m) in self.methods.iter().enumerate() {
            if self.methods[..i].contains(m) {
                return Err(Error::Invalid(format!("method {m} is listed twice")));
            }
        }
        Ok(())
    }
}

/// The reference calibration as the report shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInfo {
    /// Per camera.
    pub intrinsics: Vec<Intrinsics>,
    pub rmse_px: f64,
    pub images: usize,
    pub observations: usize,
    pub converged: bool,
    /// The reference's static correction in `board.json`'s format, written as
    /// [`REFERENCE_BOARD_JSON`] and read back by `[target] geometry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board: Option<BoardJson>,
}

/// The protocol's file of the reference static correction (`board.json`'s format).
pub const REFERENCE_BOARD_JSON: &str = "reference_board.json";

/// One subset × method result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub subset: usize,
    pub method: Method,
    /// `None` when the calibration succeeded, else the reason it failed.
    pub error: Option<String>,
    pub images: usize,
    pub observations: usize,
    pub converged: bool,
    pub iterations: i32,
    pub rmse_px: Option<f64>,
    /// Per camera (empty when the calibration failed).
    pub cameras: Vec<CameraRow>,
    /// User frame ids of the subset's images, in order.
    pub frames: Vec<i64>,
    /// The per-image paraboloid (methods that have one).
    pub deformations: Vec<Paraboloid>,
    /// `max_out_of_plane_m` per image (methods that have a paraboloid).
    pub max_out_of_plane_m: Vec<f64>,
    /// The degree-3 and -4 bend terms per image (bend orders 3 and 4 only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub higher_bends: Vec<HigherBend>,
    /// The share of the residual the noise does not explain (docs/conventions.md §3a).
    #[serde(default)]
    pub bias_ratio: Option<f64>,
    /// This row is `auto`'s: `method` is the method it chose (see `selection`).
    #[serde(default)]
    pub auto: bool,
    /// `auto`'s evidence and reason (its rows only, when the choice succeeded).
    #[serde(default)]
    pub selection: Option<Selection>,
    /// The structure-from-motion loop-closure error of camera 0's intrinsics,
    /// pixels (`[sfm]`; the paper's Table 1).
    #[serde(default)]
    pub loop_closure_px: Option<f64>,
    /// Why the reconstruction with this calibration broke off, if it did.
    #[serde(default)]
    pub sfm_error: Option<String>,
}

/// One camera's results in a [`Row`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraRow {
    pub intrinsics: Intrinsics,
    /// π_k: camera-k-from-camera-0.
    pub pose: crate::model::pose::Pose,
    pub test_rmse_px: Option<f64>,
    pub mapping_error_px: Option<f64>,
    pub mapping_error_rot_px: Option<f64>,
    pub truth_mapping_error_px: Option<f64>,
    pub truth_mapping_error_rot_px: Option<f64>,
    /// The mapping error to the truth the noise alone is expected to leave (docs/conventions.md §3a).
    #[serde(default)]
    pub expected_mapping_error_px: Option<f64>,
    /// The same with the virtual rotation profiled out.
    #[serde(default)]
    pub expected_mapping_error_rot_px: Option<f64>,
}

impl Row {
    /// Whether the calibration succeeded.
    pub fn ok(&self) -> bool {
        self.error.is_none()
    }

    /// `auto` for `auto`'s rows, else the method's name: the outputs' method column.
    pub fn label(&self) -> &'static str {
        if self.auto {
            "auto"
        } else {
            self.method.name()
        }
    }

    /// Whether this row is a calibration with the fixed method `m` (not `auto`'s).
    pub fn is_fixed(&self, m: Method) -> bool {
        !self.auto && self.method == m
    }
}
