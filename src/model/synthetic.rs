//! Built-in synthetic datasets imitating the paper's targets T1–T4 and its reference set.
//!
//! Board sizes follow the paper's Fig. 3 caption, the per-image out-of-plane
//! deformation magnitudes its Table S2 (mean ± std of the maximum Δz), the camera
//! its Allied Vision MG-235B (1936×1216, 5.86 µm pixels) with a 17 mm lens.
use crate::model::board::{higher_dz, HigherBend, Paraboloid};
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::lens::{Intrinsics, LensModel};
use crate::model::pose::Pose;
use crate::model::target::Target;
use nalgebra::{Rotation3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// A built-in dataset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// 1 m × 2 m styrofoam composite, carried.
    T1,
    /// 1 m × 1 m aluminium composite, carried.
    T2,
    /// 60 cm × 42 cm paper on cardboard (self-made), carried.
    T3,
    /// 37.5 cm × 25 cm aluminium composite, carried.
    T4,
    /// T2 lying still on the ground, camera moving; static error only.
    Reference,
    /// T2 carried in front of a stereo pair 0.3 m apart.
    Stereo,
    /// T2's board warped beyond a paraboloid: cubic and quartic terms and twist.
    Warped,
    /// A video of T2's board flexing slowly: the bend varies smoothly over 200 frames.
    Flex,
}

/// How a preset's per-image bend is shaped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum BendShape {
    /// The paper's paraboloid, a fresh random shape per image.
    Paraboloid,
    /// Paraboloid plus random cubic and quartic terms (twist included), per image.
    Warped,
    /// A paraboloid whose coefficients drift smoothly with the frame index (video).
    Smooth,
    /// A twist, per image: the board held by two opposite corners and turned, the
    /// x·y term of the paraboloid leading, with the degree-4 twist terms x³y and
    /// x·y³ and a little of the paraboloid's own curvature on top.
    Twisted,
}

/// What a preset generates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PresetSpec {
    pub target: Target,
    /// Images in the full dataset.
    pub images: usize,
    /// Mean and standard deviation of each image's maximum |Δz| in metres.
    pub bend_mean_m: f64,
    pub bend_std_m: f64,
    /// Standard deviation of the static print error, in-plane and out-of-plane, metres.
    pub print_sigma_xy_m: f64,
    pub print_sigma_z_m: f64,
    /// In-plane offset of the right half of the board (two glued sheets), metres.
    pub sheet_offset_m: [f64; 2],
    /// Distance range of the board from the camera, metres.
    pub distance_m: [f64; 2],
    /// Detector noise per pixel coordinate.
    pub noise_px: f64,
    /// The shape of the per-image bend.
    pub bend_shape: BendShape,
}

impl Preset {
    /// Names accepted in configs.
    pub const NAMES: [&'static str; 8] = [
        "t1",
        "t2",
        "t3",
        "t4",
        "reference",
        "stereo",
        "warped",
        "flex",
    ];

    /// The config name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::T1 => "t1",
            Preset::T2 => "t2",
            Preset::T3 => "t3",
            Preset::T4 => "t4",
            Preset::Reference => "reference",
            Preset::Stereo => "stereo",
            Preset::Warped => "warped",
            Preset::Flex => "flex",
        }
    }

    /// Parses a config name.
    pub fn parse(s: &str) -> Option<Preset> {
        [
            Preset::T1,
            Preset::T2,
            Preset::T3,
            Preset::T4,
            Preset::Reference,
            Preset::Stereo,
            Preset::Warped,
            Preset::Flex,
        ]
        .into_iter()
        .find(|p| p.name() == s)
    }

    /// The generation parameters.
    pub fn spec(self) -> PresetSpec {
        let base = PresetSpec {
            target: Target {
                rows: 13,
                cols: 13,
                spacing: 0.07,
            },
            images: 500,
            bend_mean_m: 0.0,
            bend_std_m: 0.0,
            print_sigma_xy_m: 50e-6,
            print_sigma_z_m: 100e-6,
            sheet_offset_m: [0.0, 0.0],
            distance_m: [1.5, 6.0],
            noise_px: 0.15,
            bend_shape: BendShape::Paraboloid,
        };
        match self {
            Preset::T1 => PresetSpec {
                target: Target {
                    rows: 11,
                    cols: 22,
                    spacing: 0.085,
                },
                bend_mean_m: 2.6e-3,
                bend_std_m: 1.2e-3,
                ..base
            },
            Preset::T2 | Preset::Stereo => PresetSpec {
                bend_mean_m: 1.7e-3,
                bend_std_m: 2.4e-3,
                ..base
            },
            Preset::T3 => PresetSpec {
                target: Target {
                    rows: 9,
                    cols: 14,
                    spacing: 0.04,
                },
                bend_mean_m: 3.0e-3,
                bend_std_m: 2.1e-3,
                print_sigma_xy_m: 200e-6,
                print_sigma_z_m: 400e-6,
                sheet_offset_m: [0.4e-3, -0.3e-3],
                // Smaller boards are held closer to fill the view.
                distance_m: [1.5, 4.5],
                ..base
            },
            Preset::T4 => PresetSpec {
                target: Target {
                    rows: 7,
                    cols: 11,
                    spacing: 0.03,
                },
                bend_mean_m: 0.19e-3,
                bend_std_m: 0.57e-3,
                distance_m: [1.5, 3.5],
                ..base
            },
            Preset::Reference => PresetSpec {
                images: 650,
                distance_m: [1.2, 4.0],
                ..base
            },
            // Bends of a few millimetres, as T1's, but not paraboloids.
            Preset::Warped => PresetSpec {
                bend_mean_m: 3.0e-3,
                bend_std_m: 1.0e-3,
                bend_shape: BendShape::Warped,
                ..base
            },
            Preset::Flex => PresetSpec {
                images: 200,
                bend_mean_m: 3.0e-3,
                bend_std_m: 0.0,
                bend_shape: BendShape::Smooth,
                ..base
            },
        }
    }

    /// Number of cameras the preset simulates unless the config says otherwise.
    pub fn default_cameras(self) -> usize {
        if self == Preset::Stereo {
            2
        } else {
            1
        }
    }

    /// The `n` cameras of the simulated rig: cam0, cam1, …
    pub fn cameras(self, n: usize) -> Vec<CameraSpec> {
        (0..n)
            .map(|k| CameraSpec::new(format!("cam{k}"), 1936, 1216, LensModel::Radial3))
            .collect()
    }
}

/// Spacing of the simulated rig's cameras along x, metres.
pub const RIG_BASELINE_M: f64 = 0.3;

/// Camera-k-from-camera-0 of a rig of `n` cameras `RIG_BASELINE_M` apart along x,
/// each turned 2° further towards camera 0's axis.
pub fn default_rig(n: usize) -> Vec<Pose> {
    (0..n)
        .map(|k| {
            let toe_in = -(2.0 * k as f64).to_radians();
            // cam0-from-camk turns camk's axis towards -x.
            let r_0k = Rotation3::from_euler_angles(0.0, toe_in, 0.0);
            let centre = Vector3::new(RIG_BASELINE_M * k as f64, 0.0, 0.0);
            let r = r_0k.inverse();
            Pose::from_parts(&r, &-(r * centre))
        })
        .collect()
}

/// True intrinsics of camera `k` of a `radial3` rig: the same lens, slightly different units.
pub fn rig_intrinsics(k: usize) -> Intrinsics {
    rig_intrinsics_of(LensModel::Radial3, k)
}

/// True intrinsics of camera `k` of a rig of `model` cameras.
pub fn rig_intrinsics_of(model: LensModel, k: usize) -> Intrinsics {
    let mut i = true_intrinsics_of(model);
    let k = k as f64;
    // The first distortion coefficient of each model (if it has one) varies a little too.
    let first = model.param_names().get(4).copied();
    let step = if model.info().pinhole_like {
        0.01
    } else {
        0.002
    };
    let core = [("fx", 7.0), ("fy", 5.0), ("cx", -4.0), ("cy", 3.0)];
    for (name, delta) in core.into_iter().chain(first.map(|f| (f, step))) {
        let v = i.get(name).expect("parameter of the model");
        i.set(name, v + delta * k);
    }
    i
}

/// The true intrinsics of the simulated 17 mm lens on 5.86 µm pixels.
pub fn true_intrinsics() -> Intrinsics {
    true_intrinsics_of(LensModel::Radial3)
}

/// The simulated camera (1936 × 1216 pixels) under each lens model: the
/// registry's `synthetic` parameters (the 17 mm lens for `radial3` and
/// `opencv5`, wide-angle and fisheye lenses for the others; each model's file in
/// `model::lens` says which).
pub fn true_intrinsics_of(model: LensModel) -> Intrinsics {
    Intrinsics::from_params(model, model.info().synthetic).expect("parameter count of the model")
}

/// Ground truth of a generated dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    pub preset: String,
    pub seed: u64,
    pub noise_px: f64,
    pub target: Target,
    pub intrinsics: Vec<Intrinsics>,
    /// Camera-k-from-camera-0.
    pub camera_poses: Vec<Pose>,
    /// Camera-0-from-board per frame (dense order, frame ids 0..n).
    pub frame_poses: Vec<Pose>,
    pub deformations: Vec<Paraboloid>,
    /// The degree-3 and -4 bend terms per frame (zero for the paper's presets).
    #[serde(default)]
    pub higher_bends: Vec<HigherBend>,
    /// The board's static deviation from the nominal grid, per corner.
    pub corrections: Vec<[f64; 3]>,
}

impl Truth {
    /// RMS over consecutive frames and the paraboloid's terms of the true bend's
    /// change from one frame to the next, as Δz at the board's corner, metres:
    /// the flex rate that `bend_smoothness` describes (0 for fewer than two frames).
    pub fn flex_rate(&self) -> f64 {
        let reach = crate::model::board::bend_reach(&self.target, 3);
        let d = &self.deformations;
        if d.len() < 2 {
            return 0.0;
        }
        let sq: f64 = d
            .windows(2)
            .map(|w| {
                [w[1].a - w[0].a, w[1].b - w[0].b, w[1].c - w[0].c]
                    .iter()
                    .zip(&reach)
                    .map(|(c, r)| (c * r).powi(2))
                    .sum::<f64>()
            })
            .sum();
        (sq / (3.0 * (d.len() - 1) as f64)).sqrt()
    }

    /// The true 3D board point of corner `i` in frame `j`.
    pub fn board_point(&self, i: usize, j: usize) -> Vector3<f64> {
        let n = self.target.nominal(i);
        let c = self.corrections[i];
        let bend = self.deformations[j];
        let higher = self
            .higher_bends
            .get(j)
            .map_or(0.0, |h| higher_dz(h, n.x, n.y));
        Vector3::new(n.x + c[0], n.y + c[1], c[2] + bend.dz(n.x, n.y) + higher)
    }
}

/// Most images a generated dataset may have (t2: about 170 MB of observations);
/// larger requests are refused before anything is allocated.
pub const MAX_IMAGES: usize = 20_000;

/// Everything a generator call may vary.
#[derive(Debug, Clone, PartialEq)]
pub struct Generator {
    pub spec: PresetSpec,
    pub preset: Preset,
    pub images: usize,
    pub seed: u64,
    /// True intrinsics per camera.
    pub intrinsics: Vec<Intrinsics>,
    /// Camera-k-from-camera-0 per camera (identity first).
    pub rig: Vec<Pose>,
    /// Scales the per-image bend (0 gives a rigid board).
    pub bend_scale: f64,
    /// Scales the static print error (0 gives a perfect print).
    pub print_scale: f64,
    /// Minimum fraction of the corners that must fall in the image for a view.
    pub min_visible: f64,
    /// The same for the cameras other than the one the board is held up to.
    pub min_visible_other: f64,
    /// Detector noise per pixel coordinate.
    pub noise_px: f64,
    /// Largest tilt of the board about its x and y axes, degrees.
    pub max_tilt_deg: f64,
    /// Where the board's centre is aimed: u0, u1, v0, v1 as fractions of the image.
    pub region: [f64; 4],
    /// Frames of a hand-held video: the pose moves smoothly between random key
    /// poses [`VIDEO_KEY_FRAMES`] frames apart, and the bend's time is the video's
    /// (frames whose board leaves the view are dropped). Off: independent stills.
    pub video: bool,
}

/// Frames between the key poses of a [`Generator::video`].
pub const VIDEO_KEY_FRAMES: usize = 25;

impl Generator {
    /// The preset's defaults.
    pub fn new(preset: Preset, images: Option<usize>, seed: u64) -> Self {
        let spec = preset.spec();
        let n = preset.default_cameras();
        Generator {
            spec,
            preset,
            images: images.unwrap_or(spec.images),
            seed,
            intrinsics: (0..n).map(rig_intrinsics).collect(),
            rig: default_rig(n),
            bend_scale: 1.0,
            print_scale: 1.0,
            min_visible: 0.8,
            min_visible_other: 0.3,
            noise_px: spec.noise_px,
            max_tilt_deg: 40.0,
            region: [0.15, 0.85, 0.15, 0.85],
            video: false,
        }
    }

    /// The same with `n` cameras on the default rig.
    pub fn with_cameras(mut self, n: usize) -> Self {
        self.intrinsics = (0..n).map(rig_intrinsics).collect();
        self.rig = default_rig(n);
        self
    }

    /// The same with camera k seen through a lens of `models[k]` (one per camera of
    /// the rig). Views through wide lenses are aimed over almost the whole image,
    /// so that the board reaches the image corners.
    pub fn with_models(mut self, models: &[LensModel]) -> Self {
        assert_eq!(models.len(), self.rig.len(), "one lens model per camera");
        self.intrinsics = models
            .iter()
            .enumerate()
            .map(|(k, &m)| rig_intrinsics_of(m, k))
            .collect();
        // A wide lens is calibrated over its whole image only if the board goes
        // there: aim over almost all of it when the corners are over 45° off axis.
        let corner = Vector2::new(0.0, 0.0);
        let wide = self.intrinsics.iter().any(|k| {
            k.unproject(&corner)
                .is_none_or(|ray| ray.z < std::f64::consts::FRAC_1_SQRT_2)
        });
        if wide {
            self.region = [0.03, 0.97, 0.03, 0.97];
            // And held closer, as a user would, so that it fills as much of the
            // view as it does for the presets' 17 mm lens (of the rig's
            // narrowest lens, so that its cameras still share views).
            let f = self
                .intrinsics
                .iter()
                .map(Intrinsics::fx)
                .fold(0.0, f64::max);
            let scale = (f / true_intrinsics().fx()).min(1.0);
            self.spec.distance_m = self.spec.distance_m.map(|d| d * scale);
        }
        self
    }

    fn random_pose(&self, rng: &mut ChaCha8Rng, camera: &CameraSpec, k: &Intrinsics) -> Pose {
        let [dmin, dmax] = self.spec.distance_m;
        let d = rng.gen_range(dmin..dmax);
        let (w, h) = (camera.width as f64, camera.height as f64);
        let [u0, u1, v0, v1] = self.region;
        let u = rng.gen_range(u0 * w..u1 * w);
        let v = rng.gen_range(v0 * h..v1 * h);
        // Pinhole-like lenses aim by the pinhole (as the presets always have);
        // a fisheye needs its own unprojection to aim near the border.
        let pinhole = Vector3::new((u - k.cx()) / k.fx(), (v - k.cy()) / k.fy(), 1.0).normalize();
        let ray = if k.model().info().pinhole_like {
            pinhole
        } else {
            k.unproject(&Vector2::new(u, v)).unwrap_or(pinhole)
        };
        let centre = ray * d;
        let deg = std::f64::consts::PI / 180.0;
        let m = self.max_tilt_deg;
        let mut tilt = || {
            if m > 0.0 {
                rng.gen_range(-m..m) * deg
            } else {
                // Keep the random stream the same as with a tilt.
                let _: f64 = rng.gen();
                0.0
            }
        };
        let (tilt_x, tilt_y) = (tilt(), tilt());
        let roll = rng.gen_range(-20.0..20.0) * deg;
        let r = Rotation3::from_euler_angles(tilt_x, tilt_y, roll);
        Pose::from_parts(&r, &centre)
    }

    /// The pose at time `t` of a video: between key poses drawn as stills (in
    /// `keys`, extended as needed), interpolated with a smooth start and stop.
    fn video_pose(
        &self,
        rng: &mut ChaCha8Rng,
        keys: &mut Vec<Pose>,
        t: usize,
        camera: &CameraSpec,
        k: &Intrinsics,
    ) -> Pose {
        let i = t / VIDEO_KEY_FRAMES;
        while keys.len() < i + 2 {
            keys.push(self.random_pose(rng, camera, k));
        }
        let s = (t % VIDEO_KEY_FRAMES) as f64 / VIDEO_KEY_FRAMES as f64;
        let s = s * s * (3.0 - 2.0 * s);
        let q = |p: &Pose| nalgebra::UnitQuaternion::from_rotation_matrix(&p.rotation_matrix());
        let r = q(&keys[i]).slerp(&q(&keys[i + 1]), s);
        let c = keys[i].translation_vector() * (1.0 - s) + keys[i + 1].translation_vector() * s;
        Pose::from_parts(&r.to_rotation_matrix(), &c)
    }

    fn random_bend(&self, rng: &mut ChaCha8Rng, frame: usize) -> (Paraboloid, HigherBend) {
        let s = &self.spec;
        let magnitude =
            (s.bend_mean_m + s.bend_std_m * rng.sample::<f64, _>(rand_distr::StandardNormal)).abs()
                * self.bend_scale;
        let n = Normal::new(0.0, 1.0).expect("unit normal");
        let mut shape = Paraboloid {
            a: n.sample(rng),
            b: n.sample(rng),
            c: 0.5 * n.sample(rng),
        };
        let mut higher = HigherBend::default();
        match s.bend_shape {
            BendShape::Paraboloid => {}
            BendShape::Warped => {
                // Coefficients in units of the board's half size, so every term
                // reaches about as far as the paraboloid's; twist (x y, x³y, x y³) too.
                let h = (s.target.cols.max(s.target.rows) as f64 - 1.0) / 2.0 * s.target.spacing;
                for (k, c) in higher.iter_mut().enumerate() {
                    let degree = if k < 4 { 3 } else { 4 };
                    *c = 1.5 * n.sample(rng) / h.powi(degree - 2);
                }
                shape.c = n.sample(rng);
            }
            BendShape::Twisted => {
                // In units of the board's half size, as for `Warped`; the sign of
                // the twist is random, its size not.
                let h = (s.target.cols.max(s.target.rows) as f64 - 1.0) / 2.0 * s.target.spacing;
                let sign = if rng.gen::<bool>() { 1.0 } else { -1.0 };
                shape = Paraboloid {
                    a: 0.2 * n.sample(rng),
                    b: 0.2 * n.sample(rng),
                    c: sign * (1.0 + 0.2 * n.sample(rng)),
                };
                // x³y and x·y³ in `HigherBend`'s order (x³, x²y, xy², y³, x⁴, x³y, …).
                higher[5] = 0.5 * n.sample(rng) / (h * h);
                higher[7] = 0.5 * n.sample(rng) / (h * h);
            }
            BendShape::Smooth => {
                // Slow drifts, periods of 60 to 150 frames: a board flexing in the hands.
                let t = frame as f64;
                let tau = std::f64::consts::TAU;
                shape = Paraboloid {
                    a: (tau * t / 97.0).sin(),
                    b: (tau * t / 150.0 + 1.0).cos(),
                    c: 0.5 * (tau * t / 61.0 + 2.0).sin(),
                };
            }
        }
        let unit = crate::model::board::max_bend(&s.target, &shape, &higher);
        if unit < 1e-12 || magnitude == 0.0 {
            return (Paraboloid::default(), HigherBend::default());
        }
        let f = magnitude / unit;
        let bend = Paraboloid {
            a: shape.a * f,
            b: shape.b * f,
            c: shape.c * f,
        };
        (bend, higher.map(|c| c * f))
    }

    /// The board's static deviation from the nominal grid per corner (print noise, sheet offset).
    fn print_errors(&self, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        let s = &self.spec;
        let target = s.target;
        let print = self.print_scale;
        let nxy = Normal::new(0.0, s.print_sigma_xy_m).expect("sigma is non-negative");
        let nz = Normal::new(0.0, s.print_sigma_z_m).expect("sigma is non-negative");
        (0..target.num_corners())
            .map(|i| {
                let right_sheet = i % target.cols >= target.cols / 2;
                let off = if right_sheet {
                    s.sheet_offset_m
                } else {
                    [0.0, 0.0]
                };
                [
                    print * (nxy.sample(rng) + off[0]),
                    print * (nxy.sample(rng) + off[1]),
                    print * nz.sample(rng),
                ]
            })
            .collect()
    }

    /// The noiseless pixels of frame `j`'s corners that fall inside each camera's image.
    fn project_views(
        &self,
        cameras: &[CameraSpec],
        truth: &Truth,
        j: usize,
    ) -> Vec<Vec<(usize, Vector2<f64>)>> {
        let pose = truth.frame_poses[j];
        (0..self.rig.len())
            .map(|k| {
                let (w, h) = (cameras[k].width as f64, cameras[k].height as f64);
                let camera_pose = self.rig[k].compose(&pose);
                (0..truth.target.num_corners())
                    .filter_map(|i| {
                        let uv = self.intrinsics[k]
                            .project(&camera_pose.transform(&truth.board_point(i, j)))?;
                        (uv.x >= 0.0 && uv.x <= w - 1.0 && uv.y >= 0.0 && uv.y <= h - 1.0)
                            .then_some((i, uv))
                    })
                    .collect()
            })
            .collect()
    }

    /// Generates the dataset and its truth.
    pub fn generate(&self) -> (Dataset, Truth) {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let s = &self.spec;
        let target = s.target;
        let mut cameras = self.preset.cameras(self.rig.len());
        for (c, k) in cameras.iter_mut().zip(&self.intrinsics) {
            c.model = k.model();
        }
        let corrections = self.print_errors(&mut rng);
        let noise = Normal::new(0.0, self.noise_px).expect("noise is a non-negative number");
        let n = self.rig.len();
        let mut truth = Truth {
            preset: self.preset.name().into(),
            seed: self.seed,
            noise_px: self.noise_px,
            target,
            intrinsics: self.intrinsics.clone(),
            camera_poses: self.rig.clone(),
            frame_poses: Vec::with_capacity(self.images),
            deformations: Vec::with_capacity(self.images),
            higher_bends: Vec::with_capacity(self.images),
            corrections,
        };
        let mut rows = Vec::new();
        let corners = target.num_corners() as f64;
        // A video's clock and key poses (unused for stills).
        let (mut time, mut keys) = (0usize, Vec::new());
        while truth.frame_poses.len() < self.images {
            // The camera the board is held up to; a lone camera draws nothing here.
            let anchor = if n > 1 { rng.gen_range(0..n) } else { 0 };
            let (camera, k) = (&cameras[anchor], &self.intrinsics[anchor]);
            let held = if self.video {
                self.video_pose(&mut rng, &mut keys, time, camera, k)
            } else {
                self.random_pose(&mut rng, camera, k)
            };
            let pose = if anchor == 0 {
                held
            } else {
                self.rig[anchor].inverse().compose(&held)
            };
            let clock = if self.video {
                time
            } else {
                truth.frame_poses.len()
            };
            time += 1;
            let (bend, higher) = self.random_bend(&mut rng, clock);
            truth.deformations.push(bend);
            truth.higher_bends.push(higher);
            truth.frame_poses.push(pose);
            let j = truth.frame_poses.len() - 1;
            let views = self.project_views(&cameras, &truth, j);
            if (views[anchor].len() as f64) < self.min_visible * corners {
                truth.frame_poses.pop();
                truth.deformations.pop();
                truth.higher_bends.pop();
                continue;
            }
            for (k, view) in views.into_iter().enumerate() {
                if k != anchor && (view.len() as f64) < self.min_visible_other * corners {
                    continue;
                }
                for (i, uv) in view {
                    let noisy = uv + Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng));
                    rows.push((k, j as i64, i, [noisy.x, noisy.y]));
                }
            }
        }
        (Dataset::from_keyed(target, cameras, rows), truth)
    }
}

/// Shorthand: the preset's dataset and truth.
pub fn generate(preset: Preset, images: Option<usize>, seed: u64) -> (Dataset, Truth) {
    Generator::new(preset, images, seed).generate()
}
