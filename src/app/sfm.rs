//! The `[sfm]` section and the structure-from-motion experiment as the
//! application runs it (the paper's section 5): one synthetic scene seen by the
//! true camera, reconstructed with each calibration under test, and the scene
//! with its tracks exported in COLMAP's text format. The scene is in
//! `model::sfm_scene`, the reconstruction in `solver::sfm`; where the true camera
//! comes from (truth or reference calibration) is the protocol's business.
use crate::error::{Error, Result};
use crate::model::lens::Intrinsics;
use crate::model::sfm_scene::{generate, Scene, SceneSettings};
use crate::solver::sfm::{reconstruct, Reconstruction, SfmSettings};
use serde::{Deserialize, Serialize};
use std::fmt::Write;

/// `[sfm]`: the loop-closure experiment; every key has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SfmConfig {
    /// Distinct views on the loop around the building (the first is appended again).
    pub frames: usize,
    /// 3D points on the façades.
    pub points: usize,
    /// Detector noise per image coordinate, pixels.
    pub noise_px: f64,
    /// Chance that a visible point is detected and matched in a frame.
    pub detect_prob: f64,
    pub seed: u64,
    /// Frames in the sliding bundle-adjustment window.
    pub window: usize,
    /// Cauchy loss scale of the bundle adjustment, pixels (0: none).
    pub loss_scale_px: f64,
}

impl Default for SfmConfig {
    fn default() -> Self {
        let (scene, sfm) = (SceneSettings::default(), SfmSettings::default());
        SfmConfig {
            frames: scene.frames,
            points: scene.points,
            noise_px: scene.noise_px,
            detect_prob: scene.detect_prob,
            seed: scene.seed,
            window: sfm.window,
            loss_scale_px: sfm.loss_scale_px,
        }
    }
}

/// Most frames and points `[sfm]` accepts (a run is linear in both).
pub const MAX_FRAMES: usize = 5_000;
pub const MAX_POINTS: usize = 200_000;

impl SfmConfig {
    /// Checks the values; the message starts with the key (`sfm.noise_px …`).
    pub fn check(&self) -> std::result::Result<(), String> {
        if !(3..=MAX_FRAMES).contains(&self.frames) {
            return Err(format!(
                "sfm.frames must be 3 to {MAX_FRAMES} (got {})",
                self.frames
            ));
        }
        if !(50..=MAX_POINTS).contains(&self.points) {
            return Err(format!(
                "sfm.points must be 50 to {MAX_POINTS} (got {})",
                self.points
            ));
        }
        if !(self.noise_px.is_finite() && (0.0..=50.0).contains(&self.noise_px)) {
            return Err(format!(
                "sfm.noise_px must be 0 to 50 pixels (got {})",
                self.noise_px
            ));
        }
        if !(self.detect_prob > 0.0 && self.detect_prob <= 1.0) {
            return Err(format!(
                "sfm.detect_prob must be in (0, 1] (got {})",
                self.detect_prob
            ));
        }
        if !(3..=100).contains(&self.window) || self.window > self.frames {
            return Err(format!(
                "sfm.window must be 3 to 100 and at most sfm.frames (got {})",
                self.window
            ));
        }
        if !(self.loss_scale_px == 0.0 || (1e-3..=1e4).contains(&self.loss_scale_px)) {
            return Err(format!(
                "sfm.loss_scale_px must be 0 (no robust loss) or 0.001 to 10000 (got {})",
                self.loss_scale_px
            ));
        }
        Ok(())
    }

    /// The reconstruction's settings.
    pub fn settings(&self) -> SfmSettings {
        SfmSettings {
            window: self.window,
            loss_scale_px: self.loss_scale_px,
            ..SfmSettings::default()
        }
    }
}

/// One scene, ready to be reconstructed with any number of calibrations.
#[derive(Debug, Clone)]
pub struct Experiment {
    pub config: SfmConfig,
    /// The camera the scene was seen with.
    pub true_camera: Intrinsics,
    pub scene: Scene,
}

impl Experiment {
    /// Generates the scene of `config` seen by `true_camera` (`width` × `height`).
    pub fn new(
        config: &SfmConfig,
        true_camera: &Intrinsics,
        width: u32,
        height: u32,
    ) -> Result<Self> {
        config.check().map_err(Error::Invalid)?;
        let s = SceneSettings {
            frames: config.frames,
            points: config.points,
            noise_px: config.noise_px,
            detect_prob: config.detect_prob,
            seed: config.seed,
        };
        Ok(Experiment {
            config: config.clone(),
            true_camera: *true_camera,
            scene: generate(true_camera, width, height, &s),
        })
    }

    /// Reconstructs the scene with `camera` held; the model must be the true one's
    /// family of pixels (any lens model: rays come from its own unprojection).
    pub fn run(&self, camera: &Intrinsics) -> Result<Reconstruction> {
        reconstruct(&self.scene, camera, &self.config.settings())
    }

    /// `sfm.json`: the settings, the loop-closure error and the sizes of the run.
    pub fn summary_json(&self, r: &Reconstruction) -> serde_json::Value {
        let features: usize = self.scene.features.iter().map(Vec::len).sum();
        serde_json::json!({
            "loop_closure_px": r.loop_closure_px,
            "loop_points": r.loop_points,
            "frames": self.scene.num_frames(),
            "tracks": self.scene.num_tracks,
            "triangulated_tracks": r.points.iter().filter(|p| p.is_some()).count(),
            "features": features,
            "true_camera": self.true_camera,
            "sfm": self.config,
        })
    }
}

/// The image file name of frame `j` in the COLMAP export (the closing frame is
/// the first image again, so it gets the first's name plus a mark).
fn image_name(j: usize, frames: usize) -> String {
    if j + 1 == frames {
        "frame_0000_again.png".into()
    } else {
        format!("frame_{j:04}.png")
    }
}

/// COLMAP's `images.txt` (true poses; COLMAP stores world-to-camera as a
/// quaternion QW QX QY QZ and TX TY TZ) and `points3D.txt` (true points), one
/// COLMAP point per sequential track: the association a COLMAP run with
/// sequential matching and no loop detection would see. Pixels shift by 0.5
/// (COLMAP puts the top-left pixel's centre at 0.5). Image k is image_id k + 1,
/// camera 1.
pub fn colmap_scene(scene: &Scene) -> (String, String) {
    let mut images = String::from(
        "# Image list with two lines of data per image:\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let n = scene.num_frames();
    let _ = writeln!(images, "# Number of images: {n}");
    // Per track: (image id, 2D index) of each of its features.
    let mut tracks: Vec<Vec<(usize, usize)>> = vec![Vec::new(); scene.num_tracks];
    for (j, frame) in scene.features.iter().enumerate() {
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(&scene.poses[j].rotation_matrix());
        let t = scene.poses[j].translation;
        let _ = writeln!(
            images,
            "{} {:?} {:?} {:?} {:?} {:?} {:?} {:?} 1 {}",
            j + 1,
            q.w,
            q.i,
            q.j,
            q.k,
            t[0],
            t[1],
            t[2],
            image_name(j, n)
        );
        let pts: Vec<String> = frame
            .iter()
            .enumerate()
            .map(|(i, f)| {
                tracks[f.track].push((j + 1, i));
                format!("{:?} {:?} {}", f.uv.x + 0.5, f.uv.y + 0.5, f.track + 1)
            })
            .collect();
        let _ = writeln!(images, "{}", pts.join(" "));
    }
    let mut points = String::from(
        "# 3D point list with one line of data per point:\n\
         #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
    );
    let _ = writeln!(points, "# Number of points: {}", scene.num_tracks);
    for (t, obs) in tracks.iter().enumerate() {
        let x = scene.points[scene.features[obs[0].0 - 1][obs[0].1].point];
        let track: Vec<String> = obs.iter().map(|(i, k)| format!("{i} {k}")).collect();
        let _ = writeln!(
            points,
            "{} {:?} {:?} {:?} 128 128 128 0 {}",
            t + 1,
            x.x,
            x.y,
            x.z,
            track.join(" ")
        );
    }
    (images, points)
}

/// The image pairs sequential matching compares, one `name1 name2` per line: the
/// list for `colmap matches_importer --match_type pairs`.
pub fn match_pairs(scene: &Scene) -> String {
    let n = scene.num_frames();
    (1..n)
        .map(|j| format!("{} {}\n", image_name(j - 1, n), image_name(j, n)))
        .collect()
}
