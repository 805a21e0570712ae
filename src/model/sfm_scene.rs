//! The synthetic scene of the structure-from-motion experiment (the paper's
//! section 5): a building-sized box with points on its façades, a closed camera
//! loop around it seen by the true camera, noisy feature observations and
//! sequential-only tracks. Pure data generation; the reconstruction lives in
//! `solver::sfm`, the geometry it needs in `model::sfm_geometry`.
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// How the scene is made; the defaults are the experiment's.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSettings {
    /// Distinct views on the loop; the image of view 0 is appended once more at the end.
    pub frames: usize,
    /// 3D points on the building's walls.
    pub points: usize,
    /// Detector noise per image coordinate, pixels (standard deviation).
    pub noise_px: f64,
    /// Chance that a visible point is detected and matched in a frame; a miss
    /// ends its track (sequential matching cannot bridge a gap).
    pub detect_prob: f64,
    pub seed: u64,
}

impl Default for SceneSettings {
    fn default() -> Self {
        SceneSettings {
            frames: 100,
            points: 1500,
            noise_px: 0.5,
            detect_prob: 0.9,
            seed: 1,
        }
    }
}

/// Half-sizes of the building (x, y footprint; z height from the ground), metres.
const BUILDING_HALF: [f64; 2] = [14.0, 9.0];
const BUILDING_HEIGHT: f64 = 14.0;
/// Semi-axes of the camera's elliptic walk around the building, metres.
const LOOP_AXES: [f64; 2] = [52.0, 44.0];
/// Where on the loop the walk starts, radians (towards the +x +y corner).
const START_ANGLE: f64 = 0.6;
/// Relief of the façades (window recesses, balconies): points lie up to this
/// far in front of or behind their wall, metres.
const RELIEF_M: f64 = 0.6;
/// Camera height above the ground, metres.
const EYE_HEIGHT: f64 = 1.7;
/// Wall points seen at a grazing angle beyond this are not matched (cosine).
const MIN_VIEW_COS: f64 = 0.25;
/// Features closer than this to the image border are not detected, pixels.
const BORDER_PX: f64 = 8.0;

/// One feature: an image point of a scene point in a frame, and the track
/// (sequential match chain) it belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feature {
    pub frame: usize,
    /// The true scene point (known only to the generator and the tests).
    pub point: usize,
    pub track: usize,
    pub uv: Vector2<f64>,
}

/// The scene, the true trajectory and the features.
#[derive(Debug, Clone)]
pub struct Scene {
    pub points: Vec<Vector3<f64>>,
    /// Outward wall normal per point.
    pub normals: Vec<Vector3<f64>>,
    /// True camera-from-world pose per frame, `frames + 1` of them: the last is the first again.
    pub poses: Vec<Pose>,
    /// Features grouped by frame, in frame order.
    pub features: Vec<Vec<Feature>>,
    pub num_tracks: usize,
    pub width: u32,
    pub height: u32,
}

impl Scene {
    /// Frames including the closing copy of the first.
    pub fn num_frames(&self) -> usize {
        self.features.len()
    }

    /// Features of every track, in frame order.
    pub fn tracks(&self) -> Vec<Vec<Feature>> {
        let mut t = vec![Vec::new(); self.num_tracks];
        for f in self.features.iter().flatten() {
            t[f.track].push(*f);
        }
        t
    }
}

/// Camera-from-world pose of a camera at `eye` looking at `at`, world z up,
/// camera x right, y down, z forward.
pub fn look_at(eye: &Vector3<f64>, at: &Vector3<f64>) -> Pose {
    let f = (at - eye).normalize();
    let right = f.cross(&Vector3::z()).normalize();
    let down = f.cross(&right);
    let r = Matrix3::from_rows(&[right.transpose(), down.transpose(), f.transpose()]);
    let r = Rotation3::from_matrix_unchecked(r);
    Pose::from_parts(&r, &-(r * eye))
}

/// Points spread uniformly over the four walls (by area), with their normals.
fn wall_points(n: usize, rng: &mut ChaCha8Rng) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let [hx, hy] = BUILDING_HALF;
    let (mut pts, mut normals) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        // Walls x = ±hx (length 2hy) or y = ±hy (length 2hx), by their share of the perimeter.
        let z = rng.gen::<f64>() * BUILDING_HEIGHT;
        let side = if rng.gen::<bool>() { 1.0 } else { -1.0 };
        let along = rng.gen::<f64>() * 2.0 - 1.0;
        let depth = (rng.gen::<f64>() * 2.0 - 1.0) * RELIEF_M;
        let (p, nrm) = if rng.gen::<f64>() * (hx + hy) < hy {
            let n = Vector3::new(side, 0.0, 0.0);
            (Vector3::new(side * hx, along * hy, z) + depth * n, n)
        } else {
            let n = Vector3::new(0.0, side, 0.0);
            (Vector3::new(along * hx, side * hy, z) + depth * n, n)
        };
        pts.push(p);
        normals.push(nrm);
    }
    (pts, normals)
}

/// The true trajectory: an ellipse around the building, camera aimed at the
/// building's middle with a slow sway, so the motion is not perfectly regular.
fn trajectory(frames: usize) -> Vec<Pose> {
    let mut poses: Vec<Pose> = (0..frames)
        .map(|j| {
            // Start facing a corner: two walls in view, so the first two views are
            // not of a single plane (where the essential matrix is degenerate).
            let a = START_ANGLE + 2.0 * std::f64::consts::PI * j as f64 / frames as f64;
            let eye = Vector3::new(
                LOOP_AXES[0] * a.cos(),
                LOOP_AXES[1] * a.sin(),
                EYE_HEIGHT + 0.3 * (3.0 * a).sin(),
            );
            let at = Vector3::new(3.0 * (2.0 * a).sin(), 2.0 * (5.0 * a).cos(), 6.0);
            look_at(&eye, &at)
        })
        .collect();
    poses.push(poses[0]);
    poses
}

/// Generates the scene seen by `camera` (the true intrinsics) of `width` × `height` pixels.
pub fn generate(camera: &Intrinsics, width: u32, height: u32, s: &SceneSettings) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let (points, normals) = wall_points(s.points, &mut rng);
    let poses = trajectory(s.frames);
    let noise = Normal::new(0.0, s.noise_px.max(0.0)).expect("noise is non-negative");
    let mut features: Vec<Vec<Feature>> = Vec::with_capacity(s.frames + 1);
    // The track each point continues in the previous frame, if it was detected there.
    let mut open: Vec<Option<usize>> = vec![None; points.len()];
    let mut num_tracks = 0;
    for (j, pose) in poses.iter().enumerate() {
        let mut now: Vec<Option<usize>> = vec![None; points.len()];
        let frame: Vec<Feature> = if j == s.frames {
            // The closing frame is the first image again: the same features, matched
            // (sequentially) only against the frame before it.
            features[0]
                .iter()
                .map(|f| Feature { frame: j, ..*f })
                .collect()
        } else {
            let centre = pose.inverse().translation_vector();
            (0..points.len())
                .filter_map(|i| {
                    let view = (centre - points[i]).normalize();
                    if view.dot(&normals[i]) < MIN_VIEW_COS || rng.gen::<f64>() > s.detect_prob {
                        return None;
                    }
                    let uv = camera.project(&pose.transform(&points[i]))?;
                    let uv = uv + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
                    let inside = uv.x >= BORDER_PX
                        && uv.y >= BORDER_PX
                        && uv.x <= width as f64 - 1.0 - BORDER_PX
                        && uv.y <= height as f64 - 1.0 - BORDER_PX;
                    inside.then_some(Feature {
                        frame: j,
                        point: i,
                        track: 0,
                        uv,
                    })
                })
                .collect()
        };
        let frame = frame
            .into_iter()
            .map(|mut f| {
                f.track = open[f.point].unwrap_or_else(|| {
                    num_tracks += 1;
                    num_tracks - 1
                });
                now[f.point] = Some(f.track);
                f
            })
            .collect();
        features.push(frame);
        open = now;
    }
    Scene {
        points,
        normals,
        poses,
        features,
        num_tracks,
        width,
        height,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::synthetic::true_intrinsics;

    #[test]
    fn look_at_puts_the_target_on_the_optical_axis() {
        let eye = Vector3::new(10.0, -3.0, 1.5);
        let at = Vector3::new(0.0, 0.0, 6.0);
        let p = look_at(&eye, &at);
        let c = p.transform(&at);
        assert!(c.x.abs() < 1e-9 && c.y.abs() < 1e-9 && c.z > 0.0);
        // World up is image up (negative camera y).
        let above = p.transform(&(at + Vector3::z()));
        assert!(above.y < 0.0);
    }

    #[test]
    fn tracks_are_sequential_and_the_loop_closes_on_the_first_image() {
        let s = SceneSettings {
            frames: 40,
            points: 1500,
            ..Default::default()
        };
        let scene = generate(&true_intrinsics(), 1936, 1216, &s);
        assert_eq!(scene.num_frames(), 41);
        assert_eq!(scene.poses[0], scene.poses[40]);
        for t in scene.tracks() {
            for w in t.windows(2) {
                assert_eq!(w[1].frame, w[0].frame + 1, "a track skips a frame");
                assert_eq!(w[1].point, w[0].point);
            }
        }
        // No track joins the first and the last frame: no loop detection.
        let first: Vec<usize> = scene.features[0].iter().map(|f| f.track).collect();
        assert!(scene.features[40].iter().all(|f| !first.contains(&f.track)));
        let uv0: Vec<_> = scene.features[0].iter().map(|f| f.uv).collect();
        let uvn: Vec<_> = scene.features[40].iter().map(|f| f.uv).collect();
        assert_eq!(uv0, uvn);
        for f in &scene.features {
            assert!(f.len() > 100, "only {} features in a frame", f.len());
        }
    }
}
