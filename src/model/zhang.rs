//! Zhang's initialisation: normalised DLT homographies, closed-form intrinsics,
//! and board poses from homographies.
use crate::error::{Error, Result};
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use nalgebra::{DMatrix, Matrix3, Rotation3, SMatrix, Vector2, Vector3};

/// Hartley normalisation: centroid at the origin, mean distance √2.
fn normalisation(points: &[Vector2<f64>]) -> Matrix3<f64> {
    let n = points.len() as f64;
    let c = points.iter().fold(Vector2::zeros(), |a, p| a + p) / n;
    let d = points.iter().map(|p| (p - c).norm()).sum::<f64>() / n;
    let s = if d > 1e-15 { 2f64.sqrt() / d } else { 1.0 };
    Matrix3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0)
}

fn apply(h: &Matrix3<f64>, p: &Vector2<f64>) -> Vector2<f64> {
    let q = h * Vector3::new(p.x, p.y, 1.0);
    Vector2::new(q.x / q.z, q.y / q.z)
}

/// Homography board (x, y) → pixel by the normalised DLT; `None` when degenerate.
pub fn homography(board: &[Vector2<f64>], image: &[Vector2<f64>]) -> Option<Matrix3<f64>> {
    if board.len() < 4 || board.len() != image.len() {
        return None;
    }
    let tb = normalisation(board);
    let ti = normalisation(image);
    // AᵀA without A: a point's two rows are (−bᵀ, 0, u bᵀ) and (0, −bᵀ, v bᵀ)
    // with b = (x, y, 1), so AᵀA is made of four sums of bbᵀ, weighted by 1, u,
    // v and u² + v² (a fifth of the work of accumulating the rows, which the
    // fisheye initialisation's focal-length search does hundreds of times).
    let mut sums = [Matrix3::<f64>::zeros(); 4];
    for (b, i) in board.iter().zip(image) {
        let b = apply(&tb, b);
        let i = apply(&ti, i);
        let b = Vector3::new(b.x, b.y, 1.0);
        let bbt = b * b.transpose();
        for (sum, w) in sums.iter_mut().zip([1.0, i.x, i.y, i.x * i.x + i.y * i.y]) {
            *sum += w * bbt;
        }
    }
    let [m, mu, mv, mr] = sums;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    ata.fixed_view_mut::<3, 3>(0, 0).copy_from(&m);
    ata.fixed_view_mut::<3, 3>(3, 3).copy_from(&m);
    ata.fixed_view_mut::<3, 3>(0, 6).copy_from(&-mu);
    ata.fixed_view_mut::<3, 3>(6, 0).copy_from(&-mu);
    ata.fixed_view_mut::<3, 3>(3, 6).copy_from(&-mv);
    ata.fixed_view_mut::<3, 3>(6, 3).copy_from(&-mv);
    ata.fixed_view_mut::<3, 3>(6, 6).copy_from(&mr);
    // The null vector of A is the eigenvector of AᵀA with the smallest eigenvalue.
    let eig = ata.symmetric_eigen();
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    let mut sorted: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    // A second (near) null vector means the points do not pin a homography (collinear).
    if sorted[1] <= 1e-10 * sorted[8].max(1e-300) {
        return None;
    }
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let h = ti.try_inverse()? * hn * tb;
    let h = h / h[(2, 2)];
    h.iter().all(|v| v.is_finite()).then_some(h)
}

fn v_ij(h: &Matrix3<f64>, i: usize, j: usize) -> [f64; 6] {
    let (hi, hj) = (h.column(i), h.column(j));
    [
        hi[0] * hj[0],
        hi[0] * hj[1] + hi[1] * hj[0],
        hi[1] * hj[1],
        hi[2] * hj[0] + hi[0] * hj[2],
        hi[2] * hj[1] + hi[1] * hj[2],
        hi[2] * hj[2],
    ]
}

/// Pixel conditioning for the closed form: centre of the image, unit ≈ half its size.
fn conditioning(width: u32, height: u32) -> Matrix3<f64> {
    let s = 2.0 / (width as f64 + height as f64);
    Matrix3::new(
        s,
        0.0,
        -s * width as f64 / 2.0,
        0.0,
        s,
        -s * height as f64 / 2.0,
        0.0,
        0.0,
        1.0,
    )
}

/// Zhang's closed-form intrinsics (zero skew) from at least two homographies.
pub fn intrinsics_closed_form(hs: &[Matrix3<f64>], width: u32, height: u32) -> Option<Intrinsics> {
    if hs.len() < 2 {
        return None;
    }
    let n = conditioning(width, height);
    let mut v = DMatrix::<f64>::zeros(2 * hs.len() + 1, 6);
    for (k, h) in hs.iter().enumerate() {
        let h = n * h;
        let h = h / h.norm();
        let v12 = v_ij(&h, 0, 1);
        let v11 = v_ij(&h, 0, 0);
        let v22 = v_ij(&h, 1, 1);
        for c in 0..6 {
            v[(2 * k, c)] = v12[c];
            v[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    // Zero skew: B12 = 0.
    v[(2 * hs.len(), 1)] = 1.0;
    let vtv = v.transpose() * &v;
    let eig = vtv.symmetric_eigen();
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    let b = eig.eigenvectors.column(imin);
    let (b11, b12, b22, b13, b23, b33) = (b[0], b[1], b[2], b[3], b[4], b[5]);
    let den = b11 * b22 - b12 * b12;
    if den.abs() < 1e-300 || b11.abs() < 1e-300 {
        return None;
    }
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha2 = lambda / b11;
    let beta2 = lambda * b11 / den;
    if !(alpha2 > 0.0 && beta2 > 0.0) {
        return None;
    }
    let (alpha, beta) = (alpha2.sqrt(), beta2.sqrt());
    let gamma = -b12 * alpha2 * beta / lambda;
    let u0 = gamma * v0 / beta - b13 * alpha2 / lambda;
    let kc = Matrix3::new(alpha, 0.0, u0, 0.0, beta, v0, 0.0, 0.0, 1.0);
    let k = n.try_inverse()? * kc;
    let k = Intrinsics::pinhole(k[(0, 0)], k[(1, 1)], k[(0, 2)], k[(1, 2)]);
    plausible(&k, width, height).then_some(k)
}

/// Focal length with the principal point at the image centre: the fallback when the
/// closed form is ill-conditioned (few or near-parallel views).
pub fn intrinsics_centred(hs: &[Matrix3<f64>], width: u32, height: u32) -> Option<Intrinsics> {
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let t = Matrix3::new(1.0, 0.0, -cx, 0.0, 1.0, -cy, 0.0, 0.0, 1.0);
    // With K = diag(f, f, 1): h1ᵀ B h2 = 0 and h1ᵀ B h1 = h2ᵀ B h2 are linear in w = 1/f².
    let (mut num, mut den) = (0.0, 0.0);
    for h in hs {
        let h = t * h;
        let h = h / h.norm();
        let (h1, h2) = (h.column(0), h.column(1));
        let rows = [
            (h1[0] * h2[0] + h1[1] * h2[1], h1[2] * h2[2]),
            (
                h1[0] * h1[0] + h1[1] * h1[1] - h2[0] * h2[0] - h2[1] * h2[1],
                h1[2] * h1[2] - h2[2] * h2[2],
            ),
        ];
        for (a, b) in rows {
            // a·w + b = 0 in least squares.
            num -= a * b;
            den += a * a;
        }
    }
    let w = num / den;
    if !(w > 0.0 && w.is_finite()) {
        return None;
    }
    let f = 1.0 / w.sqrt();
    let k = Intrinsics::pinhole(f, f, cx, cy);
    plausible(&k, width, height).then_some(k)
}

fn plausible(k: &Intrinsics, width: u32, height: u32) -> bool {
    let (w, h) = (width as f64, height as f64);
    let size = w.max(h);
    k.fx().is_finite()
        && k.fy().is_finite()
        && k.fx() > 0.05 * size
        && k.fy() > 0.05 * size
        && k.fx() < 100.0 * size
        && k.fy() < 100.0 * size
        && (k.fx() / k.fy() - 1.0).abs() < 0.5
        && k.cx() > -0.25 * w
        && k.cx() < 1.25 * w
        && k.cy() > -0.25 * h
        && k.cy() < 1.25 * h
}

/// Board pose (camera-from-board) from a homography and the camera matrix.
pub fn pose_from_homography(h: &Matrix3<f64>, k: &Intrinsics) -> Option<Pose> {
    let m = k.camera_matrix().try_inverse()? * h;
    let (c1, c2, c3) = (
        m.column(0).into_owned(),
        m.column(1).into_owned(),
        m.column(2).into_owned(),
    );
    let mut scale = 2.0 / (c1.norm() + c2.norm());
    // The board lies in front of the camera.
    if c3.z * scale < 0.0 {
        scale = -scale;
    }
    pose_from_columns(&c1, &c2, &c3, scale)
}

/// The pose whose rotation is the nearest to (s·c1, s·c2, s·c1 × s·c2) and whose
/// translation is s·c3: the columns of a board-plane homography, scaled.
fn pose_from_columns(
    c1: &Vector3<f64>,
    c2: &Vector3<f64>,
    c3: &Vector3<f64>,
    scale: f64,
) -> Option<Pose> {
    let r1 = c1 * scale;
    let r2 = c2 * scale;
    let r3 = r1.cross(&r2);
    let approx = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = approx.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u = u;
        u.column_mut(2).neg_mut();
        r = u * vt;
    }
    let rot = Rotation3::from_matrix_unchecked(r);
    let t = c3 * scale;
    t.iter()
        .chain(r.iter())
        .all(|v| v.is_finite())
        .then(|| Pose::from_parts(&rot, &t))
}

/// The board pose (camera-from-board) from rays to its corners: a DLT of the
/// board-plane homography that asks only that each ray be parallel to H·(x, y, 1),
/// not that it point forward, so a board at or beyond 90° off axis (seen by a
/// fisheye) is posed like any other. The sign puts the corners ahead along their
/// rays. `None` when degenerate.
pub fn pose_from_rays(board: &[Vector2<f64>], rays: &[Vector3<f64>]) -> Option<Pose> {
    if board.len() < 4 || board.len() != rays.len() {
        return None;
    }
    let tb = normalisation(board);
    let mut ata = nalgebra::SMatrix::<f64, 9, 9>::zeros();
    for (b, r) in board.iter().zip(rays) {
        let b = apply(&tb, b);
        let r = r.normalize();
        let x = [b.x, b.y, 1.0];
        // The three rows of r × (H x) = 0; their span has rank 2.
        let mut rows = [[0.0; 9]; 3];
        for c in 0..3 {
            rows[0][3 + c] = -r.z * x[c];
            rows[0][6 + c] = r.y * x[c];
            rows[1][c] = r.z * x[c];
            rows[1][6 + c] = -r.x * x[c];
            rows[2][c] = -r.y * x[c];
            rows[2][3 + c] = r.x * x[c];
        }
        for row in &rows {
            let v = nalgebra::SVector::<f64, 9>::from_row_slice(row);
            ata += v * v.transpose();
        }
    }
    let eig = ata.symmetric_eigen();
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    if eig.eigenvalues[order[1]] <= 1e-10 * eig.eigenvalues[order[8]].max(1e-300) {
        return None;
    }
    let h = eig.eigenvectors.column(order[0]);
    let h = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]) * tb;
    let (c1, c2, c3) = (
        h.column(0).into_owned(),
        h.column(1).into_owned(),
        h.column(2).into_owned(),
    );
    let mut scale = 2.0 / (c1.norm() + c2.norm());
    let ahead: f64 = board
        .iter()
        .zip(rays)
        .map(|(b, r)| r.dot(&(h * Vector3::new(b.x, b.y, 1.0))))
        .sum();
    if ahead < 0.0 {
        scale = -scale;
    }
    pose_from_columns(&c1, &c2, &c3, scale)
}

/// The board pose (camera-from-board) of one view under `k`: [`pose_from_rays`]
/// on every pixel that `k` unprojects.
pub fn pose_from_pixels(
    k: &Intrinsics,
    board: &[Vector2<f64>],
    pixels: &[Vector2<f64>],
) -> Option<Pose> {
    let (mut b, mut rays) = (
        Vec::with_capacity(board.len()),
        Vec::with_capacity(board.len()),
    );
    for (x, uv) in board.iter().zip(pixels) {
        if let Some(ray) = k.unproject(uv) {
            b.push(*x);
            rays.push(ray);
        }
    }
    pose_from_rays(&b, &rays)
}

/// Intrinsics from homographies: the closed form, else the centred fallback.
pub fn initial_intrinsics(
    hs: &[Matrix3<f64>],
    width: u32,
    height: u32,
) -> Result<(Intrinsics, bool)> {
    if let Some(k) = intrinsics_closed_form(hs, width, height) {
        return Ok((k, false));
    }
    intrinsics_centred(hs, width, height)
        .map(|k| (k, true))
        .ok_or_else(|| {
            Error::Init(format!(
                "no focal length fits the {} board views (are they all parallel to the image plane?)",
                hs.len()
            ))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact rays from a known pose give that pose back, for a board ahead of the
    /// camera and for one beside and behind it (its centre 110° off axis), where
    /// a homography of pixels or of normalised coordinates does not exist.
    #[test]
    fn pose_from_rays_recovers_poses_beyond_ninety_degrees() {
        let board: Vec<Vector2<f64>> = (0..35)
            .map(|i| Vector2::new((i % 7) as f64 * 0.03, (i / 7) as f64 * 0.03))
            .collect();
        for (axis_angle, t, beside) in [
            (
                Vector3::new(0.2, -0.1, 0.05),
                Vector3::new(-0.1, 0.05, 0.6),
                false,
            ),
            (
                Vector3::new(0.1, 1.4, 0.3),
                Vector3::new(0.5, 0.02, -0.18),
                true,
            ),
        ] {
            let truth = Pose::from_parts(&Rotation3::new(axis_angle), &t);
            let rays: Vec<Vector3<f64>> = board
                .iter()
                .map(|b| truth.transform(&Vector3::new(b.x, b.y, 0.0)).normalize() * 3.0)
                .collect();
            let centre = truth.transform(&Vector3::new(0.09, 0.06, 0.0));
            // The angle between the optical axis and the ray to the board's centre.
            let off_axis = centre.xy().norm().atan2(centre.z).to_degrees();
            assert_eq!(beside, off_axis > 100.0, "{off_axis}°");
            let pose = pose_from_rays(&board, &rays).expect("a pose");
            let dr = (pose.rotation_matrix().matrix() - truth.rotation_matrix().matrix()).norm();
            let dt = (pose.translation_vector() - t).norm();
            assert!(
                dr < 1e-9 && dt < 1e-9,
                "off by {dr} (rotation matrix), {dt} m (centre {centre:?})"
            );
        }
        let collinear: Vec<Vector2<f64>> = (0..6).map(|i| Vector2::new(i as f64, 0.0)).collect();
        let rays = vec![Vector3::new(0.0, 0.0, 1.0); 6];
        assert!(pose_from_rays(&collinear, &rays).is_none());
    }

    /// A known projective map of board points (pixel scale, strong perspective)
    /// is recovered to rounding, and collinear points give none.
    #[test]
    fn homography_recovers_a_known_map() {
        let truth = Matrix3::new(1450.0, 35.0, 610.0, -22.0, 1390.0, 410.0, 0.21, -0.34, 1.0);
        let board: Vec<Vector2<f64>> = (0..48)
            .map(|i| Vector2::new((i % 8) as f64 * 0.04, (i / 8) as f64 * 0.04))
            .collect();
        let image: Vec<Vector2<f64>> = board.iter().map(|b| apply(&truth, b)).collect();
        let h = homography(&board, &image).expect("a homography");
        let off = (h - truth).norm() / truth.norm();
        assert!(off < 1e-10, "relative error {off:e}\n{h}");
        let line: Vec<Vector2<f64>> = (0..8).map(|i| Vector2::new(i as f64 * 0.04, 0.1)).collect();
        let image: Vec<Vector2<f64>> = line.iter().map(|b| apply(&truth, b)).collect();
        assert!(homography(&line, &image).is_none());
    }
}
