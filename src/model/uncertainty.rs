//! What a camera's intrinsics covariance Σ_θ means in pixels (docs/conventions.md §3a): the
//! standard deviation of each intrinsic, the expected mapping error to the true
//! intrinsics (plain, and with the virtual rotation of docs/conventions.md §3 profiled out) and the
//! projection-uncertainty map over the image. Pure arithmetic on Σ_θ; computing
//! Σ_θ from a solve is `solver::uncertainty`'s.
use crate::model::lens::{Intrinsics, LensModel, MAX_PARAMS};
use crate::model::metrics::grid_rays;
use nalgebra::{DMatrix, Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};
use std::sync::{Arc, Mutex, OnceLock};

/// Why a calibration has no uncertainty figures.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UncertaintyError {
    /// The data do not determine every free parameter: JᵀJ is singular there.
    #[error("the data do not determine {0} (the normal equations are singular there)")]
    RankDeficient(String),
    /// No detector noise σ̂ to scale the covariance with.
    #[error("no detector noise estimate: set [calibration] detector_noise_px")]
    NoNoise,
    /// The Jacobian at the optimum could not be had or has an unexpected form.
    #[error("the Jacobian at the optimum is unusable: {0}")]
    Jacobian(String),
    /// More parameters remain after eliminating the per-image or per-corner blocks
    /// than a dense covariance computation should hold.
    #[error("{0} parameters remain after elimination; at most {MAX_REDUCED} are supported")]
    TooLarge(usize),
}

/// Most parameters a dense reduced system may have (about 200 MB of f64).
pub const MAX_REDUCED: usize = 5000;

/// The covariance of one camera's intrinsics at a detector noise of 1 px per
/// coordinate: multiply by σ̂² for the covariance at noise σ̂.
#[derive(Debug, Clone, PartialEq)]
pub struct IntrinsicsCovariance {
    /// Per lens parameter (registry order): estimated; `false` for a parameter
    /// held at its value, whose row and column are zero.
    pub free: Vec<bool>,
    /// n × n over the lens parameters, in their units squared per px².
    pub unit: DMatrix<f64>,
}

/// What one covariance pass over a solved problem gives at unit noise: every
/// camera's Σ_θ and, from the same Jacobian and normal matrix, the board's σ.
#[derive(Debug, Clone, PartialEq)]
pub struct UnitCovariance {
    /// Σ_θ of each camera, in the dataset's order.
    pub cameras: Vec<IntrinsicsCovariance>,
    /// The standard deviation of every static correction value (3 per corner,
    /// metres per px; 0 for a held value): present when the board's
    /// corrections stayed in the dense reduced system, absent when they were
    /// eliminated first (fewer values in the images' blocks than in the
    /// corners', as with 25 images) or the problem has none free.
    pub correction_std: Option<Vec<[f64; 3]>>,
}

/// A camera's uncertainty figures at a given noise (docs/conventions.md §3a, §5).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraUncertainty {
    /// σ of each estimated lens parameter (held ones are left out), registry order.
    pub intrinsics_std: Vec<(&'static str, f64)>,
    /// √(trace(H Σ_θ)/M): the mapping error to the truth that the noise alone leaves.
    pub expected_mapping_error_px: f64,
    /// The same with the virtual rotation profiled out.
    pub expected_mapping_error_rot_px: f64,
}

/// Relative step of the central differences in the lens parameters: the
/// projections are smooth in them, so the truncation error (∝ h²) is far below
/// the round-off (∝ ε/h) at this step.
const PARAM_STEP: f64 = 1e-6;

/// J = ∂project_θ'(ray)/∂θ' at θ' = θ (2 × n), by central differences; `None` if a
/// perturbed projection fails (a ray at the edge of the model's domain).
pub fn projection_jacobian(k: &Intrinsics, ray: &Vector3<f64>) -> Option<DMatrix<f64>> {
    let n = k.params().len();
    let j = jacobian_rows(k, ray)?;
    Some(DMatrix::from_fn(2, n, |r, c| j[r][c]))
}

/// [`projection_jacobian`]'s two rows on the stack (the first n entries hold it):
/// the grids below take one per pixel, thousands per calibration.
pub fn jacobian_rows(k: &Intrinsics, ray: &Vector3<f64>) -> Option<[[f64; MAX_PARAMS]; 2]> {
    let mut j = [[0.0; MAX_PARAMS]; 2];
    // fx, fy, cx, cy only enter the last, affine step of the projection: the
    // same arithmetic as `Intrinsics::project` on the one m (the same values to
    // the bit), without projecting again per step.
    let m = k.normalised(ray)?;
    let p = k.params();
    for i in 0..4 {
        let h = PARAM_STEP * p[i].abs().max(1.0);
        let pixel = |step: f64| {
            let mut q = [p[0], p[1], p[2], p[3]];
            q[i] += step;
            Vector2::new(q[0] * m.x + q[2], q[1] * m.y + q[3])
        };
        let d = (pixel(h) - pixel(-h)) / (2.0 * h);
        [j[0][i], j[1][i]] = [d.x, d.y];
    }
    // One copy, each parameter moved and put back in turn (no copy per step).
    let mut q = *k;
    for (i, &p) in k.params().iter().enumerate().skip(4) {
        let h = PARAM_STEP * p.abs().max(1.0);
        q.params_mut()[i] = p + h;
        let plus = q.project(ray);
        q.params_mut()[i] = p - h;
        let minus = q.project(ray);
        q.params_mut()[i] = p;
        let d = (plus? - minus?) / (2.0 * h);
        [j[0][i], j[1][i]] = [d.x, d.y];
    }
    Some(j)
}

/// J = ∂project_θ(ray)/∂θ (2 × n, in the rows' first n entries) and
/// R = ∂project_θ(R(ω)·ray)/∂ω at ω = 0 (2 × 3), in closed form: R(ω)·ray moves
/// by ω × ray = −[ray]× ω, so R = (∂uv/∂x_c)·(−[ray]×).
fn closed_form_rows(
    k: &Intrinsics,
    ray: &Vector3<f64>,
) -> Option<([[f64; MAX_PARAMS]; 2], Matrix2x3<f64>)> {
    let d = k.project_with_derivatives(ray)?;
    let minus_cross = Matrix3::new(
        0.0, ray.z, -ray.y, //
        -ray.z, 0.0, ray.x, //
        ray.y, -ray.x, 0.0,
    );
    Some((d.d_params, d.d_point * minus_cross))
}

/// The mapping-error grid's quadratic forms (H, H with the rotation profiled out, M).
pub type MappingForms = (DMatrix<f64>, DMatrix<f64>, usize);

/// Exact bits of the inputs of [`mapping_forms`]: a hit is the computation's own value.
type FormsKey = (LensModel, [u64; MAX_PARAMS], u32, u32);

/// The forms of the last few cameras asked for, each computed once (the `OnceLock`:
/// concurrent askers of one camera wait for the first, others run on).
type FormsCache = Vec<(FormsKey, Arc<OnceLock<Option<MappingForms>>>)>;

/// How many cameras' forms [`mapping_forms`] keeps.
const FORMS_KEPT: usize = 16;

/// The mapping-error grid's quadratic forms: H = Σ J_gᵀJ_g and, with the virtual
/// rotation ω profiled out, H − C (KᵀK)⁻¹ Cᵀ (C = Σ J_gᵀK_g, KᵀK = Σ K_gᵀK_g),
/// each over the M grid points; `None` without a usable grid point.
///
/// Remembered for the last [`FORMS_KEPT`] cameras: a result's summary,
/// `calibration.json` and report each ask for the same camera's forms, and the
/// grid's unprojections and central differences are most of their cost.
pub fn mapping_forms(k: &Intrinsics, width: u32, height: u32) -> Option<MappingForms> {
    static CACHE: Mutex<FormsCache> = Mutex::new(Vec::new());
    let mut bits = [0u64; MAX_PARAMS];
    for (b, v) in bits.iter_mut().zip(k.params()) {
        *b = v.to_bits();
    }
    let key = (k.model(), bits, width, height);
    let cell = {
        // A panic elsewhere while the lock was held leaves the list itself valid.
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        match cache.iter().position(|(k, _)| *k == key) {
            Some(i) => cache[i].1.clone(),
            None => {
                if cache.len() >= FORMS_KEPT {
                    cache.remove(0);
                }
                let cell = Arc::new(OnceLock::new());
                cache.push((key, cell.clone()));
                cell
            }
        }
    };
    cell.get_or_init(|| compute_mapping_forms(k, width, height))
        .clone()
}

/// [`mapping_forms`] computed afresh.
pub fn compute_mapping_forms(k: &Intrinsics, width: u32, height: u32) -> Option<MappingForms> {
    let n = k.params().len();
    let (mut h, mut c) = (DMatrix::<f64>::zeros(n, n), DMatrix::<f64>::zeros(n, 3));
    let mut kk = Matrix3::<f64>::zeros();
    let mut m = 0;
    // Sums of JᵀJ, JᵀR and RᵀR over the grid, accumulated in place: no matrix is
    // allocated per pixel. J and R in closed form, one projection per pixel (the
    // central differences of `jacobian_rows` agree to about 1e-9 relative).
    for (_, ray) in grid_rays(k, width, height) {
        let Some((j, r)) = closed_form_rows(k, &ray) else {
            continue;
        };
        for a in 0..n {
            for b in 0..n {
                h[(a, b)] += j[0][a] * j[0][b] + j[1][a] * j[1][b];
            }
            for b in 0..3 {
                c[(a, b)] += j[0][a] * r[(0, b)] + j[1][a] * r[(1, b)];
            }
        }
        kk += r.transpose() * r;
        m += 1;
    }
    let kk_inv = kk.try_inverse()?;
    let kk_inv = DMatrix::from_column_slice(3, 3, kk_inv.as_slice());
    let h_rot = &h - &c * kk_inv * c.transpose();
    (m > 0).then_some((h, h_rot, m))
}

/// The figures of one camera for a covariance Σ_θ already scaled to the noise;
/// `None` when no grid pixel can be unprojected.
pub fn camera_uncertainty(
    k: &Intrinsics,
    free: &[bool],
    sigma: &DMatrix<f64>,
    width: u32,
    height: u32,
) -> Option<CameraUncertainty> {
    let (h, h_rot, m) = mapping_forms(k, width, height)?;
    // trace(HΣ) is the expected squared mapping error summed over the grid; a
    // negative round-off of a (nearly) zero figure is clamped.
    let expected = |form: &DMatrix<f64>| ((form * sigma).trace().max(0.0) / m as f64).sqrt();
    let intrinsics_std = k
        .model()
        .param_names()
        .iter()
        .enumerate()
        .filter(|(i, _)| free[*i])
        .map(|(i, &name)| (name, sigma[(i, i)].max(0.0).sqrt()))
        .collect();
    Some(CameraUncertainty {
        intrinsics_std,
        expected_mapping_error_px: expected(&h),
        expected_mapping_error_rot_px: expected(&h_rot),
    })
}

/// The predicted 1-σ projection error over an image, on a grid of cells.
#[derive(Debug, Clone, PartialEq)]
pub struct UncertaintyMap {
    pub width: u32,
    pub height: u32,
    /// Cells across and down.
    pub columns: usize,
    pub rows: usize,
    /// Per cell, row-major from the top left: √λ_max(J_g Σ_θ J_gᵀ) at the cell's
    /// centre in pixels; NaN where the pixel has no ray.
    pub sigma_px: Vec<f64>,
}

impl UncertaintyMap {
    /// The centre pixel of cell (column, row); pixel centres are integers (docs/conventions.md §1).
    pub fn centre(&self, column: usize, row: usize) -> Vector2<f64> {
        let (w, h) = (self.width as f64, self.height as f64);
        Vector2::new(
            (column as f64 + 0.5) * w / self.columns as f64 - 0.5,
            (row as f64 + 0.5) * h / self.rows as f64 - 0.5,
        )
    }

    /// The smallest finite σ of the map (0 if none).
    pub fn min(&self) -> f64 {
        let min = self
            .sigma_px
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f64::INFINITY, f64::min);
        if min.is_finite() {
            min
        } else {
            0.0
        }
    }

    /// The largest finite σ of the map (0 if none).
    pub fn max(&self) -> f64 {
        self.sigma_px
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
    }
}

/// J Σ Jᵀ (2 × 2) for the rows of [`jacobian_rows`] and an n × n Σ.
fn propagate(j: &[[f64; MAX_PARAMS]; 2], sigma: &DMatrix<f64>) -> Matrix2<f64> {
    let n = sigma.nrows();
    let mut s = Matrix2::zeros();
    for a in 0..n {
        for b in 0..n {
            let v = sigma[(a, b)];
            s[(0, 0)] += j[0][a] * v * j[0][b];
            s[(0, 1)] += j[0][a] * v * j[1][b];
            s[(1, 1)] += j[1][a] * v * j[1][b];
        }
    }
    s[(1, 0)] = s[(0, 1)];
    s
}

/// The projection-uncertainty map of intrinsics `k` with noise-scaled covariance
/// `sigma`, on about `columns` cells across (square cells).
///
/// Each cell shows the standard deviation along the worst direction of where a
/// fixed ray (the one the estimate maps to the cell's centre) lands in the image:
/// the square root of the largest eigenvalue of J_g Σ_θ J_gᵀ, J_g as in the
/// expected mapping error (whose square is the mean over the grid of the trace,
/// the sum of both eigenvalues).
pub fn projection_uncertainty_map(
    k: &Intrinsics,
    sigma: &DMatrix<f64>,
    width: u32,
    height: u32,
    columns: usize,
) -> UncertaintyMap {
    let columns = columns.max(1);
    let rows = ((columns as f64 * height as f64 / width.max(1) as f64).round() as usize).max(1);
    let mut map = UncertaintyMap {
        width,
        height,
        columns,
        rows,
        sigma_px: Vec::with_capacity(columns * rows),
    };
    for r in 0..rows {
        for c in 0..columns {
            let px = map.centre(c, r);
            // The closed-form derivatives: one projection per cell.
            let value = k
                .unproject(&px)
                .and_then(|ray| k.project_with_derivatives(&ray))
                .map(|d| d.d_params)
                .map(|j| {
                    let s = propagate(&j, sigma);
                    s.symmetric_eigenvalues().max().max(0.0).sqrt()
                })
                .unwrap_or(f64::NAN);
            map.sigma_px.push(value);
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::metrics::{mapping_error, mapping_error_rot};
    use nalgebra::Rotation3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use std::sync::LazyLock;

    /// Step of the central differences in the virtual rotation, radians.
    const ROTATION_STEP: f64 = 1e-6;

    /// K = ∂project_θ(R(ω)·ray)/∂ω at ω = 0 (2 × 3), by central differences.
    fn rotation_jacobian(k: &Intrinsics, ray: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        // The six rotations are the same for every ray: made once.
        static STEPS: LazyLock<[(Rotation3<f64>, Rotation3<f64>); 3]> = LazyLock::new(|| {
            std::array::from_fn(|a| {
                let mut w = Vector3::zeros();
                w[a] = ROTATION_STEP;
                (
                    Rotation3::from_scaled_axis(w),
                    Rotation3::from_scaled_axis(-w),
                )
            })
        });
        let mut out = Matrix2x3::zeros();
        for (a, (plus, minus)) in STEPS.iter().enumerate() {
            let plus = k.project(&(plus * ray))?;
            let minus = k.project(&(minus * ray))?;
            out.set_column(a, &((plus - minus) / (2.0 * ROTATION_STEP)));
        }
        Some(out)
    }

    fn lens() -> Intrinsics {
        Intrinsics::radial3([1000.0, 1002.0, 320.0, 240.0, -0.2, 0.1, -0.02])
    }

    /// A covariance with strong correlations, as a calibration's has.
    fn covariance() -> DMatrix<f64> {
        let a = DMatrix::from_fn(7, 7, |i, j| ((i * 7 + j) as f64 * 0.37).sin());
        let scale = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
            0.8, 0.8, 0.5, 0.5, 1e-3, 2e-3, 2e-3,
        ]));
        let correlated = &a * a.transpose() / 7.0 + DMatrix::identity(7, 7) * 0.05;
        &scale * correlated * &scale
    }

    #[test]
    fn expected_mapping_error_matches_sampled_intrinsics() {
        // Draw intrinsics from N(θ, Σ) and measure their mapping error to θ: the
        // RMS over the draws is what the formula predicts, plain and rotated.
        let (k, sigma) = (lens(), covariance());
        let u = sigma.clone().cholesky().unwrap().l();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut plain, mut rot, n) = (0.0, 0.0, 400);
        for _ in 0..n {
            let z = nalgebra::DVector::from_fn(7, |_, _| StandardNormal.sample(&mut rng));
            let d = &u * z;
            let mut b = k;
            for (i, p) in b.params_mut().iter_mut().enumerate() {
                *p += d[i];
            }
            plain += mapping_error(&k, &b, 640, 480).powi(2);
            rot += mapping_error_rot(&k, &b, 640, 480).powi(2);
        }
        let (plain, rot) = ((plain / n as f64).sqrt(), (rot / n as f64).sqrt());
        let e = camera_uncertainty(&k, &[true; 7], &sigma, 640, 480).unwrap();
        assert!(plain > 0.1 && rot < 0.8 * plain, "{plain} {rot}");
        for (predicted, sampled) in [
            (e.expected_mapping_error_px, plain),
            (e.expected_mapping_error_rot_px, rot),
        ] {
            // 400 draws: the sampled RMS is within a few percent of its expectation.
            assert!(
                (predicted / sampled - 1.0).abs() < 0.08,
                "{predicted} vs {sampled}"
            );
        }
        assert_eq!(e.intrinsics_std[0].0, "fx");
        assert!((e.intrinsics_std[4].1 - sigma[(4, 4)].sqrt()).abs() < 1e-15);
    }

    #[test]
    fn jacobian_rows_are_the_plain_central_differences() {
        // The affine shortcut for fx, fy, cx, cy must give the central
        // differences of whole projections to the bit, for every lens model.
        for model in LensModel::ALL {
            let k = Intrinsics::from_params(model, model.info().synthetic).unwrap();
            for ray in [
                Vector3::new(0.0, 0.0, 1.0),
                Vector3::new(0.21, -0.13, 1.0),
                Vector3::new(-0.33, 0.27, 0.9),
            ] {
                let got = jacobian_rows(&k, &ray).unwrap();
                for (i, p) in k.params().iter().enumerate() {
                    let h = PARAM_STEP * p.abs().max(1.0);
                    let (mut plus, mut minus) = (k, k);
                    plus.params_mut()[i] += h;
                    minus.params_mut()[i] -= h;
                    let d =
                        (plus.project(&ray).unwrap() - minus.project(&ray).unwrap()) / (2.0 * h);
                    assert_eq!([got[0][i], got[1][i]], [d.x, d.y], "{model:?} {i} {ray:?}");
                }
            }
        }
    }

    #[test]
    fn remembered_forms_are_the_computed_ones() {
        // More cameras than are kept, asked from several threads at once, twice
        // each: every answer is the fresh computation's, bit for bit, and a
        // camera one ulp away from another gets its own.
        let cameras: Vec<Intrinsics> = (0..FORMS_KEPT + 4)
            .map(|i| {
                let mut k = lens();
                k.params_mut()[4] = -0.2 + 0.01 * i as f64;
                k
            })
            .chain(std::iter::once({
                let mut k = lens();
                k.params_mut()[0] = f64::from_bits(k.params()[0].to_bits() + 1);
                k
            }))
            .collect();
        let fresh: Vec<_> = cameras
            .iter()
            .map(|k| compute_mapping_forms(k, 320, 240))
            .collect();
        std::thread::scope(|s| {
            for t in 0..3 {
                let (cameras, fresh) = (&cameras, &fresh);
                s.spawn(move || {
                    for round in 0..2 {
                        for i in 0..cameras.len() {
                            let i = (i + 7 * t + round) % cameras.len();
                            let got = mapping_forms(&cameras[i], 320, 240);
                            assert!(got.is_some());
                            assert_eq!(got, fresh[i], "camera {i}");
                        }
                    }
                });
            }
        });
        let (h, _, _) = mapping_forms(&lens(), 320, 240).unwrap();
        let (h_ulp, _, _) = mapping_forms(cameras.last().unwrap(), 320, 240).unwrap();
        assert_eq!(h_ulp, fresh.last().unwrap().as_ref().unwrap().0);
        assert_ne!(h, h_ulp);
    }

    #[test]
    fn map_of_a_focal_length_error_grows_from_the_centre() {
        // Only fx uncertain (σ 1 px) without distortion: a ray at u lands off by
        // σ·(u − cx)/fx, zero on the column through cx.
        let k = Intrinsics::pinhole(1000.0, 1000.0, 320.0, 240.0);
        let mut sigma = DMatrix::zeros(7, 7);
        sigma[(0, 0)] = 1.0;
        let map = projection_uncertainty_map(&k, &sigma, 640, 480, 16);
        assert_eq!((map.columns, map.rows), (16, 12));
        for r in 0..map.rows {
            for c in 0..map.columns {
                let expected = (map.centre(c, r).x - 320.0).abs() / 1000.0;
                let got = map.sigma_px[r * map.columns + c];
                assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
            }
        }
        // The expected mapping error is then that of a 1 px change of fx.
        let e = camera_uncertainty(&k, &[true; 7], &sigma, 640, 480).unwrap();
        let one_px = mapping_error(&k, &k.with_param("fx", 1001.0), 640, 480);
        assert!((e.expected_mapping_error_px / one_px - 1.0).abs() < 1e-6);
        // fx's change is no rotation: profiling one out barely helps.
        assert!(e.expected_mapping_error_rot_px > 0.5 * one_px);
    }

    /// [`compute_mapping_forms`] as it was computed before the closed-form
    /// derivatives: J by `jacobian_rows`' central differences, R by central
    /// differences in the rotation.
    fn forms_by_differences(k: &Intrinsics, width: u32, height: u32) -> MappingForms {
        let n = k.params().len();
        let (mut h, mut c) = (DMatrix::<f64>::zeros(n, n), DMatrix::<f64>::zeros(n, 3));
        let mut kk = Matrix3::<f64>::zeros();
        let mut m = 0;
        for (_, ray) in grid_rays(k, width, height) {
            let (Some(j), Some(r)) = (jacobian_rows(k, &ray), rotation_jacobian(k, &ray)) else {
                continue;
            };
            let j = DMatrix::from_fn(2, n, |a, b| j[a][b]);
            let r = DMatrix::from_column_slice(2, 3, r.as_slice());
            h += j.transpose() * &j;
            c += j.transpose() * &r;
            kk += Matrix3::from_column_slice((r.transpose() * &r).as_slice());
            m += 1;
        }
        let kk_inv = DMatrix::from_column_slice(3, 3, kk.try_inverse().unwrap().as_slice());
        let h_rot = &h - &c * kk_inv * c.transpose();
        (h, h_rot, m)
    }

    #[test]
    fn closed_form_figures_are_the_central_differences_ones() {
        // The expected mapping errors (plain and rotated) from the closed-form
        // forms against those of the central differences, for every lens model
        // and several covariances (diagonal and strongly correlated, each
        // parameter's σ on its own scale): equal to 1e-6 relative.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut worst: f64 = 0.0;
        for model in LensModel::ALL {
            let k = Intrinsics::from_params(model, model.info().synthetic).unwrap();
            let n = k.params().len();
            let (width, height) = (640, 480);
            let (h, h_rot, m) = compute_mapping_forms(&k, width, height).unwrap();
            let (dh, dh_rot, dm) = forms_by_differences(&k, width, height);
            assert_eq!(m, dm, "{model:?}");
            for draw in 0..4 {
                let scale = DMatrix::from_diagonal(&nalgebra::DVector::from_fn(n, |i, _| {
                    1e-3 * k.params()[i].abs().max(1e-2)
                }));
                let a = DMatrix::<f64>::from_fn(n, n, |_, _| StandardNormal.sample(&mut rng));
                let correlated = if draw == 0 {
                    DMatrix::identity(n, n)
                } else {
                    &a * a.transpose() / n as f64 + DMatrix::identity(n, n) * 0.01
                };
                let sigma = &scale * correlated * &scale;
                let figure = |form: &DMatrix<f64>| ((form * &sigma).trace() / m as f64).sqrt();
                for (closed, differences) in [(&h, &dh), (&h_rot, &dh_rot)] {
                    let (x, y) = (figure(closed), figure(differences));
                    assert!(x > 0.0 && y > 0.0, "{model:?}: {x} {y}");
                    let rel = (x / y - 1.0).abs();
                    assert!(rel <= 1e-6, "{model:?} draw {draw}: {x} against {y}");
                    worst = worst.max(rel);
                }
            }
        }
        eprintln!("closed form against central differences: worst relative change {worst:.1e}");
    }
}
