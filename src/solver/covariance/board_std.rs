//! The board's σ for `board.json`: the marginal standard deviation of every
//! static correction value at unit noise, the diagonal of the corrections'
//! block of H⁻¹ (JᵀW²J) H⁻¹. Part of the covariance pass (`unit_covariance`),
//! which hands over H already reduced and factored, so that the Jacobian, the
//! loss weights, H, its Jacobi scaling, its Schur complement and its Cholesky
//! factor serve Σ_θ and the board alike. Structured, so that it costs a few
//! dense matrix products over the intrinsics and corrections whatever the
//! number of images: the per-image blocks (pose, bend), which couple the rest
//! only through their few values, are eliminated frame by frame from H and
//! from the noise term alike, the factor of what is left gives its inverse,
//! and only the diagonal of the product is read. The normal matrices and their
//! factorisations are `normal`'s.
use super::normal::{backward, dot, Normal};
use crate::model::dataset::Dataset;
use crate::model::state::{Layout, CORRECTION_STRIDE};
use nalgebra::DMatrix;

/// The standard deviation of every static correction value at unit noise (3 per
/// corner; 0 for a held value), with the loss the weights of `h` and `g` hold.
///
/// `h` is H = JᵀWJ (with the lens prior, the curvature the fit solves with)
/// with the per-image blocks as its eliminated ones and the corrections kept,
/// Jacobi-scaled by D (`kept` holds D's kept values), reduced by [`schur`] and
/// its Schur complement factored in place; `g` is the noise term G = JᵀW²J
/// with the same blocks, scaled by the same D: (DHD)⁻¹ (DGD) (DHD)⁻¹ = D⁻¹ Σ D⁻¹.
///
/// [`schur`]: super::normal::schur
pub(super) fn correction_std(
    d: &Dataset,
    layout: &Layout,
    h: &Normal,
    g: Normal,
    kept: &[f64],
) -> Vec<[f64; 3]> {
    let noise = reduced_noise(h, g);
    let variance = sandwich_diagonal(h.a.as_slice(), &noise);
    let mut out = vec![[0.0; 3]; d.target.num_corners()];
    for (k, &col) in h.kept_columns.iter().enumerate() {
        let Some(i) = h.params[col].checked_sub(layout.corrections) else {
            continue;
        };
        let s = kept[k] * variance[k].max(0.0).sqrt();
        out[i / CORRECTION_STRIDE][i % CORRECTION_STRIDE] = s;
    }
    out
}

/// The noise term reduced onto the kept values: with the eliminated values'
/// response x_f = −M x_k to the kept ones (M = D⁻¹Bᵀ, per image block),
/// [x_k; x_f]ᵀ G [x_k; x_f] = x_kᵀ Ĝ x_k for
/// Ĝ = G_kk − G_kf M − Mᵀ G_fk + Mᵀ G_ff M = G_kk − QᵀM − MᵀQ with
/// Q = G_fk − ½ G_ff M: one matrix product, QᵀM, over the image blocks.
///
/// `h` has been through [`schur`](super::normal::schur) (its blocks D factored
/// in place, its Bᵀ turned into L⁻¹Bᵀ); `g` is the noise term with the same
/// blocks, scaled alike, and its Bᵀ becomes Q in place (nothing reads it
/// after). With W = I and no prior, G = H and Ĝ is H's Schur complement.
fn reduced_noise(h: &Normal, g: Normal) -> DMatrix<f64> {
    let ne = h.bt.nrows();
    // M = L⁻ᵀ(L⁻¹Bᵀ) and Q, image block by image block.
    let mut m = h.bt.clone();
    let mut q = g.bt;
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
    let mut out = g.a;
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
