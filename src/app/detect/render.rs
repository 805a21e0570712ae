//! Synthetic chessboard renderer with exact ground truth.
//!
//! Tests and the detection benchmark need photos whose true corner
//! positions are known to far better than the 0.1 px we assert. This module
//! ray-casts every sub-sample of every pixel through a pinhole camera with
//! two-term radial distortion onto a planar or slightly bent board, so the
//! picture and the truth come from the same geometry; the truth is the exact
//! projection of each 3-D inner corner, not something measured from the image.
//!
//! Conventions (the crate's): inner corner (r, c) sits at board point
//! (c·spacing, r·spacing, z); index = r·cols + c; pixel (0,0) is the centre of
//! the top-left pixel. The square diagonally outside corner 0 (board cell
//! containing (−s/2, −s/2)) is dark; a white margin of one square surrounds
//! the squares, and beyond that a mid-grey background.

use crate::model::lens::{Intrinsics, LensModel};
use image::{GrayImage, Luma};
use nalgebra::Vector3;

/// Pinhole camera with radial distortion on normalised coordinates:
/// x_d = x · (1 + k1 r² + k2 r⁴): a shorthand for `radial3` intrinsics with
/// k3 = 0 (`Intrinsics::from`).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Focal length along u (px).
    pub fx: f64,
    /// Focal length along v (px).
    pub fy: f64,
    /// Principal point u (px).
    pub cx: f64,
    /// Principal point v (px).
    pub cy: f64,
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
}

impl From<Camera> for Intrinsics {
    fn from(c: Camera) -> Intrinsics {
        Intrinsics::radial3([c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, 0.0])
    }
}

/// Board-to-camera pose: X_cam = R(rvec) · X_board + t, rvec a Rodrigues vector.
#[derive(Clone, Copy, Debug)]
pub struct Pose {
    /// Rotation (Rodrigues vector, radians).
    pub rvec: [f64; 3],
    /// Translation (board units, metres in the tests).
    pub t: [f64; 3],
}

/// Everything that defines one rendered picture. A struct rather than eleven
/// positional arguments because callers vary a few fields at a time.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The lens (any model of `model::lens`).
    pub camera: Intrinsics,
    /// Full field of view of a fisheye lens in degrees: rays more than half
    /// of it off the optical axis are black, as outside a real fisheye's
    /// image circle. 0 = no image circle.
    pub image_circle_deg: f64,
    /// Vignetting: brightness falls by this fraction at the image circle's
    /// rim (or, without one, at the image corners), quadratically in the
    /// angle off the axis. 0 = none.
    pub vignetting: f64,
    /// Camera-from-board pose.
    pub pose: Pose,
    /// Parabolic bend: board z = bend · (1 − (2x/W − 1)²), W the inner-corner
    /// width, so the centre column bulges by `bend` (board units, +z away
    /// from a camera looking at the board's front) and the edge columns stay flat.
    pub bend: f64,
    /// Inner corners per column.
    pub rows: usize,
    /// Inner corners per row.
    pub cols: usize,
    /// Square size (board units).
    pub spacing: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Gaussian blur sigma in pixels (0 = none), applied after sampling.
    pub blur: f64,
    /// Gaussian noise sigma in grey levels (0..255 scale).
    pub noise: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Sub-samples per pixel side (anti-aliasing); 4 gives 16 rays per pixel.
    pub supersample: u32,
}

/// Grey level of the board's dark squares.
pub const DARK: f64 = 30.0;
/// Grey level of the board's light squares and margin.
pub const LIGHT: f64 = 220.0;
/// Grey level of everything that is not the board.
pub const BACKGROUND: f64 = 110.0;
/// Outside a fisheye's image circle.
const BLACK: f64 = 4.0;

/// Render `scene`; returns the 8-bit image and, per inner corner index, its
/// true pixel position (None when it projects outside the image or behind
/// the camera).
pub fn render_board(scene: &Scene) -> (GrayImage, Vec<Option<[f64; 2]>>) {
    render_with_albedo(scene, &|bx, by| board_albedo(scene, bx, by))
}

/// Grey level (0..255) of the printed pattern at board point (bx, by).
pub type Albedo<'a> = &'a (dyn Fn(f64, f64) -> f64 + Sync);

/// [`render_board`] with another printed pattern: `albedo(bx, by)` is the grey
/// level (0..255) at board point (bx, by) in the board frame above (a ChArUco
/// board's, for example); the truth is still the scene's inner corners.
pub fn render_with_albedo(scene: &Scene, albedo: Albedo) -> (GrayImage, Vec<Option<[f64; 2]>>) {
    let optics = Optics::new(scene);
    let mut buf = sample_image(scene, &optics, albedo);
    if scene.blur > 0.0 {
        gaussian_blur(
            &mut buf,
            scene.width as usize,
            scene.height as usize,
            scene.blur,
        );
    }
    let mut rng = SplitMix(scene.seed);
    let img = GrayImage::from_fn(scene.width, scene.height, |x, y| {
        let v = buf[y as usize * scene.width as usize + x as usize] + scene.noise * rng.gauss();
        Luma([v.round().clamp(0.0, 255.0) as u8])
    });
    (img, truth(scene, &optics.rot))
}

/// The true pixel position of every inner corner (as [`render_board`] returns
/// it), without rendering.
pub fn true_corners(scene: &Scene) -> Vec<Option<[f64; 2]>> {
    truth(scene, &rodrigues(scene.pose.rvec))
}

/// Exact projections of the inner corners.
fn truth(scene: &Scene, rot: &[[f64; 3]; 3]) -> Vec<Option<[f64; 2]>> {
    (0..scene.rows * scene.cols)
        .map(|idx| {
            seen_at(
                scene,
                rot,
                (idx % scene.cols) as f64,
                (idx / scene.cols) as f64,
            )
        })
        .collect()
}

/// Per inner corner: whether its four squares are wholly in the picture
/// (their outer corners inside the image and the image circle), i.e. a
/// detector could see the whole X-junction. Tests count found corners
/// against these.
pub fn fully_visible(scene: &Scene) -> Vec<bool> {
    let rot = rodrigues(scene.pose.rvec);
    (0..scene.rows * scene.cols)
        .map(|idx| {
            let (r, c) = ((idx / scene.cols) as f64, (idx % scene.cols) as f64);
            [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)]
                .iter()
                .all(|(dc, dr)| seen_at(scene, &rot, c + dc, r + dr).is_some())
        })
        .collect()
}

/// Pixel position of board point (c, r)·spacing when it lies in the image.
fn seen_at(scene: &Scene, rot: &[[f64; 3]; 3], c: f64, r: f64) -> Option<[f64; 2]> {
    let (w, h) = (scene.width as f64, scene.height as f64);
    let (bx, by) = (c * scene.spacing, r * scene.spacing);
    let p = transform(rot, &scene.pose.t, [bx, by, bend_z(scene, bx)]);
    let uv = project_seen(scene, p)?;
    let inside = uv[0] >= 0.0 && uv[1] >= 0.0 && uv[0] <= w - 1.0 && uv[1] <= h - 1.0;
    inside.then_some(uv)
}

fn sample_image(scene: &Scene, optics: &Optics, albedo: Albedo) -> Vec<f64> {
    let n = scene.supersample.max(1);
    let inv_n = 1.0 / n as f64;
    let mut out = Vec::with_capacity(scene.width as usize * scene.height as usize);
    for y in 0..scene.height {
        for x in 0..scene.width {
            // Adaptive: a pixel whose centre and four corners agree lies
            // inside one region (squares are many pixels wide), so only
            // pixels straddling an edge pay for the full n×n supersampling.
            let (xf, yf) = (x as f64, y as f64);
            let centre = shade(scene, optics, albedo, xf, yf);
            let uniform = [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)]
                .iter()
                .all(|(dx, dy)| {
                    (shade(scene, optics, albedo, xf + dx, yf + dy) - centre).abs() < 0.5
                });
            if uniform {
                out.push(centre);
                continue;
            }
            let mut acc = 0.0;
            for sy in 0..n {
                for sx in 0..n {
                    let u = xf + (sx as f64 + 0.5) * inv_n - 0.5;
                    let v = yf + (sy as f64 + 0.5) * inv_n - 0.5;
                    acc += shade(scene, optics, albedo, u, v);
                }
            }
            out.push(acc * inv_n * inv_n);
        }
    }
    out
}

/// Grey level seen along the ray through pixel position (u, v).
fn shade(scene: &Scene, optics: &Optics, albedo: Albedo, u: f64, v: f64) -> f64 {
    let Some(ray) = optics.ray(scene, u, v) else {
        return if scene.image_circle_deg > 0.0 {
            BLACK
        } else {
            BACKGROUND
        };
    };
    let theta = ray[0].hypot(ray[1]).atan2(ray[2]);
    if optics.theta_max.is_some_and(|m| theta > m) {
        return BLACK;
    }
    let light = 1.0 - scene.vignetting * (theta / optics.theta_ref).powi(2);
    // Ray d in the camera frame; express origin and direction in the board
    // frame (R^T (X - t)) and intersect with the (bent) surface.
    let rot = &optics.rot;
    let t = scene.pose.t;
    let o = mul_t(rot, [-t[0], -t[1], -t[2]]);
    let d = mul_t(rot, ray);
    if d[2].abs() < 1e-12 {
        return BACKGROUND * light;
    }
    // Fixed-point on z: intersect with plane z = z0, re-evaluate the bend there.
    let mut z0 = 0.0;
    let (mut bx, mut by) = (0.0, 0.0);
    let iters = if scene.bend == 0.0 { 1 } else { 8 };
    for _ in 0..iters {
        let s = (z0 - o[2]) / d[2];
        if s <= 0.0 {
            return BACKGROUND * light;
        }
        bx = o[0] + s * d[0];
        by = o[1] + s * d[1];
        z0 = bend_z(scene, bx);
    }
    albedo(bx, by) * light
}

/// What every ray of one picture shares: the board rotation, the image
/// circle's half angle, the angle at which vignetting reaches its value, and
/// for a fisheye lens its inverse as a table.
struct Optics {
    rot: [[f64; 3]; 3],
    theta_max: Option<f64>,
    theta_ref: f64,
    fisheye: Option<RadialTable>,
}

/// A radially symmetric lens (`kb4`, `ds`) maps the angle θ off the axis to a
/// radius ρ in normalised image coordinates ((u − cx)/fx, (v − cy)/fy).
/// Sampling the model's own forward projection densely and interpolating θ(ρ)
/// inverts it to ~1e-6 px for a fraction of the cost of the model's
/// iterative inverse at every sub-sample.
struct RadialTable {
    /// (ρ, θ) with ρ strictly increasing.
    samples: Vec<(f64, f64)>,
}

impl RadialTable {
    const STEPS: usize = 8192;

    fn new(cam: &Intrinsics, theta_end: f64) -> RadialTable {
        let (fx, cx) = (cam.fx(), cam.cx());
        let mut samples: Vec<(f64, f64)> = vec![(0.0, 0.0)];
        for i in 1..=Self::STEPS {
            let theta = theta_end * i as f64 / Self::STEPS as f64;
            let ray = Vector3::new(theta.sin(), 0.0, theta.cos());
            let Some(uv) = cam.project(&ray) else { break };
            let rho = (uv.x - cx) / fx;
            if rho <= samples.last().map_or(0.0, |s| s.0) {
                break;
            }
            samples.push((rho, theta));
        }
        RadialTable { samples }
    }

    /// θ at normalised radius `rho`; None beyond the table (outside the
    /// lens's valid field).
    fn theta(&self, rho: f64) -> Option<f64> {
        let i = self.samples.partition_point(|s| s.0 < rho);
        if i == 0 {
            return Some(0.0);
        }
        let (r1, t1) = *self.samples.get(i)?;
        let (r0, t0) = self.samples[i - 1];
        Some(t0 + (t1 - t0) * (rho - r0) / (r1 - r0))
    }
}

impl Optics {
    fn new(scene: &Scene) -> Optics {
        let theta_max =
            (scene.image_circle_deg > 0.0).then(|| scene.image_circle_deg.to_radians() / 2.0);
        let cam = &scene.camera;
        let fisheye = (cam.model() != LensModel::Radial3).then(|| {
            // A little beyond the circle, so pixels at its rim interpolate.
            let end = theta_max.map_or(std::f64::consts::PI * 0.999, |t| (t + 0.05).min(3.1));
            RadialTable::new(cam, end)
        });
        let mut optics = Optics {
            rot: rodrigues(scene.pose.rvec),
            theta_max,
            theta_ref: 1.0,
            fisheye,
        };
        optics.theta_ref = theta_max.unwrap_or_else(|| {
            let corner = optics.ray(scene, 0.0, 0.0).unwrap_or([1.0, 1.0, 1.0]);
            corner[0].hypot(corner[1]).atan2(corner[2]).max(1e-3)
        });
        optics
    }

    /// The camera-frame ray through pixel (u, v); None where the lens maps
    /// no ray there. `radial3` has a fast fixed-point inverse (it renders most
    /// of the tests' photos); the fisheye models a table of their projection.
    fn ray(&self, scene: &Scene, u: f64, v: f64) -> Option<[f64; 3]> {
        let cam = &scene.camera;
        if cam.model() == LensModel::Radial3 {
            let p = cam.params();
            let (xd, yd) = ((u - p[2]) / p[0], (v - p[3]) / p[1]);
            let (x, y) = undistort_radial(p[4], p[5], p[6], xd, yd)?;
            return Some([x, y, 1.0]);
        }
        let p = cam.params();
        let m = [(u - p[2]) / p[0], (v - p[3]) / p[1]];
        let rho = m[0].hypot(m[1]);
        let theta = self.fisheye.as_ref()?.theta(rho)?;
        if rho < 1e-12 {
            return Some([0.0, 0.0, 1.0]);
        }
        let s = theta.sin() / rho;
        Some([m[0] * s, m[1] * s, theta.cos()])
    }
}

/// Pixel position of a camera-frame point as the picture shows it: None
/// behind the lens or outside its image circle.
fn project_seen(scene: &Scene, p: [f64; 3]) -> Option<[f64; 2]> {
    if scene.image_circle_deg > 0.0 {
        let theta = p[0].hypot(p[1]).atan2(p[2]);
        if theta > scene.image_circle_deg.to_radians() / 2.0 {
            return None;
        }
    } else if p[2] <= 1e-9 {
        return None;
    }
    let uv = scene.camera.project(&Vector3::new(p[0], p[1], p[2]))?;
    Some([uv.x, uv.y])
}

fn board_albedo(scene: &Scene, bx: f64, by: f64) -> f64 {
    let s = scene.spacing;
    let (fx, fy) = ((bx / s).floor(), (by / s).floor());
    let in_squares = fx >= -1.0 && fx <= scene.cols as f64 - 1.0 && fy >= -1.0;
    if in_squares && fy <= scene.rows as f64 - 1.0 {
        return if (fx as i64 + fy as i64).rem_euclid(2) == 0 {
            DARK
        } else {
            LIGHT
        };
    }
    let in_margin = bx >= -2.0 * s
        && by >= -2.0 * s
        && bx <= (scene.cols as f64 + 1.0) * s
        && by <= (scene.rows as f64 + 1.0) * s;
    if in_margin {
        LIGHT
    } else {
        BACKGROUND
    }
}

fn bend_z(scene: &Scene, bx: f64) -> f64 {
    let w = (scene.cols.max(2) - 1) as f64 * scene.spacing;
    let a = 2.0 * bx / w - 1.0;
    scene.bend * (1.0 - a * a)
}

/// Invert the radial model by fixed-point iteration (converges for the mild
/// distortion used in tests); None if it diverges.
fn undistort_radial(k1: f64, k2: f64, k3: f64, xd: f64, yd: f64) -> Option<(f64, f64)> {
    let (mut x, mut y) = (xd, yd);
    for _ in 0..50 {
        let r2 = x * x + y * y;
        let f = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        if f <= 0.1 {
            return None;
        }
        let (nx, ny) = (xd / f, yd / f);
        let done = (nx - x).abs() + (ny - y).abs() < 1e-13;
        (x, y) = (nx, ny);
        if done {
            break;
        }
    }
    Some((x, y))
}

fn transform(rot: &[[f64; 3]; 3], t: &[f64; 3], p: [f64; 3]) -> [f64; 3] {
    let mut out = *t;
    for (i, row) in rot.iter().enumerate() {
        out[i] += row[0] * p[0] + row[1] * p[1] + row[2] * p[2];
    }
    out
}

/// R^T · p.
fn mul_t(rot: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (i, o) in out.iter_mut().enumerate() {
        *o = rot[0][i] * p[0] + rot[1][i] * p[1] + rot[2][i] * p[2];
    }
    out
}

/// Rotation matrix of a Rodrigues vector.
pub fn rodrigues(r: [f64; 3]) -> [[f64; 3]; 3] {
    let th = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    if th < 1e-12 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let k = [r[0] / th, r[1] / th, r[2] / th];
    let (s, c) = th.sin_cos();
    let v = 1.0 - c;
    [
        [
            c + k[0] * k[0] * v,
            k[0] * k[1] * v - k[2] * s,
            k[0] * k[2] * v + k[1] * s,
        ],
        [
            k[1] * k[0] * v + k[2] * s,
            c + k[1] * k[1] * v,
            k[1] * k[2] * v - k[0] * s,
        ],
        [
            k[2] * k[0] * v - k[1] * s,
            k[2] * k[1] * v + k[0] * s,
            c + k[2] * k[2] * v,
        ],
    ]
}

/// Separable Gaussian blur with clamp-to-edge borders.
fn gaussian_blur(buf: &mut [f64], w: usize, h: usize, sigma: f64) {
    let rad = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-rad..=rad)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let pass = |src: &[f64], stride_in_line: usize, line_len: usize, lines: usize, line_stride| {
        let mut dst = vec![0.0; src.len()];
        for l in 0..lines {
            for i in 0..line_len {
                let mut acc = 0.0;
                for (k, wk) in kernel.iter().enumerate() {
                    let j =
                        (i as isize + k as isize - rad).clamp(0, line_len as isize - 1) as usize;
                    acc += wk * src[l * line_stride + j * stride_in_line];
                }
                dst[l * line_stride + i * stride_in_line] = acc / norm;
            }
        }
        dst
    };
    let horiz = pass(buf, 1, w, h, w);
    let vert = pass(&horiz, w, h, w, 1);
    buf.copy_from_slice(&vert);
}

/// Small deterministic RNG so renders are reproducible without a dependency.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Box–Muller standard normal.
    fn gauss(&mut self) -> f64 {
        let (a, b) = (self.next_f64(), self.next_f64());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }
}
