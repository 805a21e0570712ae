//! Which of a video's sampled frames to calibrate from: sharp ones (no motion
//! blur, judged against the frames around them), with the board found, each
//! different enough in pose and image coverage from those already kept, up to
//! `max_frames`. Pure functions of the frames' sharpness and corners; decoding
//! and detection are the caller's.
use image::GrayImage;
use nalgebra::{Matrix3, SMatrix, SymmetricEigen, Vector3};

/// Frames on each side whose median sharpness a frame is judged against.
pub const BLUR_WINDOW: usize = 7;
/// A frame with less than this fraction of its neighbours' median sharpness is
/// motion-blurred: blur along the motion removes most of the Laplacian's energy
/// (a Gaussian blur of σ = 1.5 px removes about 90 % of it at a sharp edge),
/// while a steady hand changes it by far less from one frame to the next.
pub const BLUR_RATIO: f64 = 0.5;
/// Frames closer than this in [`Descriptor::distance`] to a kept one add little:
/// about 8 % of the image in position, 5° in tilt, or 17 % in size.
pub const MIN_DIFFERENCE: f64 = 0.08;
/// Weight of the image coverage a frame adds (fraction of [`CELLS`]) beside its
/// pose difference.
const COVER_WEIGHT: f64 = 1.0;
/// The image is cut into CELLS_SIDE × CELLS_SIDE cells for coverage.
const CELLS_SIDE: usize = 8;
const CELLS: usize = CELLS_SIDE * CELLS_SIDE;

/// Sharpness of a grey image: the variance of its 4-neighbour Laplacian, which
/// edges dominate and motion blur removes.
pub fn sharpness(img: &GrayImage) -> f64 {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let px = img.as_raw();
    let (mut sum, mut sum2, mut n) = (0.0f64, 0.0f64, 0.0f64);
    for y in 1..h - 1 {
        let row = y * w;
        for x in 1..w - 1 {
            let i = row + x;
            let l = px[i - 1] as f64 + px[i + 1] as f64 + px[i - w] as f64 + px[i + w] as f64
                - 4.0 * px[i] as f64;
            sum += l;
            sum2 += l * l;
            n += 1.0;
        }
    }
    let mean = sum / n;
    (sum2 / n - mean * mean).max(0.0)
}

/// Per frame (in time order): its sharpness relative to the median of the
/// [`BLUR_WINDOW`] frames on each side, `Some(ratio)` when below [`BLUR_RATIO`].
pub fn blurred(sharpness: &[f64]) -> Vec<Option<f64>> {
    (0..sharpness.len())
        .map(|i| {
            let lo = i.saturating_sub(BLUR_WINDOW);
            let hi = (i + BLUR_WINDOW + 1).min(sharpness.len());
            let mut around: Vec<f64> = (lo..hi).filter(|&j| j != i).map(|j| sharpness[j]).collect();
            if around.is_empty() {
                return None;
            }
            around.sort_by(f64::total_cmp);
            let median = around[around.len() / 2];
            let ratio = sharpness[i] / median;
            (median > 0.0 && ratio < BLUR_RATIO).then_some(ratio)
        })
        .collect()
}

/// The board's place in one frame, for comparing frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Descriptor {
    /// Centre of the corners, as a fraction of the image width and height.
    centre: [f64; 2],
    /// The board's normal in the camera frame (x and y; z is the rest), from its
    /// homography with a guessed focal length: its tilt.
    tilt: [f64; 2],
    /// Log of the corners' spread relative to the image size.
    log_size: f64,
    /// Image cells (one bit each) holding a corner.
    cells: u64,
}

impl Descriptor {
    /// The descriptor of corners `(index, u, v)` of a board with `cols` corners
    /// per row in a `width` × `height` image; None for fewer than 4 corners or
    /// corners on one line.
    pub fn of(corners: &[[f64; 3]], cols: usize, width: u32, height: u32) -> Option<Descriptor> {
        if corners.len() < 4 {
            return None;
        }
        let (w, h) = (width as f64, height as f64);
        let n = corners.len() as f64;
        let cu = corners.iter().map(|c| c[1]).sum::<f64>() / n;
        let cv = corners.iter().map(|c| c[2]).sum::<f64>() / n;
        let su = (corners.iter().map(|c| (c[1] - cu).powi(2)).sum::<f64>() / n).sqrt();
        let sv = (corners.iter().map(|c| (c[2] - cv).powi(2)).sum::<f64>() / n).sqrt();
        let spread = (su * sv).sqrt() / (w * h).sqrt();
        if spread <= 0.0 {
            return None;
        }
        let hom = homography(corners, cols)?;
        // A guessed lens (focal 0.8 × the larger side, centred): the tilt is off
        // by the guess's error, alike for every frame, which is all a comparison needs.
        let f = 0.8 * w.max(h);
        let k_inv = Matrix3::new(
            1.0 / f,
            0.0,
            -w / 2.0 / f,
            0.0,
            1.0 / f,
            -h / 2.0 / f,
            0.0,
            0.0,
            1.0,
        );
        let m = k_inv * hom;
        let r1: Vector3<f64> = m.column(0).normalize();
        let r2: Vector3<f64> = m.column(1).normalize();
        let normal = r1.cross(&r2);
        if normal.norm() < 1e-9 || !normal.iter().all(|v| v.is_finite()) {
            return None;
        }
        let normal = normal.normalize();
        let mut cells = 0u64;
        for c in corners {
            let i = ((c[1] / w * CELLS_SIDE as f64).floor() as usize).min(CELLS_SIDE - 1);
            let j = ((c[2] / h * CELLS_SIDE as f64).floor() as usize).min(CELLS_SIDE - 1);
            cells |= 1 << (j * CELLS_SIDE + i);
        }
        Some(Descriptor {
            centre: [cu / w, cv / h],
            tilt: [normal.x, normal.y],
            log_size: spread.ln(),
            cells,
        })
    }

    /// How different two frames are: position, tilt and (half-weighted) log size.
    pub fn distance(&self, o: &Descriptor) -> f64 {
        let d = [
            self.centre[0] - o.centre[0],
            self.centre[1] - o.centre[1],
            self.tilt[0] - o.tilt[0],
            self.tilt[1] - o.tilt[1],
            0.5 * (self.log_size - o.log_size),
        ];
        d.iter().map(|x| x * x).sum::<f64>().sqrt()
    }
}

/// The board-to-image homography of corners `(index, u, v)` (board points in
/// grid units), by the normalised DLT; None when degenerate.
fn homography(corners: &[[f64; 3]], cols: usize) -> Option<Matrix3<f64>> {
    let board: Vec<[f64; 2]> = corners
        .iter()
        .map(|c| {
            let i = c[0] as usize;
            [(i % cols) as f64, (i / cols) as f64]
        })
        .collect();
    let image: Vec<[f64; 2]> = corners.iter().map(|c| [c[1], c[2]]).collect();
    let (tb, _) = normaliser(&board)?;
    let (ti, ti_inv) = normaliser(&image)?;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (b, p) in board.iter().zip(&image) {
        let b = tb * Vector3::new(b[0], b[1], 1.0);
        let p = ti * Vector3::new(p[0], p[1], 1.0);
        let rows = [
            [-b.x, -b.y, -1.0, 0.0, 0.0, 0.0, p.x * b.x, p.x * b.y, p.x],
            [0.0, 0.0, 0.0, -b.x, -b.y, -1.0, p.y * b.x, p.y * b.y, p.y],
        ];
        for r in rows {
            let v = SMatrix::<f64, 9, 1>::from_column_slice(&r);
            ata += v * v.transpose();
        }
    }
    let eig = SymmetricEigen::new(ata);
    let k = eig.eigenvalues.imin();
    let h = eig.eigenvectors.column(k);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let hom = ti_inv * hn * tb;
    hom.iter().all(|v| v.is_finite()).then_some(hom)
}

/// Hartley's normalisation of 2-D points (centroid to 0, mean distance √2) and
/// its inverse; None when every point is the same.
fn normaliser(pts: &[[f64; 2]]) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
    let n = pts.len() as f64;
    let cx = pts.iter().map(|p| p[0]).sum::<f64>() / n;
    let cy = pts.iter().map(|p| p[1]).sum::<f64>() / n;
    let mean = pts
        .iter()
        .map(|p| ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    if mean <= 1e-12 {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean;
    let t = Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0);
    let inv = Matrix3::new(1.0 / s, 0.0, cx, 0.0, 1.0 / s, cy, 0.0, 0.0, 1.0);
    Some((t, inv))
}

/// What became of one sampled frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Calibrated from.
    Kept,
    /// No usable board in it.
    NoBoard,
    /// Motion-blurred: its sharpness is this fraction of its neighbours'.
    Blurred(f64),
    /// Too like the kept frame with this video frame index.
    Similar(usize),
    /// Different enough, but `max_frames` frames were kept before it.
    Surplus,
}

/// One sampled frame as the choice sees it.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// Frame index in the video.
    pub index: usize,
    /// Laplacian variance ([`sharpness`]).
    pub sharpness: f64,
    /// Whether the detector found a usable board.
    pub usable: bool,
    /// The board's corners `(index, u, v)`.
    pub corners: Vec<[f64; 3]>,
}

/// The verdict on every frame (given in time order): the blurred and those
/// without a board out, then, greedily, the frame farthest from those kept
/// (with a bonus for the image cells it adds) until `max_frames` are kept or
/// every other frame is within [`MIN_DIFFERENCE`] of a kept one and adds no
/// cell. The first kept is the one with the most corners.
pub fn choose(
    frames: &[Candidate],
    cols: usize,
    width: u32,
    height: u32,
    max_frames: usize,
) -> Vec<Verdict> {
    let blur = blurred(&frames.iter().map(|f| f.sharpness).collect::<Vec<_>>());
    let mut verdict: Vec<Verdict> = frames
        .iter()
        .zip(&blur)
        .map(|(f, b)| match (f.usable, b) {
            (false, _) => Verdict::NoBoard,
            (true, Some(r)) => Verdict::Blurred(*r),
            (true, None) => Verdict::Surplus,
        })
        .collect();
    let desc: Vec<Option<Descriptor>> = frames
        .iter()
        .zip(&verdict)
        .map(|(f, v)| match v {
            Verdict::Surplus => Descriptor::of(&f.corners, cols, width, height),
            _ => None,
        })
        .collect();
    for (v, d) in verdict.iter_mut().zip(&desc) {
        if *v == Verdict::Surplus && d.is_none() {
            *v = Verdict::NoBoard;
        }
    }
    let open: Vec<usize> = (0..frames.len()).filter(|&i| desc[i].is_some()).collect();
    let Some(&first) = open.iter().max_by_key(|&&i| frames[i].corners.len()) else {
        return verdict;
    };
    let d = |i: usize| desc[i].expect("open frames have a descriptor");
    // Per open frame: its distance to the nearest kept frame and that frame.
    let mut nearest: Vec<(f64, usize)> = vec![(f64::INFINITY, first); frames.len()];
    let mut covered = 0u64;
    let mut next = Some(first);
    let mut kept = 0;
    while let Some(k) = next.take() {
        verdict[k] = Verdict::Kept;
        kept += 1;
        covered |= d(k).cells;
        for &i in &open {
            let dist = d(i).distance(&d(k));
            if dist < nearest[i].0 {
                nearest[i] = (dist, k);
            }
        }
        if kept >= max_frames {
            break;
        }
        let gain = |i: usize| (d(i).cells & !covered).count_ones() as f64 / CELLS as f64;
        next = open
            .iter()
            .copied()
            .filter(|&i| verdict[i] == Verdict::Surplus)
            .filter(|&i| nearest[i].0 >= MIN_DIFFERENCE || gain(i) > 0.0)
            .max_by(|&a, &b| {
                let score = |i: usize| nearest[i].0 + COVER_WEIGHT * gain(i);
                score(a).total_cmp(&score(b))
            });
    }
    for &i in &open {
        if verdict[i] == Verdict::Surplus && nearest[i].0 < MIN_DIFFERENCE {
            verdict[i] = Verdict::Similar(frames[nearest[i].1].index);
        }
    }
    verdict
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 9-column board's corners seen frontally at `(u0, v0)` with `step` px.
    fn board(u0: f64, v0: f64, step: f64) -> Vec<[f64; 3]> {
        (0..54)
            .map(|i| {
                [
                    i as f64,
                    u0 + (i % 9) as f64 * step,
                    v0 + (i / 9) as f64 * step,
                ]
            })
            .collect()
    }

    fn candidate(index: usize, corners: Vec<[f64; 3]>) -> Candidate {
        Candidate {
            index,
            sharpness: 100.0,
            usable: true,
            corners,
        }
    }

    #[test]
    fn blur_lowers_the_laplacian_variance() {
        let sharp = GrayImage::from_fn(64, 64, |x, y| {
            image::Luma([if (x / 8 + y / 8) % 2 == 0 { 30 } else { 220 }])
        });
        let soft = image::imageops::blur(&sharp, 2.0);
        assert!(sharpness(&soft) < 0.2 * sharpness(&sharp));
        let s = [100.0, 90.0, 110.0, 30.0, 105.0, 95.0, 100.0];
        let b = blurred(&s);
        assert!(b[3].is_some_and(|r| (r - 0.3).abs() < 0.05), "{b:?}");
        assert_eq!(b.iter().filter(|r| r.is_some()).count(), 1);
    }

    #[test]
    fn a_frontal_board_has_no_tilt_and_a_tilted_one_has() {
        let d = Descriptor::of(&board(100.0, 100.0, 20.0), 9, 640, 480).unwrap();
        assert!(d.tilt[0].abs() < 1e-9 && d.tilt[1].abs() < 1e-9, "{d:?}");
        // Columns shrinking to the right: the board turned about its vertical axis.
        let tilted: Vec<[f64; 3]> = board(0.0, 0.0, 1.0)
            .iter()
            .map(|c| {
                let (x, y) = (c[1], c[2]);
                let z = 1.0 + 0.05 * x;
                [c[0], 200.0 + 20.0 * x / z, 200.0 + 20.0 * (y - 2.5) / z]
            })
            .collect();
        let t = Descriptor::of(&tilted, 9, 640, 480).unwrap();
        assert!(t.tilt[0].abs() > 0.1, "{t:?}");
    }

    #[test]
    fn keeps_different_frames_up_to_max_and_names_the_similar() {
        // Ten frames at one place, then three elsewhere.
        let mut frames: Vec<Candidate> = (0..10)
            .map(|i| candidate(i * 5, board(200.0 + i as f64 * 0.5, 150.0, 20.0)))
            .collect();
        for (k, u) in [(10, 20.0), (11, 420.0), (12, 300.0)] {
            frames.push(candidate(k * 5, board(u, 20.0 + k as f64 * 10.0, 25.0)));
        }
        let v = choose(&frames, 9, 640, 480, 10);
        let kept: Vec<usize> = (0..frames.len())
            .filter(|&i| v[i] == Verdict::Kept)
            .collect();
        assert_eq!(kept.iter().filter(|&&i| i < 10).count(), 1, "{v:?}");
        assert!(
            kept.contains(&10) && kept.contains(&11) && kept.contains(&12),
            "{v:?}"
        );
        assert!(v.iter().any(|x| matches!(x, Verdict::Similar(_))));
        let two = choose(&frames, 9, 640, 480, 2);
        assert_eq!(two.iter().filter(|x| **x == Verdict::Kept).count(), 2);
    }
}
