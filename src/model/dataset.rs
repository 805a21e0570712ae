//! Observed corners and the dataset a calibration sees (docs/conventions.md §5 numbering).
use crate::model::camera::CameraSpec;
use crate::model::target::Target;
use std::collections::HashMap;

/// One detected corner: camera index, dense frame index, corner index, pixel, and
/// the weight of its residual (1, or 0.5^level for a corner found on a decimated image).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub camera: usize,
    pub frame: usize,
    pub corner: usize,
    pub uv: [f64; 2],
    pub weight: f64,
}

/// One corner as a detector or a file hands it over, before frames are numbered
/// densely: the camera, the user's frame number, the corner's id on the board,
/// its pixel, and the weight of its residual (σ_ref/σ from the refinement, or
/// 0.5^level for mrgingham's decimated images; 1 when the source says nothing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectedCorner {
    pub camera: usize,
    pub frame_id: i64,
    pub corner: usize,
    pub uv: [f64; 2],
    pub weight: f64,
}

/// Everything a calibration sees: board, cameras, frames and observations.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    pub target: Target,
    pub cameras: Vec<CameraSpec>,
    /// The user's frame number of each dense frame index, ascending.
    pub frame_ids: Vec<i64>,
    pub observations: Vec<Observation>,
}

/// The CSV header docs/conventions.md §5 fixes.
pub const HEADER: [&str; 5] = ["camera", "frame", "corner", "u", "v"];

impl Dataset {
    /// A view's name for messages: "frame 7" with one camera, "cam1 frame 7" with several.
    pub fn view_name(&self, camera: usize, frame: usize) -> String {
        if self.cameras.len() == 1 {
            format!("frame {}", self.frame_ids[frame])
        } else {
            format!(
                "{} frame {}",
                self.cameras[camera].name, self.frame_ids[frame]
            )
        }
    }

    /// Number of frames (time steps).
    pub fn num_frames(&self) -> usize {
        self.frame_ids.len()
    }

    /// Observations per frame, for every camera together.
    pub fn counts_per_frame(&self) -> Vec<usize> {
        let mut n = vec![0; self.num_frames()];
        for o in &self.observations {
            n[o.frame] += 1;
        }
        n
    }

    /// A dataset restricted to the given dense frames, renumbered densely in the given order.
    pub fn subset(&self, frames: &[usize]) -> Dataset {
        let mut map = vec![usize::MAX; self.num_frames()];
        for (new, &old) in frames.iter().enumerate() {
            map[old] = new;
        }
        let observations = self
            .observations
            .iter()
            .filter(|o| map[o.frame] != usize::MAX)
            .map(|o| Observation {
                frame: map[o.frame],
                ..*o
            })
            .collect();
        Dataset {
            target: self.target,
            cameras: self.cameras.clone(),
            frame_ids: frames.iter().map(|&f| self.frame_ids[f]).collect(),
            observations,
        }
    }

    /// Builds a dataset from observations keyed by user frame numbers, every
    /// weight 1 (a source that gives no weights).
    pub fn from_keyed(
        target: Target,
        cameras: Vec<CameraSpec>,
        rows: impl IntoIterator<Item = (usize, i64, usize, [f64; 2])>,
    ) -> Dataset {
        let corners = rows
            .into_iter()
            .map(|(camera, frame_id, corner, uv)| DetectedCorner {
                camera,
                frame_id,
                corner,
                uv,
                weight: 1.0,
            });
        Dataset::from_detected(target, cameras, corners)
    }

    /// Builds a dataset from detected corners, each keeping its weight; frames
    /// are numbered densely in the order of their user numbers.
    pub fn from_detected(
        target: Target,
        cameras: Vec<CameraSpec>,
        corners: impl IntoIterator<Item = DetectedCorner>,
    ) -> Dataset {
        let corners: Vec<DetectedCorner> = corners.into_iter().collect();
        let ids: Vec<i64> = corners
            .iter()
            .map(|c| c.frame_id)
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let index: HashMap<i64, usize> = ids.iter().enumerate().map(|(i, &f)| (f, i)).collect();
        let observations = corners
            .into_iter()
            .map(|c| Observation {
                camera: c.camera,
                frame: index[&c.frame_id],
                corner: c.corner,
                uv: c.uv,
                weight: c.weight,
            })
            .collect();
        Dataset {
            target,
            cameras,
            frame_ids: ids,
            observations,
        }
    }
}
