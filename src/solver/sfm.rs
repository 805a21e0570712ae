//! Incremental structure from motion with the intrinsics held at a calibration
//! under test (the paper's section 5): two-view initialisation from the
//! essential matrix, PnP for each next frame, triangulation of new tracks and a
//! sliding-window bundle adjustment (Ceres, Cauchy loss, `cpp/sfm.h`), no loop
//! closure; then the loop-closure error. Scene generation and the geometry are
//! in the model layer; files and configs in `app::sfm`.
use super::bridge::ffi;
use crate::error::{Error, Result};
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use crate::model::sfm_geometry::{
    in_front, loop_closure_rmse, parallax_deg, relative_pose, triangulate,
};
use crate::model::sfm_scene::Scene;
use nalgebra::Vector3;

/// How the reconstruction runs.
#[derive(Debug, Clone, PartialEq)]
pub struct SfmSettings {
    /// Frames in the sliding bundle-adjustment window (the newest ones).
    pub window: usize,
    /// Frames before the window whose views of the window's points join the
    /// adjustment, held: they anchor the points.
    pub history: usize,
    /// Cauchy loss scale, pixels (0: plain least squares).
    pub loss_scale_px: f64,
    /// Ceres iterations per window adjustment.
    pub max_iterations: i32,
    /// Least parallax for a new track to be triangulated, degrees.
    pub min_parallax_deg: f64,
    /// The window is adjusted after every this many frames (and after the last);
    /// at most `window - 2`, so that each frame is free in at least one adjustment.
    /// Every second frame halves the run; over eight scenes the true camera's loop
    /// error moved by under 0.2 px each and 0.5 % on average (docs/sfm.md).
    pub adjust_every: usize,
}

impl Default for SfmSettings {
    fn default() -> Self {
        SfmSettings {
            window: 8,
            history: 8,
            loss_scale_px: 2.0,
            max_iterations: 4,
            min_parallax_deg: 1.0,
            adjust_every: 2,
        }
    }
}

/// The reconstruction and its loop-closure error.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// Estimated camera-from-world pose per frame (the gauge: frame 0 at the
    /// origin, unit distance between frames 0 and 1).
    pub poses: Vec<Pose>,
    /// Estimated point per track (`None`: never triangulated).
    pub points: Vec<Option<Vector3<f64>>>,
    /// The paper's loop-closure error, pixels.
    pub loop_closure_px: f64,
    /// Features of the first image that entered the loop-closure error.
    pub loop_points: usize,
}

/// Least PnP correspondences for a frame to be registered.
const MIN_PNP: usize = 12;

/// The working state: features as rays, the poses and points so far.
struct Sfm<'a> {
    scene: &'a Scene,
    camera: &'a Intrinsics,
    settings: &'a SfmSettings,
    /// Per frame, per feature: the ray through its pixel (`None`: outside the model's domain).
    rays: Vec<Vec<Option<Vector3<f64>>>>,
    /// Per track: (frame, feature index) of each of its features.
    tracks: Vec<Vec<(usize, usize)>>,
    poses: Vec<Option<Pose>>,
    points: Vec<Option<Vector3<f64>>>,
}

impl<'a> Sfm<'a> {
    fn new(scene: &'a Scene, camera: &'a Intrinsics, settings: &'a SfmSettings) -> Self {
        let rays = scene
            .features
            .iter()
            .map(|f| f.iter().map(|f| camera.unproject(&f.uv)).collect())
            .collect();
        let mut tracks = vec![Vec::new(); scene.num_tracks];
        for (j, frame) in scene.features.iter().enumerate() {
            for (n, f) in frame.iter().enumerate() {
                tracks[f.track].push((j, n));
            }
        }
        Sfm {
            scene,
            camera,
            settings,
            rays,
            tracks,
            poses: vec![None; scene.num_frames()],
            points: vec![None; scene.num_tracks],
        }
    }

    /// Frames 0 and 1 from the essential matrix; frame 0 is the world frame.
    fn initialise(&mut self) -> Result<()> {
        let pairs: Vec<_> = self
            .tracks
            .iter()
            .filter_map(|t| {
                let (&(j0, n0), &(j1, n1)) = (t.first()?, t.get(1)?);
                (j0 == 0 && j1 == 1).then_some(())?;
                Some((self.rays[0][n0]?, self.rays[1][n1]?))
            })
            .collect();
        let pose1 = relative_pose(&pairs).ok_or_else(|| {
            Error::Degenerate(format!("SfM: no two-view start ({} matches)", pairs.len()))
        })?;
        self.poses[0] = Some(Pose::identity());
        self.poses[1] = Some(pose1);
        self.triangulate_new(1);
        self.adjust(1, &[0])
    }

    /// The registered views of track `t` (pose, ray).
    fn views(&self, t: usize) -> Vec<(Pose, Vector3<f64>)> {
        self.tracks[t]
            .iter()
            .filter_map(|&(j, n)| Some((self.poses[j]?, self.rays[j][n]?)))
            .collect()
    }

    /// Triangulates the tracks seen in frame `k` that have no point yet.
    fn triangulate_new(&mut self, k: usize) {
        for f in &self.scene.features[k] {
            let t = f.track;
            if self.points[t].is_some() {
                continue;
            }
            let views = self.views(t);
            if let Some(x) = triangulate(&views) {
                if in_front(&views, &x)
                    && parallax_deg(&views, &x) >= self.settings.min_parallax_deg
                {
                    self.points[t] = Some(x);
                }
            }
        }
    }

    /// PnP for frame `k`: its pose alone fitted (Cauchy loss) to the features
    /// whose tracks have points, from a constant-velocity prediction.
    fn register(&mut self, k: usize) -> Result<()> {
        let (a, b) = (self.poses[k - 2], self.poses[k - 1]);
        let (Some(a), Some(b)) = (a, b) else {
            return Err(Error::Degenerate(format!(
                "SfM: frame {k} has no registered predecessors"
            )));
        };
        let predicted = b.compose(&a.inverse()).compose(&b);
        let seen = self.scene.features[k]
            .iter()
            .filter(|f| self.points[f.track].is_some())
            .count();
        if seen < MIN_PNP {
            return Err(Error::Degenerate(format!(
                "SfM lost track at frame {k}: {seen} features with 3D points, at least {MIN_PNP} needed"
            )));
        }
        self.poses[k] = Some(predicted);
        let mut problem = self.bundle(&[k], &[k], true);
        self.run(&mut problem, k)
    }

    /// Bundle adjustment of the window ending at frame `k`; `held` are held.
    fn adjust(&mut self, k: usize, held: &[usize]) -> Result<()> {
        let first = (k + 1).saturating_sub(self.settings.window);
        let window: Vec<usize> = (first..=k).collect();
        let free: Vec<usize> = window
            .iter()
            .copied()
            .filter(|j| !held.contains(j))
            .collect();
        let mut problem = self.bundle(&window, &free, false);
        self.run(&mut problem, k)
    }

    /// The problem over the points seen in `frames` and all their registered
    /// views; poses of `free` frames vary, points too unless `points_held`.
    fn bundle(&self, frames: &[usize], free: &[usize], points_held: bool) -> Problem {
        let mut p = Problem::default();
        for &j in frames {
            for f in &self.scene.features[j] {
                let t = f.track;
                if self.points[t].is_none() || p.track_index.contains_key(&t) {
                    continue;
                }
                p.track_index.insert(t, p.tracks.len());
                p.tracks.push(t);
            }
        }
        for (i, &t) in p.tracks.iter().enumerate() {
            for &(j, n) in &self.tracks[t] {
                let (Some(_), Some(_)) = (self.poses[j], self.rays[j][n]) else {
                    continue;
                };
                // A pose-only fit needs only the frame's own views (the rest are
                // constant); a window takes held views up to `history` frames
                // further back: enough to anchor its points, few enough to stay fast.
                let oldest = frames[0].saturating_sub(if points_held {
                    0
                } else {
                    self.settings.history
                });
                if j < oldest || j > *frames.last().expect("frames") {
                    continue;
                }
                let local = *p.frame_index.entry(j).or_insert_with(|| {
                    p.frames.push(j);
                    p.frames.len() - 1
                });
                let uv = self.scene.features[j][n].uv;
                p.data.obs_frame.push(local as u32);
                p.data.obs_point.push(i as u32);
                p.data.obs_uv.extend([uv.x, uv.y]);
            }
        }
        p.data.lens_model = self.camera.model().name().to_string();
        p.data.intrinsics = self.camera.params().to_vec();
        for &j in &p.frames {
            p.data
                .poses
                .extend(self.poses[j].expect("registered").to_array());
            p.data.held_frames.push(!free.contains(&j));
        }
        for &t in &p.tracks {
            p.data
                .points
                .extend(self.points[t].expect("triangulated").iter());
            p.data.held_points.push(points_held);
        }
        p.data.loss_scale_px = self.settings.loss_scale_px;
        p.data.max_iterations = self.settings.max_iterations;
        p
    }

    /// Solves `p` and writes its poses and points back.
    fn run(&mut self, p: &mut Problem, k: usize) -> Result<()> {
        let report = ffi::solve_bundle(&mut p.data).map_err(|e| Error::Problem(e.to_string()))?;
        if !report.usable {
            return Err(Error::Solver(format!(
                "SfM bundle adjustment at frame {k}: {}",
                report.message
            )));
        }
        for (l, &j) in p.frames.iter().enumerate() {
            self.poses[j] = Some(Pose::from_slice(&p.data.poses[6 * l..6 * l + 6]));
        }
        for (i, &t) in p.tracks.iter().enumerate() {
            self.points[t] = Some(Vector3::from_column_slice(&p.data.points[3 * i..3 * i + 3]));
        }
        Ok(())
    }
}

/// A bundle-adjustment problem and the global frames and tracks behind its blocks.
#[derive(Default)]
struct Problem {
    data: ffi::BundleData,
    frames: Vec<usize>,
    frame_index: std::collections::HashMap<usize, usize>,
    tracks: Vec<usize>,
    track_index: std::collections::HashMap<usize, usize>,
}

/// Runs the reconstruction of `scene` with the intrinsics `camera` held and
/// returns the loop-closure error; a reconstruction that breaks off is an error.
pub fn reconstruct(
    scene: &Scene,
    camera: &Intrinsics,
    settings: &SfmSettings,
) -> Result<Reconstruction> {
    if scene.num_frames() < 3 {
        return Err(Error::Invalid(format!(
            "SfM needs at least 3 frames, the scene has {}",
            scene.num_frames()
        )));
    }
    if settings.window < 3 {
        return Err(Error::Invalid(format!(
            "SfM window is {}; at least 3 frames",
            settings.window
        )));
    }
    let every = settings.adjust_every.clamp(1, settings.window - 2);
    let mut s = Sfm::new(scene, camera, settings);
    s.initialise()?;
    for k in 2..scene.num_frames() {
        s.register(k)?;
        s.triangulate_new(k);
        let first = (k + 1).saturating_sub(settings.window);
        // The two oldest frames of the window are held: they fix the gauge (7 DOF).
        // Every frame since the last adjustment is free in this one.
        if k % every == 0 || k + 1 == scene.num_frames() {
            s.adjust(k, &[first, first + 1])?;
        }
    }
    let last = scene.num_frames() - 1;
    let first_features: Vec<_> = scene.features[0]
        .iter()
        .filter_map(|f| Some((f.uv, s.points[f.track]?)))
        .collect();
    let poses: Vec<Pose> = s
        .poses
        .iter()
        .map(|p| p.expect("every frame registered"))
        .collect();
    let loop_closure_px =
        loop_closure_rmse(camera, &poses[last], &first_features).ok_or_else(|| {
            Error::Degenerate("SfM: no point of the first image projects into the last".into())
        })?;
    Ok(Reconstruction {
        poses,
        points: s.points,
        loop_closure_px,
        loop_points: first_features.len(),
    })
}
