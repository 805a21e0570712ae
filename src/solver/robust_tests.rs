//! Unit tests of outlier rejection: local deviations against a map-based
//! reference, and rejection on synthetic data with known outliers.
use super::*;
use crate::model::camera::CameraSpec;
use crate::model::target::Target;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use std::collections::HashMap;

/// The deviations computed again with a map and the predictions written out
/// one by one, as the reference of the dense computation.
fn local_deviations_by_map(dataset: &Dataset, residuals: &[f64]) -> Vec<f64> {
    let (rows, cols) = (dataset.target.rows as isize, dataset.target.cols as isize);
    let index: HashMap<(usize, usize, usize), usize> = dataset
        .observations
        .iter()
        .enumerate()
        .map(|(i, o)| ((o.camera, o.frame, o.corner), i))
        .collect();
    let deviation = |i: usize, o: &Observation| {
        let (row, col) = ((o.corner as isize) / cols, (o.corner as isize) % cols);
        // The residual at an offset, with its weights keyed by offset.
        let at = |dr: isize, dc: isize| -> Option<Vector2<f64>> {
            let (r, c) = (row + dr, col + dc);
            if r < 0 || c < 0 || r >= rows || c >= cols {
                return None;
            }
            index
                .get(&(o.camera, o.frame, (r * cols + c) as usize))
                .map(|&j| Vector2::new(residuals[2 * j], residuals[2 * j + 1]))
        };
        type Weights = Vec<((isize, isize), f64)>;
        let steps = [(0, -1), (0, 1), (-1, 0), (1, 0)];
        let adjacent: Vec<(Vector2<f64>, Weights)> = steps
            .iter()
            .filter_map(|&(dr, dc)| at(dr, dc).map(|a| (a, vec![((dr, dc), 1.0)])))
            .collect();
        let mut predictions = Vec::new();
        if adjacent.len() == 4 {
            predictions = adjacent;
        } else {
            for (dr, dc) in [(0, 1), (1, 0)] {
                if let (Some(a), Some(b)) = (at(-dr, -dc), at(dr, dc)) {
                    predictions.push(((a + b) / 2.0, vec![((-dr, -dc), 0.5), ((dr, dc), 0.5)]));
                }
            }
            for (dr, dc) in steps {
                if let (Some(a), Some(b)) = (at(dr, dc), at(2 * dr, 2 * dc)) {
                    predictions
                        .push((2.0 * a - b, vec![((dr, dc), 2.0), ((2 * dr, 2 * dc), -1.0)]));
                }
            }
            if predictions.is_empty() {
                predictions = adjacent;
            }
        }
        let r = Vector2::new(residuals[2 * i], residuals[2 * i + 1]);
        if predictions.is_empty() {
            return r[0].abs().max(r[1].abs());
        }
        let mut mean: HashMap<(isize, isize), f64> = HashMap::new();
        for (_, w) in &predictions {
            for &(k, x) in w {
                *mean.entry(k).or_default() += x / predictions.len() as f64;
            }
        }
        let noise = (1.0 + mean.values().map(|x| x * x).sum::<f64>()).sqrt();
        let mut us: Vec<f64> = predictions.iter().map(|p| p.0[0]).collect();
        let mut vs: Vec<f64> = predictions.iter().map(|p| p.0[1]).collect();
        (r[0] - median(&mut us))
            .abs()
            .max((r[1] - median(&mut vs)).abs())
            / noise
    };
    dataset
        .observations
        .iter()
        .enumerate()
        .map(|(i, o)| deviation(i, o))
        .collect()
}

/// A steep residual field, linear over the board (a model error), with noise,
/// gaps and a partial view: rejection takes the gross outliers planted on a
/// board corner, an edge and next to a gap, and nothing else, in one round
/// and after it. A median of neighbours on the edges took corners there by
/// the field's slope, round after round.
#[test]
fn a_linear_model_error_is_not_rejected_and_outliers_on_the_edges_are() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let target = Target {
        rows: 7,
        cols: 9,
        spacing: 0.05,
    };
    let cameras = vec![CameraSpec::new("a", 640, 480, Default::default())];
    let mut rows = Vec::new();
    for frame in 0..12 {
        for corner in 0..63 {
            // Frame 1 sees the board's left part only; frame 2 misses a corner.
            if (frame == 1 && corner % 9 > 5) || (frame == 2 && corner == 31) {
                continue;
            }
            rows.push((0, frame, corner, [0.0, 0.0]));
        }
    }
    let d = Dataset::from_keyed(target, cameras, rows);
    let slope: Vec<[f64; 6]> = (0..12)
        .map(|_| std::array::from_fn(|_| rng.gen_range(-1.5..1.5)))
        .collect();
    let noise = rand_distr::Normal::new(0.0, 0.1).unwrap();
    let mut residuals = Vec::new();
    for o in &d.observations {
        let (row, col) = ((o.corner / 9) as f64, (o.corner % 9) as f64);
        let s = &slope[o.frame];
        residuals.push(s[0] + s[1] * row + s[2] * col + rng.sample(noise));
        residuals.push(s[3] + s[4] * row + s[5] * col + rng.sample(noise));
    }
    let planted = [(0, 0), (3, 4), (1, 5), (2, 30), (2, 62)];
    let mut expected = Vec::new();
    for (i, o) in d.observations.iter().enumerate() {
        if planted.contains(&(o.frame, o.corner)) {
            residuals[2 * i] += 2.5;
            residuals[2 * i + 1] -= 1.5;
            expected.push(i);
        }
    }
    assert_eq!(expected.len(), planted.len());
    assert_eq!(pick_outliers(&d, &residuals, 4.0), expected);
    let mut kept = d.clone();
    let mut r = Vec::new();
    kept.observations.clear();
    for (i, o) in d.observations.iter().enumerate() {
        if !expected.contains(&i) {
            kept.observations.push(*o);
            r.extend_from_slice(&residuals[2 * i..2 * i + 2]);
        }
    }
    assert_eq!(pick_outliers(&kept, &r, 4.0), Vec::<usize>::new());
}

#[test]
fn local_deviations_equal_the_map_based_ones() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let target = Target {
        rows: 6,
        cols: 7,
        spacing: 0.05,
    };
    let cameras = vec![
        CameraSpec::new("a", 640, 480, Default::default()),
        CameraSpec::new("b", 640, 480, Default::default()),
    ];
    // Corners missing, rows in no order, corners observed twice in a view.
    let mut rows = Vec::new();
    for camera in 0..2 {
        for frame in 0..6 {
            for corner in 0..42 {
                if rng.gen_bool(0.8) {
                    rows.push((camera, frame, corner, [0.0, 0.0]));
                }
            }
        }
    }
    for _ in 0..12 {
        let dup = rows[rng.gen_range(0..rows.len())];
        rows.push(dup);
    }
    rows.shuffle(&mut rng);
    let d = Dataset::from_keyed(target, cameras, rows);
    let residuals: Vec<f64> = (0..2 * d.observations.len())
        .map(|_| rng.gen_range(-2.0..2.0))
        .collect();
    let dense = local_deviations(&d, &residuals);
    assert_eq!(dense.len(), d.observations.len());
    for (a, b) in dense.iter().zip(local_deviations_by_map(&d, &residuals)) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
    }
}
