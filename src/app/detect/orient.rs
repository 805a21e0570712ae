//! From the detector's grid labels to board indices (row·cols + col).
//!
//! calib-targets labels corners with an arbitrary integer grid (u, v): it does
//! not know the board's size, its orientation, nor — for a partial view —
//! which part of the board it saw. We enumerate every placement of the
//! labelled patch on the rows×cols board (8 axis symmetries × translations)
//! and keep those consistent with what the image shows:
//!
//! 1. Handedness: the board is seen from its printed side, so board x × board
//!    y must have the same sense as image u × v (x right ⇒ y down). This
//!    removes mirror labellings.
//! 2. Square colour: the board cell between corners (r,c) and (r+1,c+1) is
//!    dark iff r+c is even, i.e. the outer square diagonally beyond corner 0
//!    is dark. This breaks the 180° symmetry when rows+cols is odd (the usual
//!    "odd × even squares" advice) and 90° on odd square boards.
//! 3. Board edges: one step beyond each side of the labelled patch we look at
//!    the image. A row of non-junctions with a uniform region outside proves
//!    the board ends there; a row of X-junctions proves it continues (the
//!    detector merely missed them). A placement must agree with both.
//!
//! If one placement survives, it is the answer. If several survive and the
//! patch spans the whole board, they differ only by a symmetry the colours
//! cannot break (e.g. 180° on an odd×odd-squares board); we then pick,
//! deterministically, the placement whose board x axis points most to the
//! right in the image (so corner 0 is towards the top-left, as OpenCV and
//! mrgingham tend to report). A partial view whose two surviving placements
//! are the board turned by 180° is kept the same way: the board looks alike
//! both ways, the pose absorbs the choice, and the intrinsics do not depend on
//! it. Any other ambiguity (where on the board a patch sits) is rejected.

use crate::app::detect::refine::FloatImage;
use std::collections::HashMap;

/// A labelled, refined corner from the detector, before indexing.
#[derive(Clone, Copy, Debug)]
pub struct Labelled {
    /// Grid label along the detector's first axis.
    pub u: i32,
    /// Grid label along the detector's second axis.
    pub v: i32,
    /// Pixel position.
    pub uv: [f64; 2],
    /// Refinement uncertainty, carried through untouched.
    pub sigma: f64,
}

/// Why no unique placement exists.
#[derive(Debug, PartialEq, Eq)]
pub enum OrientError {
    /// No placement fits (the patch is larger than the board, or contradicts it).
    NoFit,
    /// Several placements fit a partial view.
    Ambiguous,
}

/// Board placement: (c, r) = A·(u, v) + t with A a signed permutation.
#[derive(Clone, Copy, Debug)]
struct Placement {
    swap: bool,
    su: i32,
    sv: i32,
    tc: i32,
    tr: i32,
}

impl Placement {
    fn map(&self, u: i32, v: i32) -> (i32, i32) {
        let (a, b) = if self.swap { (v, u) } else { (u, v) };
        (self.su * a + self.tc, self.sv * b + self.tr)
    }

    fn det(&self) -> i32 {
        self.su * self.sv * if self.swap { -1 } else { 1 }
    }
}

/// Evidence about what lies one step beyond a side of the labelled patch.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    Edge,
    Continues,
    Unknown,
}

/// The board indices of a view.
#[derive(Debug)]
pub struct Indexed {
    /// (board index, corner) pairs; corners trimmed as strays are left out.
    pub corners: Vec<(usize, Labelled)>,
    /// The board looks alike turned by 180° (or 90°) and the labelling was
    /// chosen by the image's orientation rule, not read from the board.
    pub by_symmetry: bool,
}

/// Assign board indices.
pub fn assign_indices(
    corners: &[Labelled],
    img: &FloatImage,
    rows: usize,
    cols: usize,
) -> Result<Indexed, OrientError> {
    let kept = trim_to_board(corners, rows as i32, cols as i32)?;
    let corners = kept.as_slice();
    let grid = Grid::new(corners);
    let (eu, ev) = grid.axes();
    let hand = (eu[0] * ev[1] - eu[1] * ev[0]).signum() as i32;
    let colour = grid.cell00_dark(img);
    let sides = grid.side_evidence(img, eu, ev);
    let (rows, cols) = (rows as i32, cols as i32);
    let fits: Vec<Placement> = placements(grid.nu, grid.nv, rows, cols)
        .filter(|p| p.det() * hand > 0)
        .filter(|p| colour.is_none_or(|dark| board_cell_dark(p) == dark))
        .filter(|p| sides_agree(p, &grid, &sides, rows, cols))
        .collect();
    let (chosen, by_symmetry) = match fits.as_slice() {
        [] => return Err(OrientError::NoFit),
        [one] => (*one, false),
        many if grid.nu * grid.nv == rows * cols => (most_rightward(many, eu, ev), true),
        [a, b] if turned_180(a, b, rows, cols) => (most_rightward(&[*a, *b], eu, ev), true),
        _ => return Err(OrientError::Ambiguous),
    };
    let corners = corners
        .iter()
        .map(|c| {
            let (col, row) = chosen.map(c.u - grid.u0, c.v - grid.v0);
            ((row * cols + col) as usize, *c)
        })
        .collect();
    Ok(Indexed {
        corners,
        by_symmetry,
    })
}

/// Whether placement `b` is placement `a` followed by turning the board by
/// 180° (board corner (c, r) to (cols−1−c, rows−1−r)). Placements are affine,
/// so three patch points decide it.
fn turned_180(a: &Placement, b: &Placement, rows: i32, cols: i32) -> bool {
    [(0, 0), (1, 0), (0, 1)].iter().all(|&(u, v)| {
        let (c, r) = a.map(u, v);
        b.map(u, v) == (cols - 1 - c, rows - 1 - r)
    })
}

/// The detector sometimes labels a stray X-junction just outside the board
/// (background clutter in line with a grid row). When the patch is larger
/// than the board, keep the board-sized window holding the most corners,
/// provided the window is unique and drops at most a handful of corners;
/// otherwise the patch is not this board.
fn trim_to_board(corners: &[Labelled], rows: i32, cols: i32) -> Result<Vec<Labelled>, OrientError> {
    let g = Grid::new(corners);
    let fits = |a: i32, b: i32| g.nu <= a && g.nv <= b;
    if fits(cols, rows) || fits(rows, cols) {
        return Ok(corners.to_vec());
    }
    let mut best: Option<(usize, (i32, i32, i32, i32))> = None;
    let mut tie = false;
    for (wu, wv) in [(cols, rows), (rows, cols)] {
        for u0 in 0..=(g.nu - wu).max(0) {
            for v0 in 0..=(g.nv - wv).max(0) {
                let inside = |c: &&Labelled| {
                    let (u, v) = (c.u - g.u0, c.v - g.v0);
                    u >= u0 && u < u0 + wu && v >= v0 && v < v0 + wv
                };
                let n = corners.iter().filter(inside).count();
                match best {
                    Some((bn, _)) if n < bn => {}
                    Some((bn, _)) if n == bn => tie = true,
                    _ => {
                        best = Some((n, (u0, v0, wu, wv)));
                        tie = false;
                    }
                }
            }
        }
    }
    let Some((n, (u0, v0, wu, wv))) = best else {
        return Err(OrientError::NoFit);
    };
    if tie || corners.len() - n > 3 {
        return Err(OrientError::NoFit);
    }
    Ok(corners
        .iter()
        .filter(|c| {
            let (u, v) = (c.u - g.u0, c.v - g.v0);
            u >= u0 && u < u0 + wu && v >= v0 && v < v0 + wv
        })
        .copied()
        .collect())
}

/// All placements of an nu×nv patch inside a cols×rows board.
fn placements(nu: i32, nv: i32, rows: i32, cols: i32) -> impl Iterator<Item = Placement> {
    let mut out = Vec::new();
    for swap in [false, true] {
        let (na, nb) = if swap { (nv, nu) } else { (nu, nv) };
        for su in [1, -1] {
            for sv in [1, -1] {
                // For s = 1, t ∈ [0, n_board − n]; for s = −1, t ∈ [n − 1, n_board − 1].
                let tcs = if su > 0 {
                    0..=cols - na
                } else {
                    na - 1..=cols - 1
                };
                for tc in tcs {
                    let trs = if sv > 0 {
                        0..=rows - nb
                    } else {
                        nb - 1..=rows - 1
                    };
                    for tr in trs {
                        out.push(Placement {
                            swap,
                            su,
                            sv,
                            tc,
                            tr,
                        });
                    }
                }
            }
        }
    }
    out.into_iter()
}

/// Is the board cell that patch cell (0,0) lands on dark? (r+c even ⇒ dark.)
fn board_cell_dark(p: &Placement) -> bool {
    let (c0, r0) = p.map(0, 0);
    let (c1, r1) = p.map(1, 1);
    (c0.min(c1) + r0.min(r1)).rem_euclid(2) == 0
}

fn sides_agree(p: &Placement, g: &Grid, sides: &[Side; 4], rows: i32, cols: i32) -> bool {
    // A probe point just outside each side: (−1, 0), (nu, 0), (0, −1), (0, nv).
    let probes = [(-1, 0), (g.nu, 0), (0, -1), (0, g.nv)];
    probes.iter().zip(sides).all(|(&(u, v), side)| {
        let (c, r) = p.map(u, v);
        let outside = c < 0 || r < 0 || c >= cols || r >= rows;
        match side {
            Side::Edge => outside,
            Side::Continues => !outside,
            Side::Unknown => true,
        }
    })
}

/// Deterministic tie-break among whole-board symmetries: the placement whose
/// board +x direction has the largest image-u component.
fn most_rightward(fits: &[Placement], eu: [f64; 2], ev: [f64; 2]) -> Placement {
    let score = |p: &Placement| {
        // Board +x expressed in patch coordinates, then in image pixels.
        let (c0, _) = p.map(0, 0);
        let (cu, _) = p.map(1, 0);
        let (cv, _) = p.map(0, 1);
        let (du, dv) = ((cu - c0) as f64, (cv - c0) as f64);
        let x = [du * eu[0] + dv * ev[0], du * eu[1] + dv * ev[1]];
        x[0] / (x[0].hypot(x[1]) + 1e-12)
    };
    *fits
        .iter()
        .max_by(|a, b| score(a).total_cmp(&score(b)))
        .expect("caller passes a non-empty slice")
}

/// Labelled patch rebased to (0,0), with lookup by label.
struct Grid {
    u0: i32,
    v0: i32,
    nu: i32,
    nv: i32,
    at: HashMap<(i32, i32), [f64; 2]>,
}

impl Grid {
    fn new(corners: &[Labelled]) -> Self {
        let u0 = corners.iter().map(|c| c.u).min().unwrap_or(0);
        let v0 = corners.iter().map(|c| c.v).min().unwrap_or(0);
        let nu = corners.iter().map(|c| c.u - u0 + 1).max().unwrap_or(0);
        let nv = corners.iter().map(|c| c.v - v0 + 1).max().unwrap_or(0);
        let at = corners
            .iter()
            .map(|c| ((c.u - u0, c.v - v0), c.uv))
            .collect();
        Grid { u0, v0, nu, nv, at }
    }

    fn get(&self, u: i32, v: i32) -> Option<[f64; 2]> {
        self.at.get(&(u, v)).copied()
    }

    /// Mean image step along +u and +v between labelled neighbours.
    fn axes(&self) -> ([f64; 2], [f64; 2]) {
        let mut acc = [[0.0f64; 2]; 2];
        let mut n = [0.0f64; 2];
        for (&(u, v), p) in &self.at {
            for (k, (du, dv)) in [(1, 0), (0, 1)].into_iter().enumerate() {
                if let Some(q) = self.get(u + du, v + dv) {
                    acc[k][0] += q[0] - p[0];
                    acc[k][1] += q[1] - p[1];
                    n[k] += 1.0;
                }
            }
        }
        let f = |k: usize| [acc[k][0] / n[k].max(1.0), acc[k][1] / n[k].max(1.0)];
        (f(0), f(1))
    }

    /// Centres and brightness of every patch cell whose four corners are known.
    fn cells(&self, img: &FloatImage) -> Vec<((i32, i32), f64)> {
        let mut out = Vec::new();
        for &(u, v) in self.at.keys() {
            let quad =
                [(u, v), (u + 1, v), (u, v + 1), (u + 1, v + 1)].map(|(a, b)| self.get(a, b));
            if let [Some(a), Some(b), Some(c), Some(d)] = quad {
                let cx = (a[0] + b[0] + c[0] + d[0]) / 4.0;
                let cy = (a[1] + b[1] + c[1] + d[1]) / 4.0;
                let size = ((d[0] - a[0]).hypot(d[1] - a[1])) / 1.414;
                out.push(((u, v), img.patch_mean(cx, cy, 0.15 * size)));
            }
        }
        out
    }

    /// Whether patch cell (0,0) is dark, by majority vote over all cells'
    /// colours (cell (u,v) has the colour of (0,0) iff u+v is even). None
    /// when the vote is not clear.
    fn cell00_dark(&self, img: &FloatImage) -> Option<bool> {
        let cells = self.cells(img);
        let (lo, hi) = contrast_levels(&cells)?;
        let mid = 0.5 * (lo + hi);
        let votes = cells
            .iter()
            .filter(|((u, v), b)| (*b < mid) == ((u + v).rem_euclid(2) == 0))
            .count();
        let frac = votes as f64 / cells.len() as f64;
        if frac > 0.8 {
            Some(true)
        } else if frac < 0.2 {
            Some(false)
        } else {
            None
        }
    }

    /// Evidence beyond the sides −u, +u, −v, +v (same order as the probes
    /// in `sides_agree`).
    fn side_evidence(&self, img: &FloatImage, eu: [f64; 2], ev: [f64; 2]) -> [Side; 4] {
        let Some((lo, hi)) = contrast_levels(&self.cells(img)) else {
            return [Side::Unknown; 4];
        };
        let contrast = hi - lo;
        let probe = |out: (i32, i32), along: (i32, i32), line: i32| -> Side {
            let mut tally = [0usize; 3];
            for k in -1..=self.nu.max(self.nv) {
                let (u, v) = if out.0 != 0 { (line, k) } else { (k, line) };
                if let Some(c) = self.classify(img, (u, v), out, along, contrast, eu, ev) {
                    tally[c as usize] += 1;
                }
            }
            summarise(tally)
        };
        [
            probe((-1, 0), (0, 1), 0),
            probe((1, 0), (0, 1), self.nu - 1),
            probe((0, -1), (1, 0), 0),
            probe((0, 1), (1, 0), self.nv - 1),
        ]
    }

    /// Look one step beyond boundary corner `at` in direction `out`.
    #[allow(clippy::too_many_arguments)]
    fn classify(
        &self,
        img: &FloatImage,
        at: (i32, i32),
        out: (i32, i32),
        along: (i32, i32),
        contrast: f64,
        eu: [f64; 2],
        ev: [f64; 2],
    ) -> Option<Side> {
        let p1 = self.get(at.0, at.1)?;
        let p0 = self.get(at.0 - out.0, at.1 - out.1)?;
        let p = [2.0 * p1[0] - p0[0], 2.0 * p1[1] - p0[1]];
        let o = [p1[0] - p0[0], p1[1] - p0[1]];
        let a = if along.0 != 0 { eu } else { ev };
        let r = 0.1 * o[0].hypot(o[1]);
        let pt = |so: f64, sa: f64| {
            [
                p[0] + 0.3 * (so * o[0] + sa * a[0]),
                p[1] + 0.3 * (so * o[1] + sa * a[1]),
            ]
        };
        let pts = [pt(-1.0, -1.0), pt(-1.0, 1.0), pt(1.0, -1.0), pt(1.0, 1.0)];
        let (w, h) = (img.width as f64, img.height as f64);
        let inside = |q: &[f64; 2]| {
            q[0] > r + 1.0 && q[1] > r + 1.0 && q[0] < w - r - 2.0 && q[1] < h - r - 2.0
        };
        if !pts.iter().all(inside) {
            return None;
        }
        let [in_a, in_b, out_a, out_b] = pts.map(|q| img.patch_mean(q[0], q[1], r));
        let junction = (in_a - out_b).abs() < 0.35 * contrast
            && (in_b - out_a).abs() < 0.35 * contrast
            && (in_a - in_b).abs() > 0.5 * contrast;
        let edge = (in_a - in_b).abs() > 0.5 * contrast && (out_a - out_b).abs() < 0.25 * contrast;
        Some(if junction {
            Side::Continues
        } else if edge {
            Side::Edge
        } else {
            Side::Unknown
        })
    }
}

/// Turn per-point votes [edge, continues, unknown] into one verdict; a side is
/// only called when the votes are clear, since a wrong call mis-indexes.
fn summarise(tally: [usize; 3]) -> Side {
    let total: usize = tally.iter().sum();
    let [edge, cont, _] = tally;
    if total > 0 && cont == 0 && edge * 5 >= total * 3 {
        Side::Edge
    } else if total > 0 && edge == 0 && cont * 5 >= total * 3 {
        Side::Continues
    } else {
        Side::Unknown
    }
}

/// Dark and light levels: means of the lower and upper halves of the cell
/// brightnesses. None when there are too few cells to tell.
fn contrast_levels(cells: &[((i32, i32), f64)]) -> Option<(f64, f64)> {
    if cells.len() < 2 {
        return None;
    }
    let mut b: Vec<f64> = cells.iter().map(|c| c.1).collect();
    b.sort_by(f64::total_cmp);
    let half = b.len() / 2;
    let lo = b[..half].iter().sum::<f64>() / half as f64;
    let hi = b[half..].iter().sum::<f64>() / (b.len() - half) as f64;
    (hi - lo > 10.0).then_some((lo, hi))
}
