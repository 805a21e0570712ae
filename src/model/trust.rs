//! How much of a calibration's residual the detector noise explains (Hagemann et
//! al., IJCV 2022; Kanatani 1998): the noise estimate σ̂, the bias ratio and the
//! geometric AIC. Pure arithmetic on residuals; what a residual is and how many
//! parameters were free is the caller's.
use crate::model::dataset::Dataset;

/// The noise, bias and G-AIC figures of one calibration.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Trust {
    /// σ̂: detector noise per image coordinate, pixels.
    pub noise_px: f64,
    /// Where σ̂ comes from: `"config"` or `"neighbours"`.
    pub noise_source: &'static str,
    /// N: residuals (two per observation).
    pub residuals: usize,
    /// p: free parameters after the gauge.
    pub parameters: usize,
    /// max(0, rmse² − 2σ̂²(1 − p/N)) / rmse²: the share of the residual that noise
    /// does not explain.
    pub bias_ratio: f64,
    /// Σ‖u − p‖² + 2·p·σ̂², pixels²: lower is better, on the same observations.
    pub g_aic: f64,
}

/// Estimates the detector noise from the residuals of neighbouring corners.
///
/// A model error bends the residual field smoothly across the board, so it
/// nearly cancels in the second difference r_{i−1} − 2r_i + r_{i+1} of three
/// adjacent corners (exactly, for an error linear across them), while their
/// noise adds: E‖d‖² = 12σ² for the 2D residuals. So σ̂ comes from the data
/// without assuming the model is right, which is what a bias test needs. Rows
/// and columns of the board both give triples. `None` with no triple.
///
/// The residuals are in pixels; each is scaled by its observation's weight (the
/// corner refinement's σ_ref/σ for photos, 0.5^level for corners.vnl) first, so
/// σ̂ is the noise of a weight-1 corner, the unit that the solver's weighted
/// residuals, and so the covariance, are in.
pub fn noise_from_neighbours(dataset: &Dataset, residuals: &[f64]) -> Option<f64> {
    let d2 = second_differences(dataset, residuals);
    (!d2.is_empty()).then(|| (d2.iter().sum::<f64>() / (12.0 * d2.len() as f64)).sqrt())
}

/// [`noise_from_neighbours`] from the median second difference: for Gaussian
/// noise ‖d‖²/6σ² is χ² with 2 degrees of freedom, median 2 ln 2. A few corners
/// hundreds of pixels off (a fit that put them at a pole of the rational model)
/// leave it where the other corners put it, so it can weight priors.
pub fn noise_from_neighbours_median(dataset: &Dataset, residuals: &[f64]) -> Option<f64> {
    let mut d2 = second_differences(dataset, residuals);
    if d2.is_empty() {
        return None;
    }
    d2.sort_by(f64::total_cmp);
    let median = d2[d2.len() / 2];
    Some((median / (12.0 * std::f64::consts::LN_2)).sqrt())
}

/// ‖r_a − 2r + r_b‖² of every row and column triple of neighbouring corners of
/// one view, on the weighted residuals.
///
/// In the order of the views (camera, frame) and of their corners, each corner's
/// horizontal triple before its vertical one, so that the sum, and every figure
/// scaled by σ̂, is the same in every run. A corner observed twice in one view
/// counts once, with its last observation. Each view's corners go into one dense
/// slot per board corner: no map lookups, as the callers (every trust figure of a
/// result) ask often.
fn second_differences(dataset: &Dataset, residuals: &[f64]) -> Vec<f64> {
    let cols = dataset.target.cols;
    let obs = &dataset.observations;
    let n = obs.len().min(residuals.len() / 2);
    let key = |i: usize| (obs[i].camera, obs[i].frame, obs[i].corner);
    // A stable sort keeps duplicates in input order; the last of each is kept.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| key(i));
    order.dedup_by(|later, earlier| {
        let same = key(*later) == key(*earlier);
        if same {
            *earlier = *later;
        }
        same
    });
    let slots = obs[..n]
        .iter()
        .map(|o| o.corner + 1)
        .max()
        .unwrap_or(0)
        .max(dataset.target.num_corners());
    let mut at: Vec<Option<[f64; 2]>> = vec![None; slots];
    let mut out = Vec::new();
    for view in order.chunk_by(|&a, &b| key(a).0 == key(b).0 && key(a).1 == key(b).1) {
        for &i in view {
            let (o, r) = (&obs[i], &residuals[2 * i..2 * i + 2]);
            at[o.corner] = Some([r[0] * o.weight, r[1] * o.weight]);
        }
        let get = |c: usize| at.get(c).copied().flatten();
        for &i in view {
            let corner = obs[i].corner;
            let r = at[corner].expect("set above");
            let col = corner % cols;
            // The corner as the middle of a horizontal and of a vertical triple.
            let horizontal = (col >= 1 && col + 1 < cols).then(|| (corner - 1, corner + 1));
            let vertical = (corner >= cols).then(|| (corner - cols, corner + cols));
            for (a, b) in [horizontal, vertical].into_iter().flatten() {
                if let (Some(p), Some(q)) = (get(a), get(b)) {
                    out.push(
                        (p[0] - 2.0 * r[0] + q[0]).powi(2) + (p[1] - 2.0 * r[1] + q[1]).powi(2),
                    );
                }
            }
        }
        for &i in view {
            at[obs[i].corner] = None;
        }
    }
    out
}

/// Residuals (u, v per observation, pixels) times their observation's weight:
/// in units of a weight-1 corner's noise, as the solver weighs them.
pub fn weighted(dataset: &Dataset, residuals: &[f64]) -> Vec<f64> {
    dataset
        .observations
        .iter()
        .zip(residuals.chunks_exact(2))
        .flat_map(|(o, r)| [r[0] * o.weight, r[1] * o.weight])
        .collect()
}

/// E[rmse²] = 2σ̂²(1 − p/N) of a model without systematic error: the squared
/// RMSE (per point, pixels²) the noise alone leaves with `parameters` free
/// parameters and `residuals` residuals (two per observation).
pub fn expected_rmse2(noise_px: f64, parameters: usize, residuals: usize) -> f64 {
    2.0 * noise_px * noise_px * (1.0 - parameters as f64 / residuals.max(1) as f64)
}

/// The figures for residuals (u, v per observation) of a fit with `parameters`
/// free parameters and noise σ̂.
pub fn assess(residuals: &[f64], parameters: usize, noise_px: f64, source: &'static str) -> Trust {
    let n = residuals.len();
    let sum_sq: f64 = residuals.iter().map(|r| r * r).sum();
    // rmse per point (docs/conventions.md §3): Σ‖u − p‖² over N/2 points.
    let rmse2 = sum_sq / (n as f64 / 2.0);
    let expected = expected_rmse2(noise_px, parameters, n);
    let bias_ratio = if rmse2 > 0.0 {
        ((rmse2 - expected) / rmse2).max(0.0)
    } else {
        0.0
    };
    Trust {
        noise_px,
        noise_source: source,
        residuals: n,
        parameters,
        bias_ratio,
        g_aic: sum_sq + 2.0 * parameters as f64 * noise_px * noise_px,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::camera::CameraSpec;
    use crate::model::dataset::Observation;
    use crate::model::target::Target;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn board(rows: usize, cols: usize, frames: usize) -> Dataset {
        let target = Target {
            rows,
            cols,
            spacing: 0.05,
        };
        let mut obs = Vec::new();
        for f in 0..frames as i64 {
            for c in 0..rows * cols {
                obs.push((0, f, c, [0.0, 0.0]));
            }
        }
        Dataset::from_keyed(
            target,
            vec![CameraSpec::new("c", 640, 480, Default::default())],
            obs,
        )
    }

    /// A dataset as a file may hold one: two cameras, corners missing, rows in
    /// no order, a corner of a view observed twice, weights other than 1.
    fn messy(seed: u64) -> (Dataset, Vec<f64>) {
        use rand::seq::SliceRandom;
        use rand::Rng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut d = board(6, 7, 5);
        d.cameras
            .push(CameraSpec::new("d", 640, 480, Default::default()));
        let mut obs = Vec::new();
        for camera in 0..2 {
            for o in &d.observations {
                if rng.gen_bool(0.85) {
                    let weight = if rng.gen_bool(0.3) { 0.5 } else { 1.0 };
                    obs.push(Observation {
                        camera,
                        weight,
                        ..*o
                    });
                }
            }
        }
        for _ in 0..10 {
            let dup = obs[rng.gen_range(0..obs.len())];
            obs.push(dup);
        }
        obs.shuffle(&mut rng);
        d.observations = obs;
        let residuals = (0..2 * d.observations.len())
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        (d, residuals)
    }

    /// The map-based computation the dense one replaced, as the reference.
    fn second_differences_by_map(dataset: &Dataset, residuals: &[f64]) -> Vec<f64> {
        let cols = dataset.target.cols;
        let mut at = std::collections::BTreeMap::new();
        for (o, r) in dataset.observations.iter().zip(residuals.chunks_exact(2)) {
            at.insert(
                (o.camera, o.frame, o.corner),
                [r[0] * o.weight, r[1] * o.weight],
            );
        }
        let mut out = Vec::new();
        for (&(camera, frame, corner), r) in &at {
            let col = corner % cols;
            let horizontal = (col >= 1 && col + 1 < cols).then(|| (corner - 1, corner + 1));
            let vertical = (corner >= cols).then(|| (corner - cols, corner + cols));
            for (a, b) in [horizontal, vertical].into_iter().flatten() {
                if let (Some(p), Some(q)) =
                    (at.get(&(camera, frame, a)), at.get(&(camera, frame, b)))
                {
                    out.push(
                        (p[0] - 2.0 * r[0] + q[0]).powi(2) + (p[1] - 2.0 * r[1] + q[1]).powi(2),
                    );
                }
            }
        }
        out
    }

    #[test]
    fn second_differences_equal_the_map_based_ones_in_order() {
        for seed in 0..5 {
            let (d, residuals) = messy(seed);
            let dense = second_differences(&d, &residuals);
            assert!(dense.len() > 100);
            // Bit for bit and in the same order: σ̂ sums them.
            assert_eq!(dense, second_differences_by_map(&d, &residuals));
        }
    }

    #[test]
    fn neighbours_see_the_noise_and_not_a_smooth_error() {
        let d = board(9, 12, 20);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.15).unwrap();
        let residuals: Vec<f64> = d
            .observations
            .iter()
            .flat_map(|o| {
                // A smooth systematic error of up to 2 px across the board.
                let (col, row) = ((o.corner % 12) as f64, (o.corner / 12) as f64);
                let smooth = 2.0 * ((col - 5.5) / 5.5).powi(2) + 0.5 * row / 8.0;
                [
                    smooth + noise.sample(&mut rng),
                    -smooth + noise.sample(&mut rng),
                ]
            })
            .collect();
        let sigma = noise_from_neighbours(&d, &residuals).unwrap();
        assert!((sigma - 0.15).abs() < 0.015, "{sigma}");
        // All of the smooth error is bias.
        let t = assess(&residuals, 10, sigma, "neighbours");
        assert!(t.bias_ratio > 0.9, "{t:?}");
    }

    #[test]
    fn pure_noise_has_no_bias() {
        let d = board(9, 12, 20);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let noise = Normal::new(0.0, 0.2).unwrap();
        let residuals: Vec<f64> = (0..2 * d.observations.len())
            .map(|_| noise.sample(&mut rng))
            .collect();
        let t = assess(&residuals, 0, 0.2, "config");
        assert!(t.bias_ratio < 0.05, "{t:?}");
        // G-AIC is the residual sum plus the parameter penalty.
        let sum: f64 = residuals.iter().map(|r| r * r).sum();
        let with_p = assess(&residuals, 100, 0.2, "config");
        assert!((with_p.g_aic - sum - 2.0 * 100.0 * 0.04).abs() < 1e-9);
    }
}
