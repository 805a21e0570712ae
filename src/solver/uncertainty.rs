//! The covariance of a finished calibration's intrinsics (SPEC §3a) from the
//! Jacobian at its optimum, and the uncertainty figures at the calibration's noise
//! σ̂ (`model::uncertainty` turns Σ_θ into pixels).
//!
//! The gauge is fixed by the parameterisation: held corners have no Jacobian
//! column, so JᵀJ is regular for a well-posed problem and is inverted as it is,
//! never pseudo-inverted. The per-image blocks (pose, bend) or the per-corner
//! corrections, whichever leaves fewer parameters, are eliminated by a Schur
//! complement, as Ceres' solver does; the reduced system is dense.
//!
//! The robust loss enters as fixed weights: with w = ρ'(‖r‖²) per observation the
//! fit solves the weighted normal equations H = JᵀWJ, so an estimate moves by
//! H⁻¹JᵀW·noise and Σ_θ = σ̂² [H⁻¹ (JᵀW²J) H⁻¹]_θθ; without a loss (W = I) this is
//! σ̂² [(JᵀJ)⁻¹]_θθ, and a uniform weight cancels.
use crate::model::state::{Layout, CORRECTION_STRIDE, POSE_PARAMS};
use crate::model::uncertainty::{
    camera_uncertainty, CameraUncertainty, IntrinsicsCovariance, UncertaintyError, MAX_REDUCED,
};
use crate::solver::calibrate::Calibration;
use crate::solver::problem::{Evaluation, Loss};
use nalgebra::DMatrix;
use std::collections::HashMap;

/// A diagonal pivot of the Jacobi-scaled normal matrix below this marks a
/// direction the data do not determine: its parameter is then a combination of
/// the others to a relative 1e-5 (round-off leaves about 1e-16 in a true null
/// direction; a weak but real one, such as k3 against k1 and k2, stays far above).
const MIN_PIVOT: f64 = 1e-10;

/// Where a Jacobian column goes: the dense reduced system, or a block eliminated first.
#[derive(Debug, Clone, Copy)]
enum Role {
    Kept(usize),
    Eliminated { group: usize, local: usize },
}

/// One eliminated block: its normal matrix D and its coupling B to the kept
/// parameters it touches (row-major, `touched.len()` × size).
#[derive(Debug, Clone, Default)]
struct Group {
    size: usize,
    d: Vec<f64>,
    touched: Vec<usize>,
    position: HashMap<usize, usize>,
    b: Vec<f64>,
}

impl Group {
    fn row(&mut self, kept: usize) -> usize {
        let next = self.touched.len();
        let size = self.size;
        *self.position.entry(kept).or_insert_with(|| {
            self.touched.push(kept);
            self.b.extend(std::iter::repeat_n(0.0, size));
            next
        })
    }
}

/// The normal matrix JᵀWJ in block-arrow form, and what its columns are.
struct Normal {
    roles: Vec<Role>,
    /// Per column: the value it differentiates (its index in the parameter buffer).
    params: Vec<usize>,
    /// Per kept index: its column.
    kept_columns: Vec<usize>,
    a: DMatrix<f64>,
    groups: Vec<Group>,
}

/// The group of a buffer index when per-image blocks (`frames`) or per-corner
/// corrections are eliminated; `None` for a kept value.
fn group_of(layout: &Layout, index: usize, frames: bool) -> Option<usize> {
    if frames && (layout.frames..layout.corrections).contains(&index) {
        Some((index - layout.frames) / layout.frame_stride)
    } else if !frames && index >= layout.corrections {
        Some((index - layout.corrections) / CORRECTION_STRIDE)
    } else {
        None
    }
}

/// The roles of the columns: eliminate whichever of the per-image and per-corner
/// blocks leaves the smaller reduced system.
fn roles(layout: &Layout, params: &[usize]) -> (Vec<Role>, usize, Vec<usize>) {
    let in_frames = params
        .iter()
        .filter(|&&p| group_of(layout, p, true).is_some())
        .count();
    let in_corners = params
        .iter()
        .filter(|&&p| group_of(layout, p, false).is_some())
        .count();
    let frames = in_corners == 0 || in_frames >= in_corners;
    let (mut roles, mut kept_columns) = (Vec::with_capacity(params.len()), Vec::new());
    let mut groups: HashMap<usize, usize> = HashMap::new();
    let mut sizes = Vec::new();
    for (column, &p) in params.iter().enumerate() {
        roles.push(match group_of(layout, p, frames) {
            None => {
                kept_columns.push(column);
                Role::Kept(kept_columns.len() - 1)
            }
            Some(g) => {
                let next = sizes.len();
                let group = *groups.entry(g).or_insert(next);
                if group == sizes.len() {
                    sizes.push(0);
                }
                sizes[group] += 1;
                Role::Eliminated {
                    group,
                    local: sizes[group] - 1,
                }
            }
        });
    }
    (roles, kept_columns.len(), sizes)
}

/// JᵀWJ from a CRS Jacobian with one weight per pair of rows (per observation).
fn normal_matrix(
    e: &Evaluation,
    layout: &Layout,
    weights: &[f64],
) -> Result<Normal, UncertaintyError> {
    let params: Vec<usize> = e.jacobian_col_param.iter().map(|&p| p as usize).collect();
    let (roles, kept, sizes) = roles(layout, &params);
    if kept > MAX_REDUCED {
        return Err(UncertaintyError::TooLarge(kept));
    }
    let mut n = Normal {
        kept_columns: (0..params.len())
            .filter(|&c| matches!(roles[c], Role::Kept(_)))
            .collect(),
        roles,
        params,
        a: DMatrix::zeros(kept, kept),
        groups: sizes
            .iter()
            .map(|&s| Group {
                size: s,
                d: vec![0.0; s * s],
                ..Group::default()
            })
            .collect(),
    };
    let (mut k_entries, mut e_entries) = (Vec::new(), Vec::new());
    for r in 0..e.jacobian_rows {
        let w = weights[r / 2];
        k_entries.clear();
        e_entries.clear();
        let (lo, hi) = (
            e.jacobian_row_ptr[r] as usize,
            e.jacobian_row_ptr[r + 1] as usize,
        );
        for i in lo..hi {
            let v = e.jacobian_values[i];
            match n.roles[e.jacobian_col_idx[i] as usize] {
                Role::Kept(k) => k_entries.push((k, v)),
                Role::Eliminated { group, local } => e_entries.push((group, local, v)),
            }
        }
        accumulate(&mut n, w, &k_entries, &e_entries)?;
    }
    Ok(n)
}

/// Adds one weighted Jacobian row's outer product to the block-arrow normal matrix.
fn accumulate(
    n: &mut Normal,
    w: f64,
    kept: &[(usize, f64)],
    eliminated: &[(usize, usize, f64)],
) -> Result<(), UncertaintyError> {
    for &(i, vi) in kept {
        for &(j, vj) in kept {
            n.a[(i, j)] += w * vi * vj;
        }
    }
    let Some(&(g, _, _)) = eliminated.first() else {
        return Ok(());
    };
    if eliminated.iter().any(|&(h, _, _)| h != g) {
        return Err(UncertaintyError::Jacobian(
            "a residual depends on two eliminated blocks".into(),
        ));
    }
    let group = &mut n.groups[g];
    let m = group.size;
    for &(_, a, va) in eliminated {
        for &(_, b, vb) in eliminated {
            group.d[a * m + b] += w * va * vb;
        }
    }
    for &(i, vi) in kept {
        let row = group.row(i);
        for &(_, a, va) in eliminated {
            group.b[row * m + a] += w * vi * va;
        }
    }
    Ok(())
}

/// In-place lower Cholesky factor of a symmetric m × m row-major matrix; `Err(i)`
/// at the first pivot below [`MIN_PIVOT`] (the matrix is Jacobi-scaled, unit diagonal).
fn cholesky(a: &mut [f64], m: usize) -> Result<(), usize> {
    for j in 0..m {
        let mut d = a[j * m + j];
        for k in 0..j {
            d -= a[j * m + k] * a[j * m + k];
        }
        if !(d > MIN_PIVOT) {
            return Err(j);
        }
        let d = d.sqrt();
        a[j * m + j] = d;
        for i in j + 1..m {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= a[i * m + k] * a[j * m + k];
            }
            a[i * m + j] = s / d;
        }
        for i in 0..j {
            a[i * m + j] = 0.0;
        }
    }
    Ok(())
}

/// Solves L y = b in place (L lower, row-major m × m).
fn forward(l: &[f64], m: usize, b: &mut [f64]) {
    for i in 0..m {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * m + k] * b[k];
        }
        b[i] = s / l[i * m + i];
    }
}

/// Solves Lᵀ x = y in place.
fn backward(l: &[f64], m: usize, y: &mut [f64]) {
    for i in (0..m).rev() {
        let mut s = y[i];
        for k in i + 1..m {
            s -= l[k * m + i] * y[k];
        }
        y[i] = s / l[i * m + i];
    }
}

/// What a buffer index is, in words, for a message.
fn describe(c: &Calibration, layout: &Layout, index: usize) -> String {
    let d = &c.dataset;
    if index < layout.intrinsics_len() {
        let k = layout
            .intrinsics_offsets
            .iter()
            .rposition(|&o| o <= index)
            .unwrap_or(0);
        let name = layout.lens_models[k].param_names()[index - layout.intrinsics_offsets[k]];
        format!("{name} of camera {}", d.cameras[k].name)
    } else if index < layout.frames {
        let k = (index - layout.camera_poses) / POSE_PARAMS;
        format!("the pose of camera {}", d.cameras[k].name)
    } else if index < layout.corrections {
        let j = (index - layout.frames) / layout.frame_stride;
        let what = if (index - layout.frames) % layout.frame_stride < POSE_PARAMS {
            "board pose"
        } else {
            "bend"
        };
        format!("the {what} of frame {}", d.frame_ids[j])
    } else {
        let i = (index - layout.corrections) / CORRECTION_STRIDE;
        format!("the correction of corner {i}")
    }
}

/// Scales the normal matrix to a unit diagonal (its pivots then compare with
/// [`MIN_PIVOT`] whatever the parameters' units); returns the column scales.
fn jacobi_scale(
    c: &Calibration,
    layout: &Layout,
    n: &mut Normal,
) -> Result<Vec<f64>, UncertaintyError> {
    let mut scale = vec![0.0; n.roles.len()];
    for (col, role) in n.roles.iter().enumerate() {
        let diag = match *role {
            Role::Kept(k) => n.a[(k, k)],
            Role::Eliminated { group, local } => {
                let g = &n.groups[group];
                g.d[local * g.size + local]
            }
        };
        if !(diag > 0.0 && diag.is_finite()) {
            return Err(UncertaintyError::RankDeficient(describe(
                c,
                layout,
                n.params[col],
            )));
        }
        scale[col] = 1.0 / diag.sqrt();
    }
    let kept: Vec<f64> = n.kept_columns.iter().map(|&col| scale[col]).collect();
    let kk = kept.len();
    for j in 0..kk {
        for i in 0..kk {
            n.a[(i, j)] *= kept[i] * kept[j];
        }
    }
    let mut local_scale: Vec<Vec<f64>> = n.groups.iter().map(|g| vec![0.0; g.size]).collect();
    for (col, role) in n.roles.iter().enumerate() {
        if let Role::Eliminated { group, local } = *role {
            local_scale[group][local] = scale[col];
        }
    }
    for (g, s) in n.groups.iter_mut().zip(&local_scale) {
        let m = g.size;
        for a in 0..m {
            for b in 0..m {
                g.d[a * m + b] *= s[a] * s[b];
            }
        }
        for (row, &k) in g.touched.iter().enumerate() {
            for a in 0..m {
                g.b[row * m + a] *= kept[k] * s[a];
            }
        }
    }
    Ok(scale)
}

/// The columns of each group, by local index.
fn group_columns(n: &Normal) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = n.groups.iter().map(|g| vec![0; g.size]).collect();
    for (col, role) in n.roles.iter().enumerate() {
        if let Role::Eliminated { group, local } = *role {
            out[group][local] = col;
        }
    }
    out
}

/// Eliminates every group: factors D = LLᵀ in place, turns B into M = B L⁻ᵀ and
/// subtracts M Mᵀ from the kept block, leaving the Schur complement there; then
/// factors that too.
fn eliminate(c: &Calibration, layout: &Layout, n: &mut Normal) -> Result<(), UncertaintyError> {
    let columns = group_columns(n);
    for (g, group) in n.groups.iter_mut().enumerate() {
        let m = group.size;
        cholesky(&mut group.d, m).map_err(|l| {
            UncertaintyError::RankDeficient(describe(c, layout, n.params[columns[g][l]]))
        })?;
        for row in group.b.chunks_exact_mut(m) {
            forward(&group.d, m, row);
        }
        let t = group.touched.len();
        let mm = DMatrix::from_row_slice(t, m, &group.b);
        let product = &mm * mm.transpose();
        for (q, &kq) in group.touched.iter().enumerate() {
            for (p, &kp) in group.touched.iter().enumerate() {
                n.a[(kp, kq)] -= product[(p, q)];
            }
        }
    }
    let kk = n.a.nrows();
    // Symmetric, so the column-major storage reads as row-major.
    cholesky(n.a.as_mut_slice(), kk).map_err(|k| {
        UncertaintyError::RankDeficient(describe(c, layout, n.params[n.kept_columns[k]]))
    })
}

/// X = H⁻¹ E for the unit vectors E of the `targets` columns (all kept): one
/// row of `targets.len()` values per column of the Jacobian, in its units.
fn solve_columns(n: &Normal, scale: &[f64], targets: &[usize]) -> Vec<f64> {
    let (kk, t) = (n.a.nrows(), targets.len());
    let l = n.a.as_slice();
    let mut x = vec![0.0; n.roles.len() * t];
    let mut kept_x = vec![0.0; kk * t];
    for (u, &col) in targets.iter().enumerate() {
        let Role::Kept(k) = n.roles[col] else {
            unreachable!("intrinsics are never eliminated")
        };
        let mut rhs = vec![0.0; kk];
        rhs[k] = scale[col];
        forward(l, kk, &mut rhs);
        backward(l, kk, &mut rhs);
        for (i, v) in rhs.into_iter().enumerate() {
            kept_x[i * t + u] = v;
        }
    }
    for (i, &col) in n.kept_columns.iter().enumerate() {
        for u in 0..t {
            x[col * t + u] = scale[col] * kept_x[i * t + u];
        }
    }
    let columns = group_columns(n);
    for (g, group) in n.groups.iter().enumerate() {
        let m = group.size;
        for u in 0..t {
            // x_g = −L⁻ᵀ Mᵀ x_touched.
            let mut y = vec![0.0; m];
            for (row, &k) in group.touched.iter().enumerate() {
                for a in 0..m {
                    y[a] -= group.b[row * m + a] * kept_x[k * t + u];
                }
            }
            backward(&group.d, m, &mut y);
            for (a, v) in y.into_iter().enumerate() {
                let col = columns[g][a];
                x[col * t + u] = scale[col] * v;
            }
        }
    }
    x
}

/// The robust loss' weight ρ'(‖r‖²) of each observation (1 without a loss).
fn loss_weights(c: &Calibration, residuals: &[f64]) -> Vec<f64> {
    let a2 = c.settings.loss_scale_px * c.settings.loss_scale_px;
    c.dataset
        .observations
        .iter()
        .zip(residuals.chunks_exact(2))
        .map(|(o, r)| match c.settings.loss {
            Loss::None => 1.0,
            Loss::Cauchy => {
                let s = (r[0] * r[0] + r[1] * r[1]) * o.weight * o.weight;
                1.0 / (1.0 + s / a2)
            }
        })
        .collect()
}

/// Σ_θ of every camera at unit noise, from the Jacobian at the calibration's
/// optimum; [`Calibration::covariance`] holds it after every calibration.
pub fn unit_covariance(c: &Calibration) -> Result<Vec<IntrinsicsCovariance>, UncertaintyError> {
    let problem = c.problem();
    let layout = problem.layout();
    let e = problem
        .evaluate(&c.state, &c.settings, true)
        .map_err(|e| UncertaintyError::Jacobian(e.to_string()))?;
    let rows = 2 * c.dataset.observations.len();
    if e.jacobian_rows != rows
        || e.jacobian_row_ptr.len() != rows + 1
        || e.jacobian_col_param.len() != e.jacobian_cols
    {
        return Err(UncertaintyError::Jacobian(format!(
            "{} × {} with {} column labels for {rows} residuals",
            e.jacobian_rows,
            e.jacobian_cols,
            e.jacobian_col_param.len()
        )));
    }
    let weights = loss_weights(c, &e.residuals);
    let mut n = normal_matrix(&e, &layout, &weights)?;
    let scale = jacobi_scale(c, &layout, &mut n)?;
    eliminate(c, &layout, &mut n)?;
    let targets: Vec<usize> = (0..n.params.len())
        .filter(|&col| n.params[col] < layout.intrinsics_len())
        .collect();
    let x = solve_columns(&n, &scale, &targets);
    let sigma = sandwich(&e, &weights, &x, targets.len());
    Ok(per_camera(&layout, &n.params, &targets, &sigma))
}

/// (WJX)ᵀ(WJX), t × t, with X given per Jacobian column (t values each).
fn sandwich(e: &Evaluation, weights: &[f64], x: &[f64], t: usize) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(t, t);
    let mut y = vec![0.0; t];
    for r in 0..e.jacobian_rows {
        y.iter_mut().for_each(|v| *v = 0.0);
        for i in e.jacobian_row_ptr[r] as usize..e.jacobian_row_ptr[r + 1] as usize {
            let (col, v) = (e.jacobian_col_idx[i] as usize, e.jacobian_values[i]);
            for u in 0..t {
                y[u] += v * x[col * t + u];
            }
        }
        let w = weights[r / 2];
        for a in 0..t {
            for b in 0..t {
                out[(a, b)] += w * w * y[a] * y[b];
            }
        }
    }
    out
}

/// Splits Σ over all free intrinsics into each camera's n × n block.
fn per_camera(
    layout: &Layout,
    params: &[usize],
    targets: &[usize],
    sigma: &DMatrix<f64>,
) -> Vec<IntrinsicsCovariance> {
    layout
        .lens_models
        .iter()
        .zip(&layout.intrinsics_offsets)
        .map(|(model, &offset)| {
            let np = model.num_params();
            let mut cov = IntrinsicsCovariance {
                free: vec![false; np],
                unit: DMatrix::zeros(np, np),
            };
            let local = |u: usize| params[targets[u]].checked_sub(offset).filter(|&i| i < np);
            for a in 0..targets.len() {
                let Some(i) = local(a) else { continue };
                cov.free[i] = true;
                for b in 0..targets.len() {
                    if let Some(j) = local(b) {
                        cov.unit[(i, j)] = sigma[(a, b)];
                    }
                }
            }
            cov
        })
        .collect()
}

impl Calibration {
    /// Σ_θ of every camera at the calibration's noise σ̂ (the one
    /// [`Calibration::trust`] uses); rows and columns of held parameters are zero.
    pub fn intrinsics_covariance(&self) -> Result<Vec<DMatrix<f64>>, UncertaintyError> {
        let noise = self
            .trust(self.detector_noise_px)
            .ok_or(UncertaintyError::NoNoise)?
            .noise_px;
        let unit = self.covariance.as_ref().map_err(Clone::clone)?;
        Ok(unit.iter().map(|c| &c.unit * (noise * noise)).collect())
    }

    /// Every camera's uncertainty figures (SPEC §3a) at the noise σ̂.
    pub fn uncertainty(&self) -> Result<Vec<CameraUncertainty>, UncertaintyError> {
        let sigma = self.intrinsics_covariance()?;
        let unit = self.covariance.as_ref().map_err(Clone::clone)?;
        let cameras = self.dataset.cameras.iter().zip(&self.state.intrinsics);
        cameras
            .zip(unit.iter().zip(&sigma))
            .map(|((cam, k), (cov, sigma))| {
                camera_uncertainty(k, &cov.free, sigma, cam.width, cam.height).ok_or_else(|| {
                    UncertaintyError::Jacobian(format!(
                        "no pixel of camera {} has a ray to measure the mapping error on",
                        cam.name
                    ))
                })
            })
            .collect()
    }
}
