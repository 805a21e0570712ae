// Wrappers around a residual block's cost: a corner's correction read from a
// slot of a group's block (InCornerGroup), and a view block compressed to its
// Gram factor (CompressedRows).
#pragma once

#include <Eigen/Core>
#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

namespace deformcal {
// A cost whose parameter block `block` (a corner's correction) is read from a
// slot, `offset` values in, of a larger block holding the corrections of a few
// corners (the correction prior's; ChainedReprojection places its own corner).
// Ceres' Schur update then works on a few large cells per image instead of one
// 2 x 2 cell per pair of corners (solver.cc, UseCornerGroups); the Jacobian over
// the larger block is zero outside the slot.
class InCornerGroup final : public ceres::CostFunction {
 public:
  InCornerGroup(ceres::CostFunction* inner, int block, int offset, int group_size)
      : inner_(inner), block_(block), offset_(offset) {
    set_num_residuals(inner->num_residuals());
    std::vector<int32_t> sizes = inner->parameter_block_sizes();
    slot_size_ = sizes.at(block);
    sizes[block] = group_size;
    *mutable_parameter_block_sizes() = sizes;
    if (sizes.size() > kMaxBlocks || num_residuals() * slot_size_ > kMaxSlotJacobian ||
        offset + slot_size_ > group_size) {
      throw std::invalid_argument("InCornerGroup: a cost or slot larger than it supports");
    }
  }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const size_t n = parameter_block_sizes().size();
    std::array<const double*, kMaxBlocks> q{};
    std::copy(p, p + n, q.begin());
    q[block_] = p[block_] + offset_;
    if (jacobians == nullptr || jacobians[block_] == nullptr) {
      return inner_->Evaluate(q.data(), r, jacobians);
    }
    std::array<double*, kMaxBlocks> j{};
    std::copy(jacobians, jacobians + n, j.begin());
    std::array<double, kMaxSlotJacobian> slot{};
    j[block_] = slot.data();
    if (!inner_->Evaluate(q.data(), r, j.data())) return false;
    const int m = num_residuals(), width = parameter_block_sizes()[block_];
    double* J = jacobians[block_];
    std::fill(J, J + m * width, 0.0);
    for (int row = 0; row < m; ++row) {
      for (int c = 0; c < slot_size_; ++c) J[row * width + offset_ + c] = slot[row * slot_size_ + c];
    }
    return true;
  }

 private:
  static constexpr size_t kMaxBlocks = 8;
  static constexpr int kMaxSlotJacobian = 32;
  std::unique_ptr<ceres::CostFunction> inner_;
  int block_, offset_, slot_size_ = 0;
};

// A view block handed to the solver as k = c + 1 rows instead of its 2N: with
// the c = sum of its blocks' sizes columns of J (rows of the inner block) and
// the residual r, R is the upper triangular factor of the Gram matrix of
// [J r] (R^T R = [J r]^T [J r]).  Its first c columns are the Jacobian and its
// last the residual, so the cost |r|^2 / 2, the gradient J^T r and the
// Gauss-Newton matrix J^T J (hence every Levenberg-Marquardt step, the jacobi
// scaling and the model cost change) are the inner block's, to rounding (and,
// where a column is within about 1e-7 of depending on the ones before it, to
// that: its pivot is dropped): the solve takes the same steps, while Ceres'
// Schur elimination and its Jacobian bookkeeping work on 13 rows per view (ds,
// standard) instead of 338.  Residual-only evaluations (Ceres reads only their
// cost) give (|r|, 0, ...), so Ceres' check_gradients cannot be used on them.
// The plain per-corner residuals stay with the inner block (inner()).
class CompressedRows final : public ceres::CostFunction {
 public:
  explicit CompressedRows(ceres::CostFunction* inner) : inner_(inner) {
    *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
    set_num_residuals(Columns(*inner) + 1);
  }

  // Whether compressing `inner` saves rows.
  static bool Pays(const ceres::CostFunction& inner) {
    return inner.num_residuals() > Columns(inner) + 1;
  }

  const ceres::CostFunction& inner() const { return *inner_; }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const int m = inner_->num_residuals(), k = num_residuals();
    const std::vector<int32_t>& sizes = parameter_block_sizes();
    // Scratch per thread: Ceres evaluates blocks in parallel.
    thread_local std::vector<double> inner_r, inner_j;
    thread_local std::vector<double*> inner_ptr;
    inner_r.resize(static_cast<size_t>(m));
    if (jacobians == nullptr) {
      if (!inner_->Evaluate(p, inner_r.data(), nullptr)) return false;
      double s = 0.0;
      for (double v : inner_r) s += v * v;
      std::fill(r, r + k, 0.0);
      r[0] = std::sqrt(s);
      return true;
    }
    // The inner block's Jacobian of each requested block, row-major m x size,
    // side by side in one buffer; A below gathers them and r column-major.
    inner_j.resize(static_cast<size_t>(m) * static_cast<size_t>(k));
    inner_ptr.assign(sizes.size(), nullptr);
    int used = 0;
    for (size_t b = 0; b < sizes.size(); ++b) {
      if (jacobians[b] == nullptr) continue;
      inner_ptr[b] = inner_j.data() + static_cast<size_t>(m) * used;  // row-major m x size
      used += sizes[b];
    }
    if (!inner_->Evaluate(p, inner_r.data(), inner_ptr.data())) return false;
    Eigen::MatrixXd A(m, used + 1);
    for (size_t b = 0, col = 0; b < sizes.size(); ++b) {
      if (inner_ptr[b] == nullptr) continue;
      A.middleCols(static_cast<Eigen::Index>(col), sizes[b]) =
          Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
              inner_ptr[b], m, sizes[b]);
      col += static_cast<size_t>(sizes[b]);
    }
    A.col(used) = Eigen::Map<const Eigen::VectorXd>(inner_r.data(), m);
    const Eigen::MatrixXd R = GramFactor(A);
    for (int i = 0; i < k; ++i) r[i] = i <= used ? R(i, used) : 0.0;
    for (size_t b = 0, col = 0; b < sizes.size(); ++b) {
      if (jacobians[b] == nullptr) continue;
      for (int i = 0; i < k; ++i) {
        for (int c = 0; c < sizes[b]; ++c) {
          jacobians[b][i * sizes[b] + c] = i <= used ? R(i, static_cast<Eigen::Index>(col) + c) : 0.0;
        }
      }
      col += static_cast<size_t>(sizes[b]);
    }
    return true;
  }

 private:
  // Upper triangular R with R^T R = A^T A: Cholesky of the Gram matrix with its
  // columns scaled to unit norm (the Jacobian's columns differ by orders of
  // magnitude).  A column that depends on the ones before (a pivot below
  // rounding; a held parameter's zero column) gets a zero row: the Gram matrix
  // is only semi-definite there, and the row adds nothing to it.
  static Eigen::MatrixXd GramFactor(const Eigen::MatrixXd& A) {
    const Eigen::Index n = A.cols();
    // Column dot products, not Eigen's rank update: for a view's 2N x ~14
    // matrix the product kernel's packing costs more than the arithmetic
    // (profile of 25-image `ds` calibrations: the rank update took 15 % of
    // the time, the dots under a third of that).
    Eigen::MatrixXd G(n, n);
    for (Eigen::Index j = 0; j < n; ++j) {
      for (Eigen::Index i = j; i < n; ++i) G(i, j) = A.col(i).dot(A.col(j));
    }
    Eigen::VectorXd d(n);
    for (Eigen::Index j = 0; j < n; ++j) d[j] = G(j, j) > 0.0 ? std::sqrt(G(j, j)) : 1.0;
    Eigen::MatrixXd R = Eigen::MatrixXd::Zero(n, n);
    for (Eigen::Index j = 0; j < n; ++j) {
      for (Eigen::Index i = 0; i <= j; ++i) {
        // Lower triangle of G: G(j, i) for i <= j.
        double s = G(j, i) / (d[i] * d[j]);
        for (Eigen::Index l = 0; l < i; ++l) s -= R(l, i) * R(l, j);
        if (i < j) {
          R(i, j) = R(i, i) > 0.0 ? s / R(i, i) : 0.0;
        } else {
          R(j, j) = s > kPivotFloor ? std::sqrt(s) : 0.0;
        }
      }
    }
    // Undo the scaling: column j of R times d[j].
    for (Eigen::Index j = 0; j < n; ++j) R.col(j) *= d[j];
    return R;
  }

  // On the unit diagonal, a pivot this small means the column is the ones
  // before it to about 1e-7 of its norm.
  static constexpr double kPivotFloor = 1e-14;

  // The Jacobian columns of `f`: the sum of its parameter blocks' sizes.
  static int Columns(const ceres::CostFunction& f) {
    int columns = 0;
    for (int32_t size : f.parameter_block_sizes()) columns += size;
    return columns;
  }

  std::unique_ptr<ceres::CostFunction> inner_;
};

}  // namespace deformcal
