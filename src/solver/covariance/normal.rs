//! The covariance's normal matrices: JᵀWJ in block-arrow form (a dense kept
//! block, block-diagonal eliminated blocks, their coupling) built from the
//! Jacobian at the optimum, its Jacobi scaling, the Schur complement onto the
//! kept values and the small dense factorisations both `solver::covariance`
//! and its board's σ solve with. What is asked of the matrices is theirs.
use crate::model::dataset::Dataset;
use crate::model::state::{Layout, CORRECTION_STRIDE, POSE_PARAMS};
use crate::model::uncertainty::{UncertaintyError, MAX_REDUCED};
use crate::solver::problem::{Evaluation, Loss, Problem, SolverSettings, State};
use nalgebra::DMatrix;
use std::collections::HashMap;

/// A diagonal pivot of the Jacobi-scaled normal matrix below this marks a
/// direction the data do not determine: its parameter is then a combination of
/// the others to a relative 1e-5 (round-off leaves about 1e-16 in a true null
/// direction; a weak but real one, such as k3 against k1 and k2, stays far above).
pub(super) const MIN_PIVOT: f64 = 1e-10;

/// Most values the coupling block Bᵀ (eliminated × kept) may hold: 400 MB of f64.
pub(super) const MAX_COUPLING: usize = 50_000_000;

/// Where a Jacobian column goes: the dense reduced system, or a block eliminated
/// first (`index` counts the eliminated values, block by block).
#[derive(Debug, Clone, Copy)]
pub(super) enum Role {
    Kept(usize),
    Eliminated { group: usize, index: usize },
}

/// The normal matrix JᵀWJ in block-arrow form, and what its columns are.
pub(super) struct Normal {
    pub(super) roles: Vec<Role>,
    /// Per column: the value it differentiates (its index in the parameter buffer).
    pub(super) params: Vec<usize>,
    /// Per kept index: its column.
    pub(super) kept_columns: Vec<usize>,
    /// The kept block A (kept × kept).
    pub(super) a: DMatrix<f64>,
    /// Per eliminated block: its first eliminated index and its size.
    pub(super) groups: Vec<(usize, usize)>,
    /// Per eliminated block: its diagonal block D, size × size row-major.
    pub(super) d: Vec<Vec<f64>>,
    /// Bᵀ (eliminated × kept), so that a kept value's couplings are contiguous.
    pub(super) bt: DMatrix<f64>,
}

/// The group of a buffer index when per-image blocks (`frames`) or per-corner
/// corrections are eliminated; `None` for a kept value.
pub(super) fn group_of(layout: &Layout, index: usize, frames: bool) -> Option<usize> {
    if frames && (layout.frames..layout.corrections).contains(&index) {
        Some((index - layout.frames) / layout.frame_stride)
    } else if !frames && index >= layout.corrections {
        Some((index - layout.corrections) / CORRECTION_STRIDE)
    } else {
        None
    }
}

/// Which blocks a normal matrix eliminates before its dense solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Eliminate {
    /// The per-image blocks or the per-corner corrections, whichever leaves the
    /// smaller reduced system (the intrinsics are all that is asked for).
    Smaller,
    /// The per-image blocks (pose, bend), so that the corrections stay in the
    /// reduced system with the intrinsics they trade off against.
    Frames,
}

/// The roles of the columns and the eliminated blocks (first index, size).
pub(super) fn roles(
    layout: &Layout,
    params: &[usize],
    eliminate: Eliminate,
) -> (Vec<Role>, usize, Vec<(usize, usize)>) {
    let count = |frames| {
        params
            .iter()
            .filter(|&&p| group_of(layout, p, frames).is_some())
            .count()
    };
    let frames = eliminate == Eliminate::Frames || {
        let (in_frames, in_corners) = (count(true), count(false));
        in_corners == 0 || in_frames >= in_corners
    };
    let mut ids: HashMap<usize, usize> = HashMap::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut local = Vec::with_capacity(params.len());
    let mut kept = 0;
    for &p in params {
        local.push(match group_of(layout, p, frames) {
            None => {
                kept += 1;
                None
            }
            Some(g) => {
                let next = sizes.len();
                let group = *ids.entry(g).or_insert(next);
                if group == next {
                    sizes.push(0);
                }
                sizes[group] += 1;
                Some((group, sizes[group] - 1))
            }
        });
    }
    let mut groups = Vec::with_capacity(sizes.len());
    let mut start = 0;
    for &m in &sizes {
        groups.push((start, m));
        start += m;
    }
    let mut k = 0;
    let roles = local
        .into_iter()
        .map(|l| match l {
            None => {
                k += 1;
                Role::Kept(k - 1)
            }
            Some((group, i)) => Role::Eliminated {
                group,
                index: groups[group].0 + i,
            },
        })
        .collect();
    (roles, kept, groups)
}

/// JᵀWJ from a CRS Jacobian with one weight per pair of rows (per observation).
pub(super) fn normal_matrix(
    e: &Evaluation,
    layout: &Layout,
    weights: &[f64],
    eliminate: Eliminate,
) -> Result<Normal, UncertaintyError> {
    let [n] = normal_matrices(e, layout, [weights], eliminate)?;
    Ok(n)
}

/// One block-arrow normal matrix JᵀW_iJ per set of weights W_i, in one pass
/// over the Jacobian's rows (the same columns, roles and blocks in each).
pub(super) fn normal_matrices<const K: usize>(
    e: &Evaluation,
    layout: &Layout,
    weights: [&[f64]; K],
    eliminate: Eliminate,
) -> Result<[Normal; K], UncertaintyError> {
    let params: Vec<usize> = e.jacobian_col_param.iter().map(|&p| p as usize).collect();
    let (roles, kept, groups) = roles(layout, &params, eliminate);
    let eliminated: usize = groups.iter().map(|g| g.1).sum();
    if kept > MAX_REDUCED || kept.saturating_mul(eliminated) > MAX_COUPLING {
        return Err(UncertaintyError::TooLarge(kept));
    }
    let mut out = std::array::from_fn(|_| Normal {
        kept_columns: (0..params.len())
            .filter(|&c| matches!(roles[c], Role::Kept(_)))
            .collect(),
        roles: roles.clone(),
        params: params.clone(),
        a: DMatrix::zeros(kept, kept),
        d: groups.iter().map(|&(_, m)| vec![0.0; m * m]).collect(),
        groups: groups.clone(),
        bt: DMatrix::zeros(eliminated, kept),
    });
    let (mut kept_entries, mut eliminated_entries) = (Vec::new(), Vec::new());
    for (o, pair) in e.jacobian_row_ptr.windows(3).step_by(2).enumerate() {
        let (x, y) = (
            pair[0] as usize..pair[1] as usize,
            pair[1] as usize..pair[2] as usize,
        );
        let cols = |r: &std::ops::Range<usize>| &e.jacobian_col_idx[r.clone()];
        let w = weights.map(|w| w[o]);
        // An observation's two rows, usually over the same columns: one outer
        // product of their value pairs.
        if cols(&x) == cols(&y) {
            entries(
                e,
                &roles,
                x.clone(),
                Some(y),
                &mut kept_entries,
                &mut eliminated_entries,
            );
            accumulate(&mut out, w, &kept_entries, &eliminated_entries)?;
        } else {
            for r in [x, y] {
                entries(
                    e,
                    &roles,
                    r,
                    None,
                    &mut kept_entries,
                    &mut eliminated_entries,
                );
                accumulate(&mut out, w, &kept_entries, &eliminated_entries)?;
            }
        }
    }
    out.iter_mut().for_each(mirror);
    Ok(out)
}

/// Fills each symmetric block's entries below the diagonal (of a column-major
/// kept block; of a row-major eliminated block, alike) from those above, which
/// [`accumulate`] sums.
pub(super) fn mirror(n: &mut Normal) {
    let fill = |a: &mut [f64], m: usize| {
        for hi in 0..m {
            for lo in 0..hi {
                a[lo * m + hi] = a[hi * m + lo];
            }
        }
    };
    let kk = n.a.nrows();
    fill(n.a.as_mut_slice(), kk);
    for (d, &(_, m)) in n.d.iter_mut().zip(&n.groups) {
        fill(d, m);
    }
}

/// The kept and eliminated entries of Jacobian row `x`, each with its value and
/// that of row `y` in the same column (0 without `y`).
pub(super) fn entries(
    e: &Evaluation,
    roles: &[Role],
    x: std::ops::Range<usize>,
    y: Option<std::ops::Range<usize>>,
    kept: &mut Vec<(usize, [f64; 2])>,
    eliminated: &mut Vec<(usize, usize, [f64; 2])>,
) {
    kept.clear();
    eliminated.clear();
    let start = y.as_ref().map(|y| y.start);
    for (j, i) in x.clone().enumerate() {
        let v = [
            e.jacobian_values[i],
            start.map_or(0.0, |s| e.jacobian_values[s + j]),
        ];
        match roles[e.jacobian_col_idx[i] as usize] {
            Role::Kept(k) => kept.push((k, v)),
            Role::Eliminated { group, index } => eliminated.push((group, index, v)),
        }
    }
}

/// Adds the weighted outer product of one observation's Jacobian rows (or of
/// one row, the other 0) to each block-arrow normal matrix, with its weight.
pub(super) fn accumulate<const K: usize>(
    normals: &mut [Normal; K],
    w: [f64; K],
    kept: &[(usize, [f64; 2])],
    eliminated: &[(usize, usize, [f64; 2])],
) -> Result<(), UncertaintyError> {
    let prod = |a: [f64; 2], b: [f64; 2]| a[0] * b[0] + a[1] * b[1];
    // Symmetric blocks: only the entries (lo, hi) of column hi ≥ lo are summed
    // here, the rest mirrored once at the end ([`mirror`]).
    for (n, w) in normals.iter_mut().zip(w) {
        let kk = n.a.nrows();
        let a = n.a.as_mut_slice();
        for (u, &(j, vj)) in kept.iter().enumerate() {
            for &(i, vi) in &kept[u..] {
                a[i.max(j) * kk + i.min(j)] += w * prod(vi, vj);
            }
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
    for (n, w) in normals.iter_mut().zip(w) {
        let (start, m) = n.groups[g];
        let d = &mut n.d[g];
        for (u, &(_, a, va)) in eliminated.iter().enumerate() {
            for &(_, b, vb) in &eliminated[u..] {
                d[(a.max(b) - start) * m + a.min(b) - start] += w * prod(va, vb);
            }
        }
        let ne = n.bt.nrows();
        let bt = n.bt.as_mut_slice();
        for &(k, vk) in kept {
            let column = &mut bt[k * ne..(k + 1) * ne];
            for &(_, a, va) in eliminated {
                column[a] += w * prod(vk, va);
            }
        }
    }
    Ok(())
}

/// The lens prior's information (its weight², a diagonal on the intrinsics it
/// holds): part of H, the curvature the fit solves with, never of the noise term
/// JᵀW²J, so Σ_θ is the variance of the estimate that the prior regularises.
pub(super) fn add_lens_prior(n: &mut Normal, weights: &[f64]) {
    for col in 0..n.params.len() {
        if let (Some(&w), Role::Kept(k)) = (weights.get(n.params[col]), n.roles[col]) {
            n.a[(k, k)] += w * w;
        }
    }
}

/// In-place lower Cholesky factor of a symmetric m × m row-major matrix; `Err(i)`
/// at the first pivot below [`MIN_PIVOT`] (the matrix is Jacobi-scaled, unit diagonal).
pub(super) fn cholesky(a: &mut [f64], m: usize) -> Result<(), usize> {
    for j in 0..m {
        let (done, rest) = a.split_at_mut(j * m + m);
        let row_j = &mut done[j * m..];
        let d = row_j[j] - dot(&row_j[..j], &row_j[..j]);
        // NaN fails too.
        if d.is_nan() || d <= MIN_PIVOT {
            return Err(j);
        }
        let d = d.sqrt();
        row_j[j] = d;
        row_j[j + 1..].iter_mut().for_each(|v| *v = 0.0);
        for row_i in rest.chunks_exact_mut(m) {
            row_i[j] = (row_i[j] - dot(&row_i[..j], &row_j[..j])) / d;
        }
    }
    Ok(())
}

/// Σ aᵢbᵢ over the shorter length, in four interleaved partial sums: a single
/// running sum waits on each addition, and the Cholesky factors and triangular
/// solves here are mostly these dot products.
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 4];
    let (head, tail) = (n - n % 4, n % 4);
    for (x, y) in a[..head].chunks_exact(4).zip(b[..head].chunks_exact(4)) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    let mut rest = 0.0;
    for k in 0..tail {
        rest += a[head + k] * b[head + k];
    }
    (s[0] + s[1]) + (s[2] + s[3]) + rest
}

/// Solves L y = b in place (L lower, row-major m × m).
pub(super) fn forward(l: &[f64], m: usize, b: &mut [f64]) {
    for i in 0..m {
        let s = b[i] - dot(&l[i * m..i * m + i], &b[..i]);
        b[i] = s / l[i * m + i];
    }
}

/// Solves Lᵀ x = y in place.
pub(super) fn backward(l: &[f64], m: usize, y: &mut [f64]) {
    for i in (0..m).rev() {
        let mut s = y[i];
        for k in i + 1..m {
            s -= l[k * m + i] * y[k];
        }
        y[i] = s / l[i * m + i];
    }
}

/// What a buffer index is, in words, for a message.
pub(super) fn describe(d: &Dataset, layout: &Layout, index: usize) -> String {
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
pub(super) fn jacobi_scale(
    d: &Dataset,
    layout: &Layout,
    n: &mut Normal,
) -> Result<Vec<f64>, UncertaintyError> {
    let (kept, eliminated) = jacobi_scales(d, layout, n)?;
    scale_normal(n, &kept, &eliminated);
    Ok(column_scales(n, &kept, &eliminated))
}

/// The scales of the kept and of the eliminated values, per Jacobian column.
pub(super) fn column_scales(n: &Normal, kept: &[f64], eliminated: &[f64]) -> Vec<f64> {
    n.roles
        .iter()
        .map(|r| match *r {
            Role::Kept(k) => kept[k],
            Role::Eliminated { index, .. } => eliminated[index],
        })
        .collect()
}

/// The scales 1/√diag of the kept and of the eliminated values that give the
/// normal matrix a unit diagonal.
pub(super) fn jacobi_scales(
    d: &Dataset,
    layout: &Layout,
    n: &Normal,
) -> Result<(Vec<f64>, Vec<f64>), UncertaintyError> {
    let mut kept = vec![0.0; n.a.nrows()];
    let mut eliminated = vec![0.0; n.bt.nrows()];
    for (col, role) in n.roles.iter().enumerate() {
        let (diag, slot) = match *role {
            Role::Kept(k) => (n.a[(k, k)], &mut kept[k]),
            Role::Eliminated { group, index } => {
                let (start, m) = n.groups[group];
                let i = index - start;
                (n.d[group][i * m + i], &mut eliminated[index])
            }
        };
        if !(diag > 0.0 && diag.is_finite()) {
            return Err(UncertaintyError::RankDeficient(describe(
                d,
                layout,
                n.params[col],
            )));
        }
        *slot = 1.0 / diag.sqrt();
    }
    Ok((kept, eliminated))
}

/// D N D for the diagonal D of the kept and eliminated scales.
pub(super) fn scale_normal(n: &mut Normal, kept: &[f64], eliminated: &[f64]) {
    for (j, mut column) in n.a.column_iter_mut().enumerate() {
        for (i, v) in column.iter_mut().enumerate() {
            *v *= kept[i] * kept[j];
        }
    }
    for (&(start, m), d) in n.groups.iter().zip(&mut n.d) {
        for a in 0..m {
            for b in 0..m {
                d[a * m + b] *= eliminated[start + a] * eliminated[start + b];
            }
        }
    }
    for (k, mut column) in n.bt.column_iter_mut().enumerate() {
        for (e, v) in column.iter_mut().enumerate() {
            *v *= kept[k] * eliminated[e];
        }
    }
}

/// Eliminates every block and factors what is left: [`schur`], then the
/// Schur complement's Cholesky factor in place.
pub(super) fn eliminate(
    d: &Dataset,
    layout: &Layout,
    n: &mut Normal,
) -> Result<(), UncertaintyError> {
    schur(d, layout, n)?;
    let kk = n.a.nrows();
    // Symmetric, so the column-major storage reads as row-major.
    cholesky(n.a.as_mut_slice(), kk).map_err(|k| {
        UncertaintyError::RankDeficient(describe(d, layout, n.params[n.kept_columns[k]]))
    })
}

/// Factors every eliminated block D = LLᵀ in place, turns Bᵀ into L⁻¹Bᵀ and
/// subtracts its Gram matrix from the kept block, leaving the Schur complement
/// A − B D⁻¹ Bᵀ there (one matrix product).
pub(super) fn schur(d: &Dataset, layout: &Layout, n: &mut Normal) -> Result<(), UncertaintyError> {
    let ne = n.bt.nrows();
    for (g, &(start, m)) in n.groups.iter().enumerate() {
        cholesky(&mut n.d[g], m).map_err(|l| {
            let col = n
                .roles
                .iter()
                .position(|r| matches!(*r, Role::Eliminated { index, .. } if index == start + l))
                .unwrap_or(0);
            UncertaintyError::RankDeficient(describe(d, layout, n.params[col]))
        })?;
    }
    // Column by column of Bᵀ, each read once from memory.
    for column in n.bt.as_mut_slice().chunks_exact_mut(ne.max(1)) {
        for (g, &(start, m)) in n.groups.iter().enumerate() {
            forward(&n.d[g], m, &mut column[start..start + m]);
        }
    }
    n.a.gemm(-1.0, &n.bt.transpose(), &n.bt, 1.0);
    Ok(())
}

/// The robust loss' weight ρ'(‖r‖²) of each observation (1 without a loss).
pub(super) fn loss_weights(d: &Dataset, settings: &SolverSettings, residuals: &[f64]) -> Vec<f64> {
    let a2 = settings.loss_scale_px * settings.loss_scale_px;
    d.observations
        .iter()
        .zip(residuals.chunks_exact(2))
        .map(|(o, r)| match settings.loss {
            Loss::None => 1.0,
            Loss::Cauchy => {
                let s = (r[0] * r[0] + r[1] * r[1]) * o.weight * o.weight;
                1.0 / (1.0 + s / a2)
            }
        })
        .collect()
}

/// The Jacobian of `problem` at `state`, as this module's error.
pub fn jacobian(
    problem: &Problem,
    state: &State,
    settings: &SolverSettings,
) -> Result<Evaluation, UncertaintyError> {
    problem
        .jacobian(state, settings)
        .map_err(|e| UncertaintyError::Jacobian(e.to_string()))
}

/// `Err` unless the Jacobian has one row per residual of `problem` and a label per column.
pub(super) fn check_shape(e: &Evaluation, problem: &Problem) -> Result<(), UncertaintyError> {
    let rows = 2 * problem.dataset.observations.len();
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
    Ok(())
}

/// Whether a normal matrix built from `e` with [`Eliminate::Smaller`] has
/// free static corrections, all of them kept in its dense system (what the
/// board's σ needs): known from the columns alone, before the matrix is built,
/// so that the pass builds the noise term beside H only when it is wanted.
pub(super) fn keeps_corrections(e: &Evaluation, layout: &Layout) -> bool {
    let params: Vec<usize> = e.jacobian_col_param.iter().map(|&p| p as usize).collect();
    let (roles, _, _) = roles(layout, &params, Eliminate::Smaller);
    let mut any = false;
    for (&param, role) in params.iter().zip(&roles) {
        if param >= layout.corrections {
            if !matches!(role, Role::Kept(_)) {
                return false;
            }
            any = true;
        }
    }
    any
}
