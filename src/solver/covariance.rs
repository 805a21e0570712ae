//! The covariance of a solved problem's intrinsics (docs/conventions.md §3a) from the Jacobian
//! at its optimum, at unit noise; `solver::uncertainty` scales it to a
//! calibration's noise and `model::uncertainty` turns it into pixels.
//!
//! The gauge is fixed by the parameterisation: held corners have no Jacobian
//! column, so JᵀJ is regular for a well-posed problem and is inverted as it is,
//! never pseudo-inverted. Σ_θ and the board's σ come out of one pass
//! ([`unit_covariance`]), so that the Jacobian at the optimum (at 650 images
//! a third of the board's σ) and H are computed once per calibration. For both, the
//! per-image blocks (pose, bend) or the per-corner corrections, whichever leaves
//! fewer parameters, are eliminated by a Schur complement, as Ceres' solver
//! does; for the corrections' marginal information the per-image blocks are.
//! The reduced system is dense.
//!
//! The robust loss enters as fixed weights: with w = ρ'(‖r‖²) per observation the
//! fit solves the weighted normal equations H = JᵀWJ, so an estimate moves by
//! H⁻¹JᵀW·noise and Σ_θ = σ̂² [H⁻¹ (JᵀW²J) H⁻¹]_θθ; without a loss (W = I) this is
//! σ̂² [(JᵀJ)⁻¹]_θθ, and a uniform weight cancels.
use crate::model::state::Layout;
use crate::model::uncertainty::{IntrinsicsCovariance, UncertaintyError, UnitCovariance};
use crate::solver::problem::{Evaluation, Problem, SolverSettings, State};
use nalgebra::DMatrix;
use normal::{
    add_lens_prior, backward, check_shape, cholesky, column_scales, describe, dot, eliminate,
    forward, jacobi_scale, jacobi_scales, keeps_corrections, loss_weights, normal_matrices,
    normal_matrix, scale_normal, schur, Eliminate, Normal, Role,
};

mod board_std;
mod normal;
pub use normal::jacobian;

/// X = H⁻¹ E for the unit vectors E of the `targets` columns (all kept): one
/// row of `targets.len()` values per column of the Jacobian, in its units.
fn solve_columns(n: &Normal, scale: &[f64], targets: &[usize]) -> Vec<f64> {
    let (kk, t) = (n.a.nrows(), targets.len());
    // The factor L is stored row-major in `a`; backward substitution reads it by
    // columns, which Lᵀ stored row-major (a's transpose) holds by rows.
    let l = n.a.as_slice();
    let lt = n.a.transpose();
    let lt = lt.as_slice();
    let mut kept_x = DMatrix::zeros(kk, t);
    for (u, &col) in targets.iter().enumerate() {
        let Role::Kept(k) = n.roles[col] else {
            unreachable!("intrinsics are never eliminated")
        };
        let rhs = kept_x.column_mut(u);
        let rhs = rhs.data.into_slice_mut();
        rhs[k] = scale[col];
        forward(l, kk, rhs);
        for i in (0..kk).rev() {
            let row = &lt[i * kk..(i + 1) * kk];
            rhs[i] = (rhs[i] - dot(&row[i + 1..], &rhs[i + 1..])) / row[i];
        }
    }
    // x_g = −L⁻ᵀ (L⁻¹Bᵀ) x_kept for every eliminated block at once.
    let mut eliminated_x = -(&n.bt * &kept_x);
    let ne = n.bt.nrows();
    for (g, &(start, m)) in n.groups.iter().enumerate() {
        for column in eliminated_x.as_mut_slice().chunks_exact_mut(ne) {
            backward(&n.d[g], m, &mut column[start..start + m]);
        }
    }
    let mut x = vec![0.0; n.roles.len() * t];
    for (col, role) in n.roles.iter().enumerate() {
        let row = match *role {
            Role::Kept(k) => kept_x.row(k),
            Role::Eliminated { index, .. } => eliminated_x.row(index),
        };
        for (u, v) in row.iter().enumerate() {
            x[col * t + u] = scale[col] * v;
        }
    }
    x
}

/// The loss's weights and H = JᵀWJ with the lens prior's information, from the
/// Jacobian at the optimum: what the corrections' information starts from.
fn weighted_normal_of(
    e: &Evaluation,
    problem: &Problem,
    settings: &SolverSettings,
    eliminate: Eliminate,
) -> Result<(Vec<f64>, Normal), UncertaintyError> {
    check_shape(e, problem)?;
    let weights = loss_weights(problem.dataset, settings, &e.residuals);
    let mut n = normal_matrix(e, &problem.layout(), &weights, eliminate)?;
    add_lens_prior(&mut n, &problem.lens_prior_weights(settings));
    Ok((weights, n))
}

/// Σ_θ of every camera at unit noise, from the Jacobian of `problem` at `state`
/// (its optimum) with the loss of `settings`, and the board's σ when the
/// normal matrix keeps the static corrections. One pass: the Jacobian, the
/// loss weights, H and its Jacobi scaling, Schur complement and Cholesky
/// factor serve both. The Jacobian (at 10 000 images, 1.7 million
/// observations) is freed before the board's part allocates its matrices, and
/// nothing of the pass but its results is kept.
pub fn unit_covariance(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
) -> Result<UnitCovariance, UncertaintyError> {
    let d = problem.dataset;
    let layout = problem.layout();
    let e = jacobian(problem, state, settings)?;
    check_shape(&e, problem)?;
    let weights = loss_weights(d, settings, &e.residuals);
    // The board's noise term G = JᵀW²J is built beside H, in the same pass over
    // the Jacobian's rows, only when the corrections stay in the dense system.
    let (mut h, mut g) = if keeps_corrections(&e, &layout) {
        let squared: Vec<f64> = weights.iter().map(|w| w * w).collect();
        let [h, g] = normal_matrices(&e, &layout, [&weights, &squared], Eliminate::Smaller)?;
        (h, Some(g))
    } else {
        let [h] = normal_matrices(&e, &layout, [&weights], Eliminate::Smaller)?;
        (h, None)
    };
    add_lens_prior(&mut h, &problem.lens_prior_weights(settings));
    // G is scaled by H's scales D: (DHD)⁻¹ (DGD) (DHD)⁻¹ = D⁻¹ Σ D⁻¹.
    let (kept, eliminated) = jacobi_scales(d, &layout, &h)?;
    scale_normal(&mut h, &kept, &eliminated);
    if let Some(g) = g.as_mut() {
        scale_normal(g, &kept, &eliminated);
    }
    let scale = column_scales(&h, &kept, &eliminated);
    eliminate(d, &layout, &mut h)?;
    let targets: Vec<usize> = (0..h.params.len())
        .filter(|&col| h.params[col] < layout.intrinsics_len())
        .collect();
    let x = solve_columns(&h, &scale, &targets);
    let sigma = sandwich(&e, &weights, &x, targets.len());
    drop(e);
    let cameras = per_camera(&layout, &h.params, &targets, &sigma);
    let correction_std = g.map(|g| board_std::correction_std(d, &layout, &h, g, &kept));
    Ok(UnitCovariance {
        cameras,
        correction_std,
    })
}

/// (WJX)ᵀ(WJX), t × t, with X given per Jacobian column (t values each): the
/// rows of WJX made first (one column of t values per Jacobian row), then one
/// matrix product.
fn sandwich(e: &Evaluation, weights: &[f64], x: &[f64], t: usize) -> DMatrix<f64> {
    let mut y = DMatrix::<f64>::zeros(t, e.jacobian_rows);
    for (r, column) in y.as_mut_slice().chunks_exact_mut(t.max(1)).enumerate() {
        for i in e.jacobian_row_ptr[r] as usize..e.jacobian_row_ptr[r + 1] as usize {
            let (col, v) = (e.jacobian_col_idx[i] as usize, e.jacobian_values[i]);
            // Over slices, so that it vectorises.
            for (yu, xu) in column.iter_mut().zip(&x[col * t..(col + 1) * t]) {
                *yu += v * xu;
            }
        }
        let w = weights[r / 2];
        column.iter_mut().for_each(|v| *v *= w);
    }
    &y * y.transpose()
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

/// The static corrections' marginal information at unit noise, with each
/// row's index in the parameter buffer: the inverse of their covariance block
/// with everything else free (the intrinsics above all, which they trade off
/// against), i.e. the Schur complement of JᵀWJ onto them. The per-image blocks
/// (pose, bend) are eliminated first, so the dense system is the corrections
/// and the intrinsics (about 500 values for a 13 × 13 board) whatever the
/// number of images; then the intrinsics (and camera poses) are.
pub fn unit_correction_information(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
) -> Result<(Vec<usize>, DMatrix<f64>), UncertaintyError> {
    unit_correction_information_of(&jacobian(problem, state, settings)?, problem, settings)
}

/// [`unit_correction_information`] from the Jacobian [`jacobian`] gave.
pub fn unit_correction_information_of(
    e: &Evaluation,
    problem: &Problem,
    settings: &SolverSettings,
) -> Result<(Vec<usize>, DMatrix<f64>), UncertaintyError> {
    let d = problem.dataset;
    let layout = problem.layout();
    let (_, mut n) = weighted_normal_of(e, problem, settings, Eliminate::Frames)?;
    let scale = jacobi_scale(d, &layout, &mut n)?;
    schur(d, &layout, &mut n)?;
    let (c, o): (Vec<usize>, Vec<usize>) =
        (0..n.a.nrows()).partition(|&k| n.params[n.kept_columns[k]] >= layout.corrections);
    if c.is_empty() {
        return Err(UncertaintyError::Jacobian(
            "the problem has no free static correction".into(),
        ));
    }
    let mut info = n.a.select_rows(&c).select_columns(&c);
    if !o.is_empty() {
        // S_cc − S_co S_oo⁻¹ S_oc = S_cc − YᵀY with Y = L⁻¹ S_oc, S_oo = LLᵀ.
        let mut l = n.a.select_rows(&o).select_columns(&o);
        cholesky(l.as_mut_slice(), o.len()).map_err(|k| {
            UncertaintyError::RankDeficient(describe(d, &layout, n.params[n.kept_columns[o[k]]]))
        })?;
        let mut y = n.a.select_rows(&o).select_columns(&c);
        for column in y.as_mut_slice().chunks_exact_mut(o.len()) {
            forward(l.as_slice(), o.len(), column);
        }
        info.gemm(-1.0, &y.transpose(), &y, 1.0);
    }
    // Undo the Jacobi scaling: H was scaled to D H D, its Schur complements alike.
    let s: Vec<f64> = c.iter().map(|&k| scale[n.kept_columns[k]]).collect();
    for (j, mut column) in info.column_iter_mut().enumerate() {
        for (i, v) in column.iter_mut().enumerate() {
            *v /= s[i] * s[j];
        }
    }
    let params = c.iter().map(|&k| n.params[n.kept_columns[k]]).collect();
    Ok((params, info))
}
