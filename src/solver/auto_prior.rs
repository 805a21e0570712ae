//! The board priors' σ from the data (`static_prior_mm = "auto"`,
//! `bend_prior_mm = "auto"`, `bend_smoothness = "auto"`; empirical Bayes), and
//! whether the frames' bends follow their order at all (the test that lets the
//! smoothness prior act only on a video in time order).
//!
//! A fixed prior σ either does nothing (far above the values' estimation noise)
//! or biases real deformations (below their size). The estimates' own spread
//! says which: their mean square, less the part their estimation variance
//! explains, is the variance of the true values. On a rigid, well printed board
//! that is near zero, so the prior holds the values and the method keeps close
//! to `standard`'s variance; on a bending or misprinted one it is the
//! deformation's size, and the prior hardly pulls. This module reads a finished
//! solve without the prior and returns each prior's σ; the pipeline
//! (`calibrate`) solves again with it, and drops it if it fits clearly worse.
use crate::model::board::{bend_reach, BoardPriors, Method};
use crate::model::state::{State, POSE_PARAMS};
use crate::solver::covariance::{jacobian, unit_correction_information_of};
use crate::solver::problem::{Evaluation, Problem, SolverSettings};
use nalgebra::{DMatrix, DVector};
use rand::seq::SliceRandom;
use rand::SeedableRng;

/// The smallest bend σ the estimate returns, metres: the prior never pins a
/// bend tighter than a hundredth of a millimetre at the board's corner.
pub const MIN_BEND_SIGMA_M: f64 = 1e-5;

/// The smallest static σ the estimate returns, metres: a micrometre, the
/// floor a measured board's σ has too (`MIN_GEOMETRY_STD_M`).
pub const MIN_STATIC_SIGMA_M: f64 = 1e-6;

/// A board prior whose σ can be estimated from the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AutoPrior {
    /// The prior on every static correction value (`static_prior_mm`).
    Static,
    /// The prior on every bend term (`bend_prior_mm`).
    Bend,
}

/// An estimated σ, and how many estimated values it rests on (the values the
/// prior then holds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    pub sigma: f64,
    pub values: usize,
}

impl AutoPrior {
    /// Both, in the order the pipeline adds them.
    pub const ALL: [AutoPrior; 2] = [AutoPrior::Static, AutoPrior::Bend];

    /// The config key.
    pub fn key(self) -> &'static str {
        match self {
            AutoPrior::Static => "static_prior_mm",
            AutoPrior::Bend => "bend_prior_mm",
        }
    }

    /// Whether `board` asks for this σ to be estimated and `method` has the values.
    pub fn wanted(self, board: &BoardPriors, method: Method) -> bool {
        match self {
            AutoPrior::Static => {
                board.static_sigma_auto && board.static_sigma_m.is_none() && method.has_correction()
            }
            AutoPrior::Bend => {
                board.bend_sigma_auto && board.bend_sigma_m.is_none() && method.has_paraboloid()
            }
        }
    }

    /// Sets this prior's σ, metres (`None`: off).
    pub fn set(self, board: &mut BoardPriors, sigma: Option<f64>) {
        match self {
            AutoPrior::Static => board.static_sigma_m = sigma,
            AutoPrior::Bend => board.bend_sigma_m = sigma,
        }
    }

    /// The σ (metres) that the values of the solve at `state` show beyond their
    /// noise `noise_px`; `None` when no value has a variance.
    pub fn estimate(
        self,
        problem: &Problem,
        state: &State,
        settings: &SolverSettings,
        noise_px: f64,
    ) -> Option<Estimate> {
        let e = jacobian(problem, state, settings).ok()?;
        self.estimate_of(&e, problem, state, settings, noise_px)
    }

    /// [`AutoPrior::estimate`] of each of `priors` from one Jacobian (each would
    /// evaluate the same one), in their order.
    pub fn estimate_all(
        priors: &[AutoPrior],
        problem: &Problem,
        state: &State,
        settings: &SolverSettings,
        noise_px: f64,
    ) -> Vec<Option<Estimate>> {
        let e = if priors.is_empty() {
            None
        } else {
            jacobian(problem, state, settings).ok()
        };
        priors
            .iter()
            .map(|p| p.estimate_of(e.as_ref()?, problem, state, settings, noise_px))
            .collect()
    }

    fn estimate_of(
        self,
        e: &Evaluation,
        problem: &Problem,
        state: &State,
        settings: &SolverSettings,
        noise_px: f64,
    ) -> Option<Estimate> {
        match self {
            AutoPrior::Static => static_sigma_of(e, problem, state, settings, noise_px),
            AutoPrior::Bend => {
                let f = bends_with_variances_of(e, problem, state, noise_px)?;
                bend_sigma_of(&f)
            }
        }
    }
}

/// The σ of zero-mean true values from unbiased estimates Δ of them whose
/// errors have covariance C, by the moments: over n values and with P = C⁻¹,
/// E[ΔᵀPΔ] = σ²·tr P + n, so σ² = (ΔᵀPΔ − n) / tr P, at least `floor`. For a
/// diagonal C this is the precision-weighted mean of Δ² − var, so that a barely
/// determined value cannot drown the others; for a full C the same holds for
/// barely determined directions, which a diagonal would smear over every value.
fn excess_sigma(quadratic: f64, trace: f64, values: usize, floor: f64) -> Option<Estimate> {
    (trace > 0.0 && trace.is_finite() && quadratic.is_finite()).then(|| Estimate {
        sigma: ((quadratic - values as f64) / trace)
            .max(0.0)
            .sqrt()
            .max(floor),
        values,
    })
}

/// The static prior's σ: over every free correction value Δ, with P its
/// marginal information (intrinsics, poses and bends free, at the noise). The
/// information given the intrinsics would be far too large: the correction
/// trades off against them, which is why `static` is weakly determined at all,
/// and the excess over a too small variance would read noise as print error.
/// The marginal variances alone (P's inverse's diagonal) would not do either:
/// most of the estimates' error lies along the few directions the intrinsics
/// take up, so their Δ²/var scatter by 0.4–2.2 around 1 from set to set, and
/// one T2 set of 25 images gave σ = 0 against a true 0.07 mm.
pub fn estimate_static_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    AutoPrior::Static.estimate(problem, state, settings, noise_px)
}

/// [`estimate_static_sigma`] from the Jacobian at `state`.
fn static_sigma_of(
    e: &Evaluation,
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    let values = problem.layout().pack(state)?;
    let (params, info) = unit_correction_information_of(e, problem, settings).ok()?;
    let delta = DVector::from_iterator(params.len(), params.iter().map(|&p| values[p]));
    let n2 = noise_px * noise_px;
    let quadratic = delta.dot(&(&info * &delta)) / n2;
    excess_sigma(
        quadratic,
        info.trace() / n2,
        params.len(),
        MIN_STATIC_SIGMA_M,
    )
}

/// The bend prior's σ (Δz of each term at the board's corner) over every frame
/// and term, each with its own variance (P diagonal). A bend's estimation
/// variance is taken given the intrinsics (its
/// frame's pose and bend from that frame's observations alone): cheap, and a
/// slight underestimate that leaves the prior a little looser than it could be.
pub fn estimate_bend_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    AutoPrior::Bend.estimate(problem, state, settings, noise_px)
}

/// [`estimate_bend_sigma`] from the frames' bends and their variances.
fn bend_sigma_of(f: &FrameBends) -> Option<Estimate> {
    let pairs =
        f.dz.iter()
            .zip(&f.variance)
            .filter_map(|(dz, var)| Some(dz.iter().copied().zip(var.as_ref()?.iter().copied())))
            .flatten();
    excess_sigma_of(pairs, MIN_BEND_SIGMA_M).map(|(e, _)| e)
}

/// Each frame's bend terms as Δz at the board's corner ([`frame_bends_at_reach`])
/// and their estimation variances, m², given the intrinsics (`None` for a frame
/// whose pose and bend its own observations do not determine).
fn bends_with_variances(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<FrameBends> {
    let e = jacobian(problem, state, settings).ok()?;
    bends_with_variances_of(&e, problem, state, noise_px)
}

/// [`bends_with_variances`] from the Jacobian at `state`.
fn bends_with_variances_of(
    e: &Evaluation,
    problem: &Problem,
    state: &State,
    noise_px: f64,
) -> Option<FrameBends> {
    let bends = frame_bends_at_reach(problem, state)?;
    let terms = bends.first().map_or(0, Vec::len);
    let reach = bend_reach(&problem.dataset.target, terms);
    let variances = frame_information(e, problem)?
        .into_iter()
        .map(|info| {
            let cov = info.try_inverse()?;
            Some(
                reach
                    .iter()
                    .enumerate()
                    .map(|(i, r)| {
                        let slot = POSE_PARAMS + i;
                        noise_px * noise_px * cov[(slot, slot)] * r * r
                    })
                    .collect(),
            )
        })
        .collect();
    Some(FrameBends {
        dz: bends,
        variance: variances,
    })
}

/// Per frame, its bend terms as Δz at the board's corner and their variances.
struct FrameBends {
    dz: Vec<Vec<f64>>,
    variance: Vec<Option<Vec<f64>>>,
}

/// [`excess_sigma`] over estimates given as (value, variance) pairs, skipping
/// those without a finite positive variance; with tr P, Σ 1/variance.
fn excess_sigma_of(pairs: impl Iterator<Item = (f64, f64)>, floor: f64) -> Option<(Estimate, f64)> {
    let (mut quadratic, mut trace, mut count) = (0.0, 0.0, 0);
    for (value, variance) in pairs {
        if variance.is_finite() && variance > 0.0 {
            quadratic += value * value / variance;
            trace += 1.0 / variance;
            count += 1;
        }
    }
    Some((excess_sigma(quadratic, trace, count, floor)?, trace))
}

/// Per frame, JᵀJ of its pose and bend values from its own observations' rows
/// (weighted residuals, so in units of a weight-1 corner's noise).
fn frame_information(e: &Evaluation, problem: &Problem) -> Option<Vec<DMatrix<f64>>> {
    let layout = problem.layout();
    let stride = layout.frame_stride;
    if e.jacobian_rows != 2 * problem.dataset.observations.len() {
        return None;
    }
    let frames = layout.frames..layout.frames + stride * layout.num_frames;
    let slot: Vec<Option<(usize, usize)>> = e
        .jacobian_col_param
        .iter()
        .map(|&p| {
            let p = p as usize;
            frames
                .contains(&p)
                .then(|| ((p - frames.start) / stride, (p - frames.start) % stride))
        })
        .collect();
    let mut info = vec![DMatrix::<f64>::zeros(stride, stride); layout.num_frames];
    let mut entries = Vec::new();
    for r in 0..e.jacobian_rows {
        entries.clear();
        for i in e.jacobian_row_ptr[r] as usize..e.jacobian_row_ptr[r + 1] as usize {
            if let Some((j, s)) = slot[e.jacobian_col_idx[i] as usize] {
                entries.push((j, s, e.jacobian_values[i]));
            }
        }
        for &(j, a, va) in &entries {
            for &(k, b, vb) in &entries {
                if j == k {
                    info[j][(a, b)] += va * vb;
                }
            }
        }
    }
    Some(info)
}

/// Each frame's bend terms as Δz at the board's corner, metres, in frame order;
/// `None` for a method without per-frame bends.
pub fn frame_bends_at_reach(problem: &Problem, state: &State) -> Option<Vec<Vec<f64>>> {
    let layout = problem.layout();
    let stride = layout.frame_stride;
    let terms = stride.checked_sub(POSE_PARAMS).filter(|&t| t > 0)?;
    let values = layout.pack(state)?;
    let reach = bend_reach(&problem.dataset.target, terms);
    Some(
        (0..layout.num_frames)
            .map(|j| {
                let at = layout.frames + j * stride + POSE_PARAMS;
                values[at..at + terms]
                    .iter()
                    .zip(&reach)
                    .map(|(c, r)| c * r)
                    .collect()
            })
            .collect(),
    )
}

/// Whether a sequence of per-frame bends follows its order: the median square
/// change from one frame to the next, against the frames in random orders.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrderTest {
    /// Median square change between consecutive frames over its mean in random
    /// orders: near 1 for frames in no particular order, near 0 for a smooth video.
    pub ratio: f64,
    /// The share of random orders whose consecutive changes are as small
    /// (a permutation test, [`ORDER_PERMUTATIONS`] orders).
    pub p_value: f64,
}

/// Random orders the permutation test draws (seeded: the same data, the same verdict).
pub const ORDER_PERMUTATIONS: usize = 1999;

/// The frames count as in time order below this p-value.
pub const ORDER_P_VALUE: f64 = 0.001;

impl OrderTest {
    /// Whether the bends change less from frame to frame than chance allows.
    pub fn in_order(&self) -> bool {
        self.p_value < ORDER_P_VALUE
    }
}

/// Tests `bends` (one vector of terms per frame, in frame order); `None` for
/// fewer than three frames or bends that do not vary at all.
///
/// A bend estimated per frame is the true bend plus that frame's estimation
/// error. In time order a slowly flexing board's consecutive bends differ by
/// the flex of one frame plus the two errors; in any other order, by the
/// bends' whole spread. The test needs no noise model: noisy bends only bring
/// the ratio towards 1, never below it. It takes the median change, not the
/// mean: a few frames whose bend is barely determined (few corners, a far
/// board) come out far off, and their changes would drown every other frame's.
/// Shuffled frames give ratios of 0.87–1.13 on the `flex` preset, the same
/// frames in time order 0.006–0.18 (the hand-held video's noisy bends the highest).
pub fn order_test(bends: &[Vec<f64>]) -> Option<OrderTest> {
    let n = bends.len();
    if n < 3 {
        return None;
    }
    let mut changes = vec![0.0; n - 1];
    let mut median_change = |order: &[usize]| -> f64 {
        for (c, w) in changes.iter_mut().zip(order.windows(2)) {
            *c = bends[w[1]]
                .iter()
                .zip(&bends[w[0]])
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>();
        }
        let mid = changes.len() / 2;
        *changes.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let mut order: Vec<usize> = (0..n).collect();
    let observed = median_change(&order);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let (mut as_small, mut sum) = (0, 0.0);
    for _ in 0..ORDER_PERMUTATIONS {
        order.shuffle(&mut rng);
        let m = median_change(&order);
        sum += m;
        if m <= observed {
            as_small += 1;
        }
    }
    let chance = sum / ORDER_PERMUTATIONS as f64;
    if !(chance > 0.0 && chance.is_finite()) {
        return None;
    }
    Some(OrderTest {
        ratio: observed / chance,
        p_value: (1 + as_small) as f64 / (1 + ORDER_PERMUTATIONS) as f64,
    })
}

/// The smoothness prior's σ (each term's change from frame j−1 to j, as Δz at
/// the board's corner) from the frames' own bends (a solve without the prior):
/// the moments of [`excess_sigma`] over the consecutive differences, each with
/// the variance of its two frames' bend estimates (given the intrinsics, as
/// for the bend prior). What the changes show beyond that noise is the flex
/// per frame, which is what the prior's σ means. Where the noise drowns it
/// (a far, noisy board), the estimate is not allowed below its own standard
/// error: a σ the data cannot tell from zero would tie frames the data do not.
pub fn estimate_smoothness_sigma(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
    noise_px: f64,
) -> Option<Estimate> {
    let f = bends_with_variances(problem, state, settings, noise_px)?;
    // The change of each term from frame j−1 to j, with the two frames' variance.
    let dz = &f.dz;
    let pairs = (1..dz.len())
        .filter_map(|j| {
            let (a, b) = (f.variance[j - 1].as_ref()?, f.variance[j].as_ref()?);
            Some((0..a.len()).map(move |q| (dz[j][q] - dz[j - 1][q], a[q] + b[q])))
        })
        .flatten();
    let (estimate, trace) = excess_sigma_of(pairs, MIN_BEND_SIGMA_M)?;
    // The moment estimate of σ² has a standard error of √(2n) / tr P near σ = 0.
    let resolvable = ((2.0 * estimate.values as f64).sqrt() / trace).sqrt();
    Some(Estimate {
        sigma: estimate.sigma.max(resolvable),
        ..estimate
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::{Distribution, Normal};

    /// A random walk of three terms (steps of σ) seen with estimation noise.
    fn walk(n: usize, step: f64, noise: f64, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (s, e) = (
            Normal::new(0.0, step).unwrap(),
            Normal::new(0.0, noise).unwrap(),
        );
        let mut truth = [0.0; 3];
        (0..n)
            .map(|_| {
                truth
                    .iter_mut()
                    .map(|t| {
                        *t += s.sample(&mut rng);
                        *t + e.sample(&mut rng)
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_walk_in_order_passes_and_shuffled_fails() {
        for seed in 1..=5 {
            // Noise three times the step: each bend alone is mostly noise.
            let bends = walk(200, 1.0, 3.0, seed);
            let t = order_test(&bends).unwrap();
            assert!(t.in_order() && t.ratio < 0.5, "seed {seed}: {t:?}");
            let mut shuffled = bends.clone();
            shuffled.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed + 100));
            let t = order_test(&shuffled).unwrap();
            assert!(
                !t.in_order() && (0.7..1.3).contains(&t.ratio),
                "seed {seed} shuffled: {t:?}"
            );
        }
    }

    #[test]
    fn the_ratio_is_what_a_stationary_flex_and_noise_predict() {
        // An AR(1) flex of unit variance and lag-1 correlation ρ, seen with noise e:
        // consecutive frames differ by 2(1 − ρ) + 2e² per term, random pairs by
        // 2 + 2e², both Gaussian, so the medians of their squared norms (the
        // same scaled χ² of 3 degrees) keep the ratio (1 − ρ + e²) / (1 + e²).
        let (n, rho, noise) = (4000, 0.9_f64, 0.3_f64);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut flex = [0.0; 3];
        let bends: Vec<Vec<f64>> = (0..n)
            .map(|_| {
                flex.iter_mut()
                    .map(|f| {
                        *f = rho * *f + (1.0 - rho * rho).sqrt() * unit.sample(&mut rng);
                        *f + noise * unit.sample(&mut rng)
                    })
                    .collect()
            })
            .collect();
        let t = order_test(&bends).unwrap();
        let expected = (1.0 - rho + noise * noise) / (1.0 + noise * noise);
        assert!(
            (t.ratio / expected - 1.0).abs() < 0.1,
            "{} vs {expected}",
            t.ratio
        );
    }

    #[test]
    fn a_few_wild_frames_do_not_hide_the_order() {
        // Frames whose bend is barely determined (few corners, a far board) can
        // come out metres off; they must not drown the other frames' changes.
        let mut bends = walk(200, 1.0, 1.0, 3);
        for j in [20, 90, 150] {
            bends[j] = bends[j].iter().map(|v| v + 1000.0).collect();
        }
        let t = order_test(&bends).unwrap();
        assert!(t.in_order() && t.ratio < 0.5, "{t:?}");
    }

    #[test]
    fn too_few_or_constant_frames_give_no_test() {
        assert!(order_test(&walk(2, 1.0, 0.0, 1)).is_none());
        assert!(order_test(&vec![vec![1.0, 2.0, 3.0]; 10]).is_none());
    }
}
