//! The board's σ for `board.json`: the marginal standard deviation of every
//! static correction value at unit noise, the diagonal of the corrections'
//! block of H⁻¹ (JᵀW²J) H⁻¹. Structured, so that it costs a few dense matrix
//! products over the intrinsics and corrections whatever the number of images:
//! the per-image blocks (pose, bend), which couple the rest only through their
//! few values, are eliminated frame by frame from H and from the noise term
//! alike, one Cholesky factor of what is left gives its inverse, and only the
//! diagonal of the product is read. The normal matrices and their
//! factorisations are `normal`'s.
use super::normal::{
    add_lens_prior, backward, check_shape, cholesky, corrections_kept, describe, dot,
    jacobi_scales, jacobian, loss_weights, normal_matrices, scale_normal, schur, Eliminate, Normal,
};
use crate::model::state::CORRECTION_STRIDE;
use crate::model::uncertainty::UncertaintyError;
use crate::solver::problem::{Problem, SolverSettings, State};
use nalgebra::DMatrix;

/// The standard deviation of every static correction value at unit noise (3 per
/// corner; 0 for a held value), with the loss of `settings` as
/// `unit_covariance` takes it; `Err` when the problem has no free
/// correction or when the corrections are the eliminated blocks (fewer values
/// in the images' blocks than in the corners', so a dataset too small to
/// measure a board anyway).
pub fn unit_correction_std(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
) -> Result<Vec<[f64; 3]>, UncertaintyError> {
    let d = problem.dataset;
    let layout = problem.layout();
    let e = jacobian(problem, state, settings)?;
    check_shape(&e, problem)?;
    let weights = loss_weights(d, settings, &e.residuals);
    let squared: Vec<f64> = weights.iter().map(|w| w * w).collect();
    // H = JᵀWJ (with the lens prior, the curvature the fit solves with) and the
    // noise term G = JᵀW²J, in one pass over the Jacobian.
    let [mut h, mut g] = normal_matrices(&e, &layout, [&weights, &squared], Eliminate::Smaller)?;
    add_lens_prior(&mut h, &problem.lens_prior_weights(settings));
    if !corrections_kept(&h, &layout) {
        return Err(UncertaintyError::Jacobian(
            "the corrections are not determined well enough for a covariance".into(),
        ));
    }
    // Both scaled by H's Jacobi scales D: (DHD)⁻¹ (DGD) (DHD)⁻¹ = D⁻¹ Σ D⁻¹.
    let (kept, eliminated) = jacobi_scales(d, &layout, &h)?;
    scale_normal(&mut h, &kept, &eliminated);
    scale_normal(&mut g, &kept, &eliminated);
    schur(d, &layout, &mut h)?;
    let noise = reduced_noise(&h, &g);
    let m = h.a.nrows();
    // Symmetric, so the column-major storage reads as row-major.
    cholesky(h.a.as_mut_slice(), m).map_err(|k| {
        UncertaintyError::RankDeficient(describe(d, &layout, h.params[h.kept_columns[k]]))
    })?;
    let variance = sandwich_diagonal(h.a.as_slice(), &noise);
    let mut out = vec![[0.0; 3]; d.target.num_corners()];
    for (k, &col) in h.kept_columns.iter().enumerate() {
        let Some(i) = h.params[col].checked_sub(layout.corrections) else {
            continue;
        };
        let s = kept[k] * variance[k].max(0.0).sqrt();
        out[i / CORRECTION_STRIDE][i % CORRECTION_STRIDE] = s;
    }
    Ok(out)
}

/// The noise term reduced onto the kept values: with the eliminated values'
/// response x_f = −M x_k to the kept ones (M = D⁻¹Bᵀ, per image block),
/// [x_k; x_f]ᵀ G [x_k; x_f] = x_kᵀ Ĝ x_k for
/// Ĝ = G_kk − G_kf M − Mᵀ G_fk + Mᵀ G_ff M = G_kk − QᵀM − MᵀQ with
/// Q = G_fk − ½ G_ff M: one matrix product, QᵀM, over the image blocks.
///
/// `h` has been through [`schur`] (its blocks D factored in place, its Bᵀ turned
/// into L⁻¹Bᵀ); `g` is the noise term with the same blocks, scaled alike. With
/// W = I and no prior, G = H and Ĝ is H's Schur complement.
fn reduced_noise(h: &Normal, g: &Normal) -> DMatrix<f64> {
    let ne = h.bt.nrows();
    // M = L⁻ᵀ(L⁻¹Bᵀ) and Q, image block by image block.
    let mut m = h.bt.clone();
    let mut q = g.bt.clone();
    let columns = m
        .as_mut_slice()
        .chunks_exact_mut(ne)
        .zip(q.as_mut_slice().chunks_exact_mut(ne));
    for (mc, qc) in columns {
        for (b, &(start, size)) in h.groups.iter().enumerate() {
            let mb = &mut mc[start..start + size];
            backward(&h.d[b], size, mb);
            let gd = &g.d[b];
            for (a, v) in qc[start..start + size].iter_mut().enumerate() {
                *v -= 0.5 * dot(&gd[a * size..(a + 1) * size], mb);
            }
        }
    }
    let t = q.transpose() * &m;
    let mut out = g.a.clone();
    out -= &t;
    out -= t.transpose();
    out
}

/// diag(S⁻¹ Ĝ S⁻¹) from S's lower Cholesky factor L (row-major, in place of S):
/// S⁻¹ = L⁻ᵀL⁻¹ made explicit (L⁻¹ column by column, then one product), so the
/// rest is two matrix products and a dot product per value.
fn sandwich_diagonal(l: &[f64], noise: &DMatrix<f64>) -> Vec<f64> {
    let m = noise.nrows();
    let mut l_inv = DMatrix::<f64>::zeros(m, m);
    for (i, mut column) in l_inv.column_iter_mut().enumerate() {
        // L x = e_i: x is zero above row i.
        let x = column.as_mut_slice();
        x[i] = 1.0 / l[i * m + i];
        for r in i + 1..m {
            x[r] = -dot(&l[r * m + i..r * m + r], &x[i..r]) / l[r * m + r];
        }
    }
    let inverse = l_inv.transpose() * &l_inv;
    let y = noise * &inverse;
    // S⁻¹ is symmetric: row k of S⁻¹ is its column k.
    (0..m)
        .map(|k| dot(inverse.column(k).as_slice(), y.column(k).as_slice()))
        .collect()
}
