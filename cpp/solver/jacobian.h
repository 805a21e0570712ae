// Residuals and Jacobians read from an assembled problem, in observation
// order, with each Jacobian column's index in the parameter buffer.
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "deformcal/cpp/solver/assembled.h"

namespace deformcal {
namespace {

// The observation blocks' residuals (no loss, the loss folded into view blocks
// switched off too), block after block, and their cost; false where one is not
// finite.  Straight from the cost functions: Problem::Evaluate would build a
// program and an evaluator over every block first (5 % of a 10 000-image `full`
// calibration, called after every solve).
bool PlainResiduals(const Assembled& a, std::vector<double>* by_block, double* cost) {
  const double robust = *a.loss_scale_factor;
  *a.loss_scale_factor = 0.0;
  by_block->assign(2 * a.block_observations.size(), 0.0);
  std::vector<double*> blocks;
  double sum = 0.0;
  bool ok = true;
  size_t row = 0;
  for (size_t k = 0; k < a.residuals.size() && ok; ++k) {
    const ceres::CostFunction* f = &a.PlainCost(k);
    a.problem->GetParameterBlocksForResidualBlock(a.residuals[k], &blocks);
    a.ObservationsOf(k, f->num_residuals());  // the rows fit
    double* r = by_block->data() + row;
    ok = f->Evaluate(blocks.data(), r, nullptr);
    for (int i = 0; i < f->num_residuals() && ok; ++i) {
      ok = std::isfinite(r[i]);
      sum += r[i] * r[i];
    }
    row += static_cast<size_t>(f->num_residuals());
  }
  *a.loss_scale_factor = robust;
  if (cost != nullptr) *cost = 0.5 * sum;
  return ok;
}

// The index in the parameter buffer (which starts at `base`) of every Jacobian
// column of `blocks`, in order.  A column is one tangent coordinate; every manifold
// deformcal sets is a SubsetManifold, whose tangent coordinates are the free values
// in order, read here off its PlusJacobian so no other manifold is silently misread.
std::vector<uint32_t> ColumnParameters(const ceres::Problem& problem,
                                       const std::vector<double*>& blocks, const double* base) {
  std::vector<uint32_t> out;
  for (double* b : blocks) {
    const uint32_t offset = static_cast<uint32_t>(b - base);
    const int n = problem.ParameterBlockSize(b);
    const ceres::Manifold* m = problem.GetManifold(b);
    if (m == nullptr) {
      for (int i = 0; i < n; ++i) out.push_back(offset + static_cast<uint32_t>(i));
      continue;
    }
    const int t = m->TangentSize();
    std::vector<double> plus(static_cast<size_t>(n) * t);
    if (!m->PlusJacobian(b, plus.data())) Fail("a manifold's Jacobian could not be evaluated");
    for (int c = 0; c < t; ++c) {
      int row = -1;
      for (int r = 0; r < n; ++r) {
        const double v = plus[static_cast<size_t>(r) * t + c];
        if (v == 1.0 && row < 0) {
          row = r;
        } else if (v != 0.0) {
          Fail("a parameter block's manifold is not a subset of its values");
        }
      }
      if (row < 0) Fail("a parameter block's manifold is not a subset of its values");
      out.push_back(offset + static_cast<uint32_t>(row));
    }
  }
  return out;
}

// Puts row r of a CRS matrix at row order[r] (a permutation).
void SortRows(const std::vector<uint32_t>& order, ceres::CRSMatrix& m) {
  bool identity = true;
  for (size_t r = 0; r < order.size(); ++r) identity = identity && order[r] == r;
  if (identity) return;
  std::vector<uint32_t> source(order.size());
  for (size_t r = 0; r < order.size(); ++r) source[order[r]] = static_cast<uint32_t>(r);
  ceres::CRSMatrix sorted;
  sorted.num_rows = m.num_rows;
  sorted.num_cols = m.num_cols;
  sorted.rows.push_back(0);
  for (uint32_t from : source) {
    const int lo = m.rows[from], hi = m.rows[from + 1];
    sorted.cols.insert(sorted.cols.end(), m.cols.begin() + lo, m.cols.begin() + hi);
    sorted.values.insert(sorted.values.end(), m.values.begin() + lo, m.values.begin() + hi);
    sorted.rows.push_back(static_cast<int>(sorted.cols.size()));
  }
  m = std::move(sorted);
}

// The free parameter blocks of the parameter buffer: the columns of a Jacobian
// Rust reads, without the correction prior's internal similarity (the reprojection
// residuals do not depend on it).
std::vector<double*> FreeLayoutBlocks(const Assembled& a) {
  std::vector<double*> all, out;
  a.problem->GetParameterBlocks(&all);
  for (double* b : all) {
    if (!a.problem->IsParameterBlockConstant(b) && b != a.similarity) out.push_back(b);
  }
  return out;
}

// Problem::Evaluate of the observation blocks with their Jacobian over the free
// parameter blocks, rows sorted into observation order; residuals block after block.
bool EvaluateWithJacobian(Assembled& a, int threads, double* cost, std::vector<double>* by_block,
                          ceres::CRSMatrix* jacobian, const double* base, std::vector<uint32_t>* columns) {
  // Problem::Evaluate would read compressed rows as observations'.
  if (a.compress_views) Fail("internal: the Jacobian of a problem assembled for solving");
  ceres::Problem::EvaluateOptions e;
  e.residual_blocks = a.residuals;
  e.apply_loss_function = false;
  e.num_threads = threads;
  e.parameter_blocks = FreeLayoutBlocks(a);
  if (columns != nullptr) *columns = ColumnParameters(*a.problem, e.parameter_blocks, base);
  // Plain residuals: the loss folded into view blocks is switched off too.
  const double robust = *a.loss_scale_factor;
  *a.loss_scale_factor = 0.0;
  const bool ok = a.problem->Evaluate(e, cost, by_block, nullptr, jacobian);
  *a.loss_scale_factor = robust;
  if (!ok) return false;
  // Ceres' row r is observation row order[r].
  std::vector<uint32_t> order;
  order.reserve(2 * a.block_observations.size());
  for (uint32_t i : a.block_observations) {
    order.push_back(2 * i);
    order.push_back(2 * i + 1);
  }
  SortRows(order, *jacobian);
  return true;
}

// Residuals (loss not applied) in observation order; Ceres orders them by block.
// With `jacobian`, also the Jacobian over the free parameter blocks, whose columns'
// buffer indices go to `columns`.
bool OrderedResiduals(Assembled& a, size_t num_observations, int threads, double* cost,
                      std::vector<double>* out, ceres::CRSMatrix* jacobian,
                      const double* base = nullptr, std::vector<uint32_t>* columns = nullptr) {
  std::vector<double> by_block;
  if (jacobian == nullptr) {
    if (!PlainResiduals(a, &by_block, cost)) return false;
  } else if (!EvaluateWithJacobian(a, threads, cost, &by_block, jacobian, base, columns)) {
    return false;
  }
  if (by_block.size() != 2 * a.block_observations.size()) return false;
  // Row r, block after block, is observation block_observations[r / 2]'s.
  out->assign(2 * num_observations, 0.0);
  for (size_t r = 0; r < by_block.size(); ++r) {
    (*out)[2 * a.block_observations[r / 2] + r % 2] = by_block[r];
  }
  return true;
}

// The free blocks' columns: per block its first column and the value offsets of
// its tangent coordinates (ColumnParameters' reading of its manifold).
struct FreeColumns {
  std::unordered_map<const double*, std::pair<uint32_t, std::vector<int>>> blocks;
  std::vector<uint32_t> params;  // per column: the buffer index it differentiates
};

FreeColumns FreeColumnsOf(const Assembled& a, const double* base) {
  const ceres::Problem& problem = *a.problem;
  FreeColumns f;
  for (double* b : FreeLayoutBlocks(a)) {
    const std::vector<uint32_t> cols = ColumnParameters(problem, {b}, base);
    std::vector<int> coords;
    for (uint32_t c : cols) coords.push_back(static_cast<int>(c - static_cast<uint32_t>(b - base)));
    f.blocks.emplace(b, std::make_pair(static_cast<uint32_t>(f.params.size()), std::move(coords)));
    f.params.insert(f.params.end(), cols.begin(), cols.end());
  }
  return f;
}

// The Jacobian of the residuals (loss not applied) over the free parameters, in
// CRS with one row per residual in observation order, straight from the cost
// functions.  Problem::Evaluate gives the same numbers, but builds a program and
// a sparse matrix first, which costs several times the evaluation itself.
// Two passes: the rows' lengths first (a block's rows all span its free blocks'
// columns), then each row's entries written in place, with no intermediate
// copy (a 650-image Jacobian holds 3.5 million entries).
void DirectJacobian(const Assembled& a, const double* base, size_t num_observations,
                    ffi::Jacobian& out) {
  const ceres::Problem& problem = *a.problem;
  *a.loss_scale_factor = 0.0;  // the Jacobian of the plain residuals
  const FreeColumns f = FreeColumnsOf(a, base);
  std::vector<double*> blocks;
  // Per residual block, its free parameter blocks' entries (nullptr if held).
  std::vector<std::vector<const std::pair<uint32_t, std::vector<int>>*>> free(a.residuals.size());
  std::vector<uint32_t> length(2 * num_observations, 0);
  for (size_t k = 0; k < a.residuals.size(); ++k) {
    problem.GetParameterBlocksForResidualBlock(a.residuals[k], &blocks);
    uint32_t width = 0;
    free[k].assign(blocks.size(), nullptr);
    for (size_t b = 0; b < blocks.size(); ++b) {
      const auto it = f.blocks.find(blocks[b]);
      if (it == f.blocks.end()) continue;
      free[k][b] = &it->second;
      width += static_cast<uint32_t>(it->second.second.size());
    }
    const int nres = a.PlainCost(k).num_residuals();
    const uint32_t* obs = a.ObservationsOf(k, nres);
    for (int row = 0; row < nres; ++row) length[2 * obs[row / 2] + row % 2] = width;
  }
  out.row_ptr.assign(1, 0);
  out.row_ptr.reserve(length.size() + 1);
  for (uint32_t n : length) out.row_ptr.push_back(out.row_ptr.back() + n);
  out.col_idx.resize(out.row_ptr.back());
  out.values.resize(out.row_ptr.back());
  out.residuals.assign(2 * num_observations, 0.0);
  std::vector<std::vector<double>> jac;
  std::vector<double*> jac_ptr;
  std::vector<double> r;
  for (size_t k = 0; k < a.residuals.size(); ++k) {
    const ceres::CostFunction* cost = &a.PlainCost(k);
    problem.GetParameterBlocksForResidualBlock(a.residuals[k], &blocks);
    const std::vector<int32_t>& sizes = cost->parameter_block_sizes();
    const int nres = cost->num_residuals();
    jac.resize(std::max(jac.size(), blocks.size()));
    jac_ptr.assign(blocks.size(), nullptr);
    for (size_t b = 0; b < blocks.size(); ++b) {
      if (free[k][b] == nullptr) continue;
      // Zeroed: a cost function may leave the entries it knows are 0.
      jac[b].assign(static_cast<size_t>(nres) * sizes[b], 0.0);
      jac_ptr[b] = jac[b].data();
    }
    r.assign(nres, 0.0);
    if (!cost->Evaluate(blocks.data(), r.data(), jac_ptr.data())) {
      Fail("the residuals could not be evaluated (a point behind the camera?)");
    }
    const uint32_t* obs = a.ObservationsOf(k, nres);
    for (int row = 0; row < nres; ++row) {
      const size_t target = 2 * obs[row / 2] + row % 2;
      out.residuals[target] = r[row];
      size_t at = out.row_ptr[target];
      for (size_t b = 0; b < blocks.size(); ++b) {
        if (free[k][b] == nullptr) continue;
        const auto& [first, coords] = *free[k][b];
        const double* jrow = jac[b].data() + static_cast<size_t>(row) * sizes[b];
        for (size_t j = 0; j < coords.size(); ++j, ++at) {
          out.col_idx[at] = first + static_cast<uint32_t>(j);
          out.values[at] = jrow[coords[j]];
        }
      }
    }
  }
  out.cols = f.params.size();
  out.col_param = f.params;
}

}  // namespace
}  // namespace deformcal
