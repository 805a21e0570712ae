//! Growing the labelled grid outward to the corners the grid finder missed.
//!
//! calib-targets labels the core of the board well but gives up where squares
//! are strongly compressed: near the rim of a fisheye's image circle, or on a
//! board seen at a grazing angle. Those are exactly the corners that pin a
//! fisheye's distortion. Distortion is smooth, so along a grid row or column
//! the next corner is well predicted from the last three (quadratic
//! extrapolation, which follows the steady shrinking of the squares; linear
//! from two where only two are known). Each prediction is refined with a
//! window sized to the local spacing and kept only if it is a clean
//! X-junction whose square colours continue the board's checker pattern, so
//! growth stops by itself at the board's edge, at the image circle and at
//! clutter. Works on the detector's own (u, v) labels, before the board
//! indices are assigned (`orient`), and never grows the patch beyond what the
//! rows×cols board can hold.

use crate::app::detect::orient::Labelled;
use crate::app::detect::refine::{self, FloatImage};
use std::collections::HashMap;

/// Largest point-symmetry misfit of a grown corner (as for the found ones).
const MAX_ASYMMETRY: f64 = 0.05;
/// Refinement half-window as a fraction of the local corner spacing: the
/// window stays inside the four squares around the corner, however small.
pub const WINDOW_FRACTION: f64 = 0.4;
/// Reach of the window shaped by the local grid, in cells along each grid
/// vector: on the rendered fisheye views' grown corners 0.3 gave 0.063 px RMS
/// to the truth, 0.4 gave 0.073 and 0.25 0.063 (kb4; ds 0.068, 0.079, 0.071),
/// every corner found with each.
const AFFINE_FRACTION: f64 = 0.3;
/// Smallest and largest refinement half-windows (px).
pub const MIN_HALF: usize = 2;
/// See [`MIN_HALF`].
pub const MAX_HALF: usize = 12;
/// Fewest pixels between corners worth refining: below this the junction is
/// a blur of a few pixels and its position is not trustworthy.
const MIN_SPACING: f64 = 4.0;

/// The four grid directions.
const DIRS: [(i32, i32); 4] = [(1, 0), (-1, 0), (0, 1), (0, -1)];

/// The refinement half-window for a corner with local spacing `spacing` (px).
pub fn half_window(spacing: f64) -> usize {
    ((WINDOW_FRACTION * spacing).round() as usize).clamp(MIN_HALF, MAX_HALF)
}

/// Smallest distance (px) from the corner at `at` to a labelled 4-neighbour;
/// None for an isolated corner.
pub fn local_spacing(at: (i32, i32), grid: &HashMap<(i32, i32), [f64; 2]>) -> Option<f64> {
    let p = grid.get(&at)?;
    DIRS.iter()
        .filter_map(|(du, dv)| grid.get(&(at.0 + du, at.1 + dv)))
        .map(|q| (q[0] - p[0]).hypot(q[1] - p[1]))
        .min_by(f64::total_cmp)
}

/// Add every corner reachable by extrapolation along rows and columns from
/// `corners`. Grown corners carry their refinement σ like found ones.
pub fn grow(img: &FloatImage, corners: Vec<Labelled>, rows: usize, cols: usize) -> Vec<Labelled> {
    let mut grid: HashMap<(i32, i32), Labelled> =
        corners.into_iter().map(|c| ((c.u, c.v), c)).collect();
    let Some(parity) = dark_parity(img, &grid) else {
        return grid.into_values().collect();
    };
    let (long, short) = (rows.max(cols) as i32, rows.min(cols) as i32);
    // Each round tries the whole frontier again: a cell that failed with a
    // linear prediction may succeed once a neighbour gives a quadratic one.
    loop {
        let added: Vec<Labelled> = frontier(&grid)
            .into_iter()
            .filter(|&at| fits_board(&grid, at, long, short))
            .filter_map(|at| try_corner(img, &grid, at, parity))
            .collect();
        let mut inserted = 0;
        for c in added {
            // Two frontier cells may have refined onto the same junction, or
            // together stretch the patch beyond the board.
            let dup = grid
                .values()
                .any(|o| (o.uv[0] - c.uv[0]).hypot(o.uv[1] - c.uv[1]) < 1.5);
            if !dup && fits_board(&grid, (c.u, c.v), long, short) {
                grid.insert((c.u, c.v), c);
                inserted += 1;
            }
        }
        if inserted == 0 {
            break;
        }
    }
    grid.into_values().collect()
}

/// Empty cells next to a labelled corner, in a fixed order (growth is
/// deterministic).
fn frontier(grid: &HashMap<(i32, i32), Labelled>) -> Vec<(i32, i32)> {
    let mut out: Vec<(i32, i32)> = grid
        .keys()
        .flat_map(|&(u, v)| DIRS.iter().map(move |(du, dv)| (u + du, v + dv)))
        .filter(|k| !grid.contains_key(k))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// Whether adding `at` keeps the labelled patch small enough for the board in
/// some orientation.
fn fits_board(grid: &HashMap<(i32, i32), Labelled>, at: (i32, i32), long: i32, short: i32) -> bool {
    let (mut u0, mut u1, mut v0, mut v1) = (at.0, at.0, at.1, at.1);
    for &(u, v) in grid.keys() {
        (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
    }
    let (nu, nv) = (u1 - u0 + 1, v1 - v0 + 1);
    nu.max(nv) <= long && nu.min(nv) <= short
}

/// Predict, refine and check the corner at grid cell `at`.
fn try_corner(
    img: &FloatImage,
    grid: &HashMap<(i32, i32), Labelled>,
    at: (i32, i32),
    parity: i32,
) -> Option<Labelled> {
    let pos = |u: i32, v: i32| grid.get(&(u, v)).map(|c| c.uv);
    let mut preds: Vec<([f64; 2], f64)> = Vec::new();
    for (du, dv) in DIRS {
        // Walk back from `at` against the direction of growth.
        let (Some(p1), Some(p2)) = (pos(at.0 - du, at.1 - dv), pos(at.0 - 2 * du, at.1 - 2 * dv))
        else {
            continue;
        };
        let pred = match pos(at.0 - 3 * du, at.1 - 3 * dv) {
            Some(p3) => [
                3.0 * p1[0] - 3.0 * p2[0] + p3[0],
                3.0 * p1[1] - 3.0 * p2[1] + p3[1],
            ],
            None => [2.0 * p1[0] - p2[0], 2.0 * p1[1] - p2[1]],
        };
        // The predicted step, not the last one: squares keep shrinking.
        let step = (pred[0] - p1[0]).hypot(pred[1] - p1[1]);
        preds.push((pred, step));
    }
    if preds.is_empty() {
        return None;
    }
    let n = preds.len() as f64;
    let pred = [
        preds.iter().map(|p| p.0[0]).sum::<f64>() / n,
        preds.iter().map(|p| p.0[1]).sum::<f64>() / n,
    ];
    // The spacing to the other known neighbours bounds the window too.
    let spacing = DIRS
        .iter()
        .filter_map(|(du, dv)| {
            let q = pos(at.0 + du, at.1 + dv)?;
            Some((q[0] - pred[0]).hypot(q[1] - pred[1]))
        })
        .chain(preds.iter().map(|p| p.1))
        .fold(f64::INFINITY, f64::min);
    if spacing.is_nan() || spacing < MIN_SPACING {
        return None;
    }
    let inside = |q: [f64; 2]| {
        let m = 0.5 * spacing;
        q[0] >= m
            && q[1] >= m
            && q[0] <= img.width as f64 - 1.0 - m
            && q[1] <= img.height as f64 - 1.0 - m
    };
    if !inside(pred) {
        return None;
    }
    // The window follows the local grid: on the sheared squares near the rim
    // a square window sized to the shortest spacing still reaches the
    // junctions along the short diagonal, and the corner fails its checks.
    let r = match frame_at(grid, at, pred) {
        Some(axes) => refine::refine_affine(img, pred, axes, AFFINE_FRACTION)?,
        None => refine::refine_corner(img, pred, half_window(spacing))?,
    };
    let moved = (r.uv[0] - pred[0]).hypot(r.uv[1] - pred[1]);
    if r.asymmetry > MAX_ASYMMETRY || moved > 0.3 * spacing || !inside(r.uv) {
        return None;
    }
    let cand = Labelled {
        u: at.0,
        v: at.1,
        uv: r.uv,
        sigma: r.sigma,
    };
    is_checker_junction(img, grid, &cand, parity, spacing).then_some(cand)
}

/// The grid vectors (+u, +v) at the empty cell `at` whose corner is predicted
/// at `pred`: to its known neighbours, else those of a neighbour along the
/// other axis.
fn frame_at(
    grid: &HashMap<(i32, i32), Labelled>,
    at: (i32, i32),
    pred: [f64; 2],
) -> Option<refine::Axes> {
    let pos = |u: i32, v: i32| grid.get(&(u, v)).map(|c| c.uv);
    let diff = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
    let axis = |du: i32, dv: i32| -> Option<[f64; 2]> {
        if let Some(q) = pos(at.0 + du, at.1 + dv) {
            return Some(diff(q, pred));
        }
        if let Some(q) = pos(at.0 - du, at.1 - dv) {
            return Some(diff(pred, q));
        }
        [1, -1].iter().find_map(|s| {
            let n = (at.0 + s * dv, at.1 + s * du);
            let c = pos(n.0, n.1)?;
            pos(n.0 + du, n.1 + dv)
                .map(|q| diff(q, c))
                .or_else(|| pos(n.0 - du, n.1 - dv).map(|q| diff(c, q)))
        })
    };
    Some([axis(1, 0)?, axis(0, 1)?])
}

/// The image direction of +u and +v at a grid cell, from its nearest known
/// neighbours along each axis.
fn local_axes(grid: &HashMap<(i32, i32), Labelled>, c: &Labelled) -> Option<([f64; 2], [f64; 2])> {
    let axis = |du: i32, dv: i32| -> Option<[f64; 2]> {
        for s in [1, -1] {
            if let Some(q) = grid.get(&(c.u + s * du, c.v + s * dv)) {
                let f = s as f64;
                return Some([f * (q.uv[0] - c.uv[0]), f * (q.uv[1] - c.uv[1])]);
            }
        }
        None
    };
    let eu = axis(1, 0);
    let ev = axis(0, 1);
    match (eu, ev) {
        (Some(a), Some(b)) => Some((a, b)),
        // One axis only (a corner grown off the end of a row): the other is
        // that axis turned by the patch's handedness, good enough to sample
        // the four squares.
        (Some(a), None) => Some((a, turn(a, handedness(grid)?))),
        (None, Some(b)) => Some((turn(b, -handedness(grid)?), b)),
        (None, None) => None,
    }
}

fn turn(a: [f64; 2], hand: f64) -> [f64; 2] {
    [-hand * a[1], hand * a[0]]
}

/// The sign of u × v in the image over the labelled patch.
fn handedness(grid: &HashMap<(i32, i32), Labelled>) -> Option<f64> {
    let mut cross = 0.0;
    for c in grid.values() {
        let (Some(a), Some(b)) = (grid.get(&(c.u + 1, c.v)), grid.get(&(c.u, c.v + 1))) else {
            continue;
        };
        let eu = [a.uv[0] - c.uv[0], a.uv[1] - c.uv[1]];
        let ev = [b.uv[0] - c.uv[0], b.uv[1] - c.uv[1]];
        cross += (eu[0] * ev[1] - eu[1] * ev[0]).signum();
    }
    (cross != 0.0).then_some(cross.signum())
}

/// Mean brightness of the four squares around a corner, in the order
/// (+u+v, −u+v, −u−v, +u−v), sampled a third of the way into each square.
fn quadrants(img: &FloatImage, c: &Labelled, eu: [f64; 2], ev: [f64; 2], spacing: f64) -> [f64; 4] {
    let s = |a: f64, b: f64| {
        let n = |v: [f64; 2]| v[0].hypot(v[1]).max(1e-9);
        let (nu, nv) = (n(eu), n(ev));
        let d = [
            a * eu[0] / nu + b * ev[0] / nv,
            a * eu[1] / nu + b * ev[1] / nv,
        ];
        let k = 0.3 * spacing;
        img.patch_mean(c.uv[0] + k * d[0], c.uv[1] + k * d[1], 0.08 * spacing)
    };
    [s(1.0, 1.0), s(-1.0, 1.0), s(-1.0, -1.0), s(1.0, -1.0)]
}

/// The corner is an X-junction of this board: diagonally opposite squares
/// alike, neighbouring ones clearly different, and the square towards +u+v
/// (patch cell (u, v)) dark exactly when u + v has the board's dark parity.
fn is_checker_junction(
    img: &FloatImage,
    grid: &HashMap<(i32, i32), Labelled>,
    c: &Labelled,
    parity: i32,
    spacing: f64,
) -> bool {
    // The grid's own vectors where known (sheared squares near the rim are far
    // from the right angle `local_axes` falls back to).
    let axes = frame_at(grid, (c.u, c.v), c.uv)
        .map(|[eu, ev]| (eu, ev))
        .or_else(|| local_axes(grid, c));
    let Some((eu, ev)) = axes else {
        return false;
    };
    let [a, b, a2, b2] = quadrants(img, c, eu, ev, spacing);
    let contrast = (a + a2 - b - b2).abs() / 2.0;
    let alike = (a - a2).abs().max((b - b2).abs());
    if contrast < 25.0 || alike > 0.5 * contrast {
        return false;
    }
    let cell_dark = a + a2 < b + b2;
    cell_dark == ((c.u + c.v).rem_euclid(2) == parity)
}

/// Which parity of u + v has a dark square towards +u+v, by majority over the
/// corners with both axes known; None when the vote is not clear.
fn dark_parity(img: &FloatImage, grid: &HashMap<(i32, i32), Labelled>) -> Option<i32> {
    let mut votes = [0usize; 2];
    for c in grid.values() {
        let (Some(a), Some(b)) = (grid.get(&(c.u + 1, c.v)), grid.get(&(c.u, c.v + 1))) else {
            continue;
        };
        let eu = [a.uv[0] - c.uv[0], a.uv[1] - c.uv[1]];
        let ev = [b.uv[0] - c.uv[0], b.uv[1] - c.uv[1]];
        let spacing = eu[0].hypot(eu[1]).min(ev[0].hypot(ev[1]));
        let [q, r, q2, r2] = quadrants(img, c, eu, ev, spacing);
        if (q + q2 - r - r2).abs() < 20.0 {
            continue;
        }
        let dark = q + q2 < r + r2;
        let p = (c.u + c.v).rem_euclid(2);
        votes[if dark { p } else { 1 - p } as usize] += 1;
    }
    let total = votes[0] + votes[1];
    if total < 3 {
        return None;
    }
    if votes[0] * 5 >= total * 4 {
        Some(0)
    } else if votes[1] * 5 >= total * 4 {
        Some(1)
    } else {
        None
    }
}
