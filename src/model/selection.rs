//! Model selection between board models (docs/conventions.md §3a, `method = "auto"`): the
//! seeded k-fold split of the frames and the rule that picks a method from the
//! candidates' held-out errors. Pure arithmetic on per-frame errors; the solves
//! that produce them live in `solver::select`.
use crate::model::board::Method;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The config's `method`: one board model, or `auto` (chosen by cross-validation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MethodChoice {
    /// Calibrate with this method.
    Fixed(Method),
    /// Calibrate with every candidate and keep the one the data supports.
    Auto,
}

impl MethodChoice {
    /// `auto` or one of the method names.
    pub fn parse(s: &str) -> Option<MethodChoice> {
        match s {
            "auto" => Some(MethodChoice::Auto),
            _ => Method::parse(s).map(MethodChoice::Fixed),
        }
    }
}

impl fmt::Display for MethodChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MethodChoice::Fixed(m) => write!(f, "{m}"),
            MethodChoice::Auto => f.write_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for MethodChoice {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        MethodChoice::parse(&s).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown method `{s}`, expected one of standard, static, dynamic, full, auto"
            ))
        })
    }
}

/// How `auto` cross-validates: which methods, how many folds, which shuffle.
#[derive(Debug, Clone, PartialEq)]
pub struct AutoSettings {
    /// The methods tried; `standard` is always among them (the baseline).
    pub candidates: Vec<Method>,
    /// k of the k-fold cross-validation over frames.
    pub folds: usize,
    /// Seed of the frames' shuffle into folds.
    pub seed: u64,
    /// The detector noise the user gave, for every candidate's trust figures.
    pub detector_noise_px: Option<f64>,
}

/// Fewest frames per fold: a held-out error from fewer frames is mostly noise,
/// so a capture too small for `folds` folds of this many is left out one by one.
pub const MIN_FRAMES_PER_FOLD: usize = 2;

impl AutoSettings {
    /// The folds used on `frames` frames: the configured number where every fold
    /// gets [`MIN_FRAMES_PER_FOLD`] frames, else one per frame (leave-one-out),
    /// so that a small capture is still judged rather than refused.
    pub fn folds_for(&self, frames: usize) -> usize {
        if frames >= self.folds * MIN_FRAMES_PER_FOLD {
            self.folds
        } else {
            frames
        }
    }
}

impl Default for AutoSettings {
    fn default() -> Self {
        AutoSettings {
            candidates: vec![Method::Standard, Method::Dynamic, Method::Full],
            folds: 5,
            seed: 1,
            detector_noise_px: None,
        }
    }
}

/// Splits frames `0..n` into `k` folds of near-equal size after a seeded shuffle
/// (ChaCha8's specified stream: the same folds on every machine). Each fold is sorted.
pub fn folds(n: usize, k: usize, seed: u64) -> Vec<Vec<usize>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    let mut out: Vec<Vec<usize>> = (0..k)
        .map(|f| order.iter().skip(f).step_by(k).copied().collect())
        .collect();
    for f in &mut out {
        f.sort_unstable();
    }
    out
}

/// One candidate's held-out error, per frame: the sum of squared residuals (px²)
/// and the number of points, for the frames it was tested on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HeldOut {
    pub squared: Vec<f64>,
    pub points: Vec<usize>,
}

impl HeldOut {
    /// An empty record for `frames` frames.
    pub fn new(frames: usize) -> Self {
        HeldOut {
            squared: vec![0.0; frames],
            points: vec![0; frames],
        }
    }

    /// Mean squared error per point, px² (the cross-validated RMSE squared).
    pub fn mse(&self) -> f64 {
        let n: usize = self.points.iter().sum();
        self.squared.iter().sum::<f64>() / n.max(1) as f64
    }
}

/// What one candidate showed, in `calibration.json`'s `auto.candidates`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub method: Method,
    /// Cross-validated RMSE on the held-out frames, px (none when a fold failed).
    pub cv_rmse_px: Option<f64>,
    /// Its standard error relative to the best candidate (paired over frames), px.
    pub cv_noise_px: Option<f64>,
    /// Training RMSE of the fit to all data, px.
    pub rmse_px: Option<f64>,
    pub g_aic: Option<f64>,
    pub bias_ratio: Option<f64>,
    /// Free parameters of the fit to all data.
    pub parameters: usize,
    /// Largest out-of-plane bend of any frame in the fit to all data, metres.
    pub max_bend_m: Option<f64>,
    /// Why the candidate could not be judged, if it could not.
    pub failed: Option<String>,
}

/// The choice `auto` made, with every candidate's evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    pub chosen: Method,
    pub folds: usize,
    pub seed: u64,
    pub candidates: Vec<Candidate>,
    pub reason: String,
    /// Largest mapping error between `standard`'s and the chosen intrinsics over
    /// the cameras, px: how far modelling the board moves the projection.
    pub projection_shift_px: f64,
    /// The same with the virtual rotation profiled out (docs/conventions.md §3), px.
    #[serde(default)]
    pub projection_shift_rot_px: f64,
}

/// Paired standard error of `mse(a) − mse(b)`, in px², over the frames both saw.
fn paired_noise(a: &HeldOut, b: &HeldOut) -> f64 {
    let total: usize = a.points.iter().sum();
    let d: Vec<f64> = a
        .squared
        .iter()
        .zip(&b.squared)
        .zip(&a.points)
        .filter(|(_, &n)| n > 0)
        .map(|((x, y), _)| x - y)
        .collect();
    if d.len() < 2 || total == 0 {
        return f64::INFINITY;
    }
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (d.len() - 1) as f64;
    (d.len() as f64 * var).sqrt() / total as f64
}

/// How many paired standard errors a candidate's held-out error must be below a
/// simpler candidate's for `auto` to prefer it. Fitted on the auto grid's seeds
/// 1-3 and judged on seeds 100 and 200 (docs/benchmarks.md): with one, `auto`
/// left rigid boards for a bend model that predicted the left-out photos a
/// little better by chance, with a lens 12 % and more further from the truth
/// than `standard`'s; with three, it kept `standard` on bending boards where
/// `standard` was several times worse.
pub const CV_STANDARD_ERRORS: f64 = 2.0;

/// The rule: the candidate with the lowest cross-validated error, unless a simpler
/// one (fewer parameters; `entries` is in that order) is within
/// [`CV_STANDARD_ERRORS`] paired standard errors of it. Fills each candidate's
/// `cv_rmse_px`/`cv_noise_px` and returns the index chosen and the reason;
/// `None` when no candidate has an error.
pub fn choose(entries: &mut [(Candidate, Option<HeldOut>)]) -> Option<(usize, String)> {
    let best = (0..entries.len())
        .filter(|&i| entries[i].1.is_some())
        .min_by(|&i, &j| {
            let (a, b) = (entries[i].1.as_ref(), entries[j].1.as_ref());
            a.map(HeldOut::mse)
                .partial_cmp(&b.map(HeldOut::mse))
                .unwrap_or(std::cmp::Ordering::Equal)
        })?;
    let best_held = entries[best].1.clone()?;
    let best_mse = best_held.mse();
    for (c, h) in entries.iter_mut() {
        if let Some(h) = h {
            let mse = h.mse();
            c.cv_rmse_px = Some(mse.sqrt());
            // The noise of a difference of squares, as a difference of RMSEs.
            let noise = paired_noise(h, &best_held);
            c.cv_noise_px = Some(noise / (2.0 * mse.sqrt().max(1e-12)));
        }
    }
    let within = |i: usize| {
        let h = entries[i].1.as_ref()?;
        let noise = paired_noise(h, &best_held);
        (h.mse() - best_mse <= CV_STANDARD_ERRORS * noise).then_some(())
    };
    let chosen = (0..best).find(|&i| within(i).is_some()).unwrap_or(best);
    Some((chosen, reason(entries, chosen, best)))
}

/// "within twice the noise (±n%)": the rule's allowance, said in words.
fn within_noise(noise_percent: f64) -> String {
    let times = match CV_STANDARD_ERRORS {
        k if k == 1.0 => String::new(),
        k if k == 2.0 => "twice ".into(),
        k => format!("{k} times "),
    };
    format!("within {times}the noise (±{noise_percent:.1}%)")
}

/// What a board model adds to a rigid board, in a user's words.
fn models(m: Method) -> &'static str {
    match (m.has_paraboloid(), m.has_correction()) {
        (true, true) => "each photo's bend and a fixed correction of every corner",
        (true, false) => "each photo's bend",
        (false, true) => "a fixed correction of every corner",
        (false, false) => "nothing beyond a rigid board",
    }
}

/// Why `auto` chose `entries[chosen]` (`best` has the lowest score), in one
/// sentence a user understands; `entries[0]` is the simplest candidate.
fn reason(entries: &[(Candidate, Option<HeldOut>)], chosen: usize, best: usize) -> String {
    let name = |i: usize| entries[i].0.method;
    let rmse = |i: usize| entries[i].0.cv_rmse_px.unwrap_or(f64::NAN);
    // How much better `i` predicts than `j`, and the noise of that, in per cent.
    let gain = |i: usize, j: usize| {
        let (hi, hj) = (entries[i].1.as_ref(), entries[j].1.as_ref());
        let noise = match (hi, hj) {
            (Some(a), Some(b)) => paired_noise(a, b) / (2.0 * rmse(j) * rmse(j)),
            _ => f64::NAN,
        };
        (100.0 * (1.0 - rmse(i) / rmse(j)), 100.0 * noise)
    };
    if !rmse(0).is_finite() {
        return format!(
            "`{}` could not be cross-validated; `{}` has the lowest cross-validated error \
             ({:.4} px per corner)",
            name(0),
            name(chosen),
            rmse(chosen)
        );
    }
    if chosen == 0 {
        if best == 0 {
            return format!(
                "the board looks rigid: no board model predicts the left-out photos better than a \
                 rigid board (`{}`, {:.4} px per corner)",
                name(0),
                rmse(0)
            );
        }
        let (g, noise) = gain(best, 0);
        return format!(
            "the board looks rigid: modelling {} (`{}`) predicts the left-out photos only {g:.1}% \
             better than a rigid board, {}, so the simpler `{}` is kept",
            models(name(best)),
            name(best),
            within_noise(noise),
            name(0)
        );
    }
    let (g, noise) = gain(chosen, 0);
    let what = if name(chosen).has_paraboloid() {
        "the board bends"
    } else {
        "the board is not the nominal one"
    };
    let mut out = format!(
        "{what}: modelling {} (`{}`) predicts the left-out photos {g:.1}% better than a rigid \
         board (`{}`; noise ±{noise:.1}%)",
        models(name(chosen)),
        name(chosen),
        name(0)
    );
    if chosen != best {
        let (g, noise) = gain(best, chosen);
        out += &format!(
            "; `{}` does only {g:.1}% better still, {}, and is more complex",
            name(best),
            within_noise(noise)
        );
    }
    out
}

/// `bend_order = "auto"`: when the candidates hold several bend orders of one
/// deformation (which the default candidates never do), the order is the one of
/// lowest G-AIC among them (all fit the same observations, so their G-AIC
/// compare; cross-validation with unbent held-out frames cannot see a better bend
/// of the training frames). Returns the method and the reason; `None` otherwise.
pub fn choose_bend_order(candidates: &[Candidate]) -> Option<(Method, String)> {
    let bends: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.method.bend_order() >= 2 && c.g_aic.is_some())
        .collect();
    let first = bends.first()?;
    let family = first.method.has_correction();
    if bends.iter().any(|c| c.method.has_correction() != family) || bends.len() < 2 {
        return None;
    }
    let best = bends.iter().min_by(|a, b| {
        a.g_aic
            .partial_cmp(&b.g_aic)
            .unwrap_or(std::cmp::Ordering::Equal)
    })?;
    let others: Vec<String> = bends
        .iter()
        .filter(|c| c.method != best.method)
        .map(|c| format!("`{}` {:.1}", c.method, c.g_aic.unwrap_or(f64::NAN)))
        .collect();
    Some((
        best.method,
        format!(
            "bend_order = \"auto\": `{}` (order {}) has the lowest G-AIC, {:.1} (vs {})",
            best.method,
            best.method.bend_order(),
            best.g_aic.unwrap_or(f64::NAN),
            others.join(", ")
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(method: Method) -> Candidate {
        Candidate {
            method,
            cv_rmse_px: None,
            cv_noise_px: None,
            rmse_px: None,
            g_aic: None,
            bias_ratio: None,
            parameters: 0,
            max_bend_m: None,
            failed: None,
        }
    }

    fn held(per_frame: &[f64]) -> HeldOut {
        HeldOut {
            squared: per_frame.to_vec(),
            points: vec![10; per_frame.len()],
        }
    }

    #[test]
    fn folds_partition_the_frames_evenly_and_reproducibly() {
        let f = folds(23, 5, 9);
        let mut all: Vec<usize> = f.iter().flatten().copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..23).collect::<Vec<_>>());
        assert!(f.iter().all(|x| x.len() == 4 || x.len() == 5));
        assert_eq!(f, folds(23, 5, 9));
        assert_ne!(f, folds(23, 5, 10));
    }

    #[test]
    fn a_clearly_better_complex_model_wins() {
        // dynamic is lower on every frame by far more than the frames scatter.
        let mut e = vec![
            (
                candidate(Method::Standard),
                Some(held(&[10.0, 11.0, 9.0, 10.5])),
            ),
            (
                candidate(Method::Dynamic),
                Some(held(&[5.0, 5.2, 4.9, 5.1])),
            ),
        ];
        let (i, reason) = choose(&mut e).unwrap();
        assert_eq!(i, 1, "{reason}");
        assert!(e[0].0.cv_rmse_px.unwrap() > e[1].0.cv_rmse_px.unwrap());
        // mse 10.125/10 → rmse √1.0125.
        assert!((e[0].0.cv_rmse_px.unwrap() - 1.0125f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_simpler_model_within_the_noise_wins() {
        // full is lower on average, but the per-frame differences scatter around 0.
        let mut e = vec![
            (
                candidate(Method::Standard),
                Some(held(&[10.0, 12.0, 8.0, 10.0])),
            ),
            (
                candidate(Method::Dynamic),
                Some(held(&[10.5, 11.0, 8.5, 9.5])),
            ),
            (candidate(Method::Full), Some(held(&[9.0, 12.5, 7.5, 10.2]))),
        ];
        let (i, reason) = choose(&mut e).unwrap();
        assert_eq!(i, 0, "{reason}");
        assert!(reason.contains("within twice the noise"), "{reason}");
    }

    #[test]
    fn a_bend_model_must_predict_better_by_two_standard_errors() {
        // Per-frame differences m + a_i with a = ±√3/2 (sample σ 1): the mean
        // difference is 2m/σ = 2m paired standard errors.
        let a = 3f64.sqrt() / 2.0;
        let standard = [10.0, 11.0, 9.0, 10.5];
        let with_gain = |m: f64| {
            let dynamic: Vec<f64> = standard
                .iter()
                .enumerate()
                .map(|(i, x)| x - m - if i % 2 == 0 { -a } else { a })
                .collect();
            vec![
                (candidate(Method::Standard), Some(held(&standard))),
                (candidate(Method::Dynamic), Some(held(&dynamic))),
            ]
        };
        // 1.5 standard errors: not enough.
        let (i, reason) = choose(&mut with_gain(0.75)).unwrap();
        assert_eq!(i, 0, "{reason}");
        // 2.5 standard errors: the bend model.
        let (i, reason) = choose(&mut with_gain(1.25)).unwrap();
        assert_eq!(i, 1, "{reason}");
    }

    #[test]
    fn failed_candidates_are_skipped() {
        let mut e = vec![
            (candidate(Method::Standard), Some(held(&[10.0, 11.0, 9.0]))),
            (candidate(Method::Full), None),
        ];
        assert_eq!(choose(&mut e).unwrap().0, 0);
        let mut none = vec![(candidate(Method::Standard), None)];
        assert!(choose(&mut none).is_none());
    }
}
