//! The parameter state of a calibration and its one layout in the solver's
//! parameter buffer.
//!
//! | section | per | values | offset |
//! |---|---|---|---|
//! | intrinsics | camera k | the lens model's parameters, registry order | `intrinsics_offsets[k]` |
//! | camera poses | camera k | camera-k-from-camera-0: angle-axis, translation (6) | `camera_poses + 6k` |
//! | frames | frame j | camera-0-from-board (6), then the board model's per-frame parameters | `frames + frame_stride·j` |
//! | corrections | corner i | Δx, Δy, Δz (3; a board model uses a prefix) | `corrections + 3i` |
//!
//! [`Layout::pack`] and [`Layout::unpack`] are the only code that reads or writes
//! this buffer on the Rust side; the C++ core takes the offsets and checks them.
use crate::model::board::{HigherBend, Paraboloid, PARABOLOID_PARAMS};
use crate::model::lens::{Intrinsics, LensModel};
use crate::model::pose::Pose;
use crate::model::target::Target;

/// Values of a pose in the buffer.
pub const POSE_PARAMS: usize = 6;
/// Values of a corner's correction in the buffer.
pub const CORRECTION_STRIDE: usize = 3;

/// Every parameter of a calibration: the state the solver refines.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// θ_k per camera.
    pub intrinsics: Vec<Intrinsics>,
    /// π_k: camera-k-from-camera-0 (identity for camera 0).
    pub camera_poses: Vec<Pose>,
    /// Π_j: camera-0-from-board per frame.
    pub frame_poses: Vec<Pose>,
    /// β_j per frame (zero where the method has none).
    pub deformations: Vec<Paraboloid>,
    /// The degree-3 and -4 bend coefficients per frame (zero beyond the method's order).
    pub higher_bends: Vec<HigherBend>,
    /// Δx_i per corner (zero where the method has none).
    pub corrections: Vec<[f64; 3]>,
}

impl State {
    /// A state with the given intrinsics and poses and no deformation.
    pub fn rigid(
        intrinsics: Vec<Intrinsics>,
        camera_poses: Vec<Pose>,
        frame_poses: Vec<Pose>,
        target: &Target,
    ) -> Self {
        let frames = frame_poses.len();
        State {
            intrinsics,
            camera_poses,
            frame_poses,
            deformations: vec![Paraboloid::default(); frames],
            higher_bends: vec![HigherBend::default(); frames],
            corrections: vec![[0.0; 3]; target.num_corners()],
        }
    }
}

/// Where every parameter lives in the solver's buffer (the table above).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    pub lens_models: Vec<LensModel>,
    pub intrinsics_offsets: Vec<usize>,
    pub camera_poses: usize,
    pub frames: usize,
    pub frame_stride: usize,
    pub corrections: usize,
    pub num_frames: usize,
    pub num_corners: usize,
    /// Total number of values.
    pub len: usize,
}

impl Layout {
    /// The layout for cameras of the given lens models, `num_frames` frames with
    /// `frame_params` board-model parameters each, and `num_corners` corners.
    pub fn new(
        lens_models: &[LensModel],
        num_frames: usize,
        frame_params: usize,
        num_corners: usize,
    ) -> Self {
        let mut intrinsics_offsets = Vec::with_capacity(lens_models.len());
        let mut next = 0;
        for m in lens_models {
            intrinsics_offsets.push(next);
            next += m.num_params();
        }
        let camera_poses = next;
        let frames = camera_poses + POSE_PARAMS * lens_models.len();
        let frame_stride = POSE_PARAMS + frame_params;
        let corrections = frames + frame_stride * num_frames;
        Layout {
            lens_models: lens_models.to_vec(),
            intrinsics_offsets,
            camera_poses,
            frames,
            frame_stride,
            corrections,
            num_frames,
            num_corners,
            len: corrections + CORRECTION_STRIDE * num_corners,
        }
    }

    /// Values in the intrinsics section.
    pub fn intrinsics_len(&self) -> usize {
        self.camera_poses
    }

    /// The buffer of a state; `None` if the state does not fit the layout.
    pub fn pack(&self, state: &State) -> Option<Vec<f64>> {
        let fits = state.intrinsics.len() == self.lens_models.len()
            && state.camera_poses.len() == self.lens_models.len()
            && state.frame_poses.len() == self.num_frames
            && state.deformations.len() == self.num_frames
            && state.higher_bends.len() == self.num_frames
            && state.corrections.len() == self.num_corners
            && state
                .intrinsics
                .iter()
                .zip(&self.lens_models)
                .all(|(k, m)| k.model() == *m);
        if !fits {
            return None;
        }
        let mut out = Vec::with_capacity(self.len);
        for k in &state.intrinsics {
            out.extend_from_slice(k.params());
        }
        for p in &state.camera_poses {
            out.extend_from_slice(&p.to_array());
        }
        let extra = self.frame_stride - POSE_PARAMS;
        for ((p, d), h) in state
            .frame_poses
            .iter()
            .zip(&state.deformations)
            .zip(&state.higher_bends)
        {
            out.extend_from_slice(&p.to_array());
            let bend: Vec<f64> = d.to_array().into_iter().chain(*h).collect();
            out.extend_from_slice(&bend[..extra]);
        }
        for c in &state.corrections {
            out.extend_from_slice(c);
        }
        debug_assert_eq!(out.len(), self.len);
        Some(out)
    }

    /// Writes a buffer back into a state of this layout (the inverse of [`Layout::pack`]).
    pub fn unpack(&self, buffer: &[f64], state: &mut State) {
        assert_eq!(buffer.len(), self.len, "buffer does not match the layout");
        for (k, (&offset, m)) in self
            .intrinsics_offsets
            .iter()
            .zip(&self.lens_models)
            .enumerate()
        {
            let n = m.num_params();
            state.intrinsics[k] = Intrinsics::from_params(*m, &buffer[offset..offset + n])
                .expect("count from layout");
        }
        for (k, chunk) in buffer[self.camera_poses..self.frames]
            .chunks_exact(POSE_PARAMS)
            .enumerate()
        {
            state.camera_poses[k] = Pose::from_slice(chunk);
        }
        for (j, chunk) in buffer[self.frames..self.corrections]
            .chunks_exact(self.frame_stride)
            .enumerate()
        {
            state.frame_poses[j] = Pose::from_slice(&chunk[..POSE_PARAMS]);
            if self.frame_stride >= POSE_PARAMS + PARABOLOID_PARAMS {
                let e = &chunk[POSE_PARAMS..];
                state.deformations[j] = Paraboloid {
                    a: e[0],
                    b: e[1],
                    c: e[2],
                };
                let mut h = HigherBend::default();
                h[..e.len() - PARABOLOID_PARAMS].copy_from_slice(&e[PARABOLOID_PARAMS..]);
                state.higher_bends[j] = h;
            }
        }
        for (i, chunk) in buffer[self.corrections..]
            .chunks_exact(CORRECTION_STRIDE)
            .enumerate()
        {
            state.corrections[i] = [chunk[0], chunk[1], chunk[2]];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pack_then_unpack_is_the_identity() {
        let target = Target {
            rows: 2,
            cols: 3,
            spacing: 0.1,
        };
        let models = [
            LensModel::OpenCv8,
            LensModel::Radial3,
            LensModel::DoubleSphere,
        ];
        let intrinsics: Vec<Intrinsics> = models
            .iter()
            .enumerate()
            .map(|(k, &m)| {
                let p: Vec<f64> = (0..m.num_params())
                    .map(|i| (10 * k + i) as f64 + 0.5)
                    .collect();
                Intrinsics::from_params(m, &p).unwrap()
            })
            .collect();
        let pose = |s: f64| Pose::from_slice(&[s, s + 1.0, s + 2.0, s + 3.0, s + 4.0, s + 5.0]);
        let mut state = State::rigid(
            intrinsics,
            vec![pose(1.0), pose(2.0), pose(3.0)],
            vec![pose(4.0), pose(5.0)],
            &target,
        );
        state.deformations[1] = Paraboloid {
            a: 1.0,
            b: 2.0,
            c: 3.0,
        };
        state.corrections[4] = [0.1, 0.2, 0.3];
        let layout = Layout::new(&models, 2, PARABOLOID_PARAMS, target.num_corners());
        let buffer = layout.pack(&state).unwrap();
        assert_eq!(buffer.len(), 12 + 7 + 6 + 3 * 6 + 2 * 9 + 3 * 6);
        assert_eq!(buffer[layout.intrinsics_offsets[1]], 10.5);
        assert_eq!(
            buffer[layout.frames + layout.frame_stride + POSE_PARAMS + 2],
            3.0
        );
        let mut back = State::rigid(
            state.intrinsics.clone(),
            vec![Pose::identity(); 3],
            vec![Pose::identity(); 2],
            &target,
        );
        layout.unpack(&buffer, &mut back);
        assert_eq!(back, state);
        // A state of other lens models does not fit.
        let other = Layout::new(&[LensModel::Radial3; 3], 2, PARABOLOID_PARAMS, 6);
        assert!(other.pack(&state).is_none());
    }
}
