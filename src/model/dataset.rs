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

    /// Builds a dataset from observations keyed by user frame numbers.
    pub fn from_keyed(
        target: Target,
        cameras: Vec<CameraSpec>,
        rows: impl IntoIterator<Item = (usize, i64, usize, [f64; 2])>,
    ) -> Dataset {
        let rows: Vec<_> = rows.into_iter().collect();
        let ids: Vec<i64> = rows
            .iter()
            .map(|r| r.1)
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let index: HashMap<i64, usize> = ids.iter().enumerate().map(|(i, &f)| (f, i)).collect();
        let observations = rows
            .into_iter()
            .map(|(camera, f, corner, uv)| Observation {
                camera,
                frame: index[&f],
                corner,
                uv,
                weight: 1.0,
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
