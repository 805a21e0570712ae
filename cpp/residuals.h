// Residual functors: observed minus projected pixel of one board corner, for
// every lens model and board model (the two registries in camera.h and
// board.h).  Knows nothing of how a problem is assembled.
#pragma once

#include <Eigen/Core>
#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"

namespace deformcal {

template <class A, class B>
struct Concat;
template <int... A, int... B>
struct Concat<std::integer_sequence<int, A...>, std::integer_sequence<int, B...>> {
  using type = std::integer_sequence<int, A..., B...>;
};

// Residual of one observed corner, differentiated in one autodiff piece: the
// reference the chained Jacobian below is tested against.  Blocks: intrinsics,
// [camera-k-from-camera-0 if kRig], the frame's block (camera-0-from-board pose
// followed by the board model's per-frame parameters), then the corner's
// correction if the board model has one.
template <class Lens, class Board, bool kRig>
class ReprojectionError {
 public:
  ReprojectionError(double u, double v, double w, const double* x)
      : u_(u), v_(v), w_(w), x_{x[0], x[1], x[2]} {}

  template <typename T>
  bool operator()(const T* const p0, const T* const p1, T* r) const {
    const T* const p[] = {p0, p1};
    return Evaluate(p, r);
  }
  template <typename T>
  bool operator()(const T* const p0, const T* const p1, const T* const p2, T* r) const {
    const T* const p[] = {p0, p1, p2};
    return Evaluate(p, r);
  }
  template <typename T>
  bool operator()(const T* const p0, const T* const p1, const T* const p2, const T* const p3,
                  T* r) const {
    const T* const p[] = {p0, p1, p2, p3};
    return Evaluate(p, r);
  }

  // w scales the residual: 1 for a full-resolution detection, 0.5^level for a
  // corner found on a decimated image.
  static ceres::CostFunction* Create(double u, double v, double w, const double* x) {
    return Make(new ReprojectionError(u, v, w, x), BlockSizes{});
  }

 private:
  static constexpr int kFrame = kRig ? 2 : 1;
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  using LeadingSizes =
      std::conditional_t<kRig, std::integer_sequence<int, Lens::kNumParams, kPoseSize, kFrameSize>,
                         std::integer_sequence<int, Lens::kNumParams, kFrameSize>>;
  using BlockSizes = std::conditional_t<
      Board::kCornerSize == 0, LeadingSizes,
      typename Concat<LeadingSizes, std::integer_sequence<int, Board::kCornerSize>>::type>;

  template <int... Ns>
  static ceres::CostFunction* Make(ReprojectionError* f, std::integer_sequence<int, Ns...>) {
    return new ceres::AutoDiffCostFunction<ReprojectionError, 2, Ns...>(f);
  }

  template <typename T>
  bool Evaluate(const T* const* p, T* r) const {
    const T* frame = p[kFrame];
    const T* corner = Board::kCornerSize > 0 ? p[kFrame + 1] : nullptr;
    T board[3];
    Board::Point(x_, frame + kPoseSize, corner, board);
    T xc[3];
    TransformPoint(frame, board, xc);
    if constexpr (kRig) {
      T xk[3];
      TransformPoint(p[1], xc, xk);
      xc[0] = xk[0];
      xc[1] = xk[1];
      xc[2] = xk[2];
    }
    T uv[2];
    if (!Lens::Project(p[0], xc, uv)) return false;
    r[0] = w_ * (T(u_) - uv[0]);
    r[1] = w_ * (T(v_) - uv[1]);
    return true;
  }

  double u_, v_, w_;
  double x_[3];
};

// The same residual with its Jacobian assembled by the chain rule from three
// pieces: the board point (Jets over the model's own parameters), the rigid
// transform (closed form; d/dX is the rotation matrix), and the projection
// (closed form over intrinsics and the camera point, Lens::ProjectWithJacobian).
// The Jets carry at most the board model's few derivatives instead of up to 21,
// which makes the Jacobian several times cheaper; ReprojectionError stays as the
// reference it is tested against.
template <class Lens, class Board, bool kRig>
class ChainedReprojection final : public ceres::CostFunction {
 public:
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  static constexpr int kModel = Board::kFrameExtra + Board::kCornerSize;

  ChainedReprojection(double u, double v, double w, const double* x)
      : u_(u), v_(v), w_(w), x_{x[0], x[1], x[2]} {
    set_num_residuals(2);
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(Lens::kNumParams);
    if (kRig) sizes->push_back(kPoseSize);
    sizes->push_back(kFrameSize);
    if (Board::kCornerSize > 0) sizes->push_back(Board::kCornerSize);
  }

  // Reads the corner's correction from `offset` values into a block of `width`
  // holding a group of corners' corrections (InCornerGroup's job, done here to
  // spare a wrapper per observation: 200 MB at 10 000 images).
  void PlaceCorner(int offset, int width) {
    if (Board::kCornerSize == 0 || offset < 0 || offset + Board::kCornerSize > width) {
      throw std::invalid_argument("ChainedReprojection: the corner's slot lies outside its block");
    }
    corner_offset_ = offset;
    mutable_parameter_block_sizes()->back() = width;
  }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const double* intrinsics = p[0];
    const double* rig = kRig ? p[1] : nullptr;
    const double* frame = p[kRig ? 2 : 1];
    const double* corner = Board::kCornerSize > 0 ? p[kRig ? 3 : 2] + corner_offset_ : nullptr;

    // Board point X and dX/d(frame extra, corner).
    double X[3];
    double dX[3][kModel > 0 ? kModel : 1] = {};
    if constexpr (kModel > 0) {
      using JM = ceres::Jet<double, kModel>;
      JM extra[Board::kFrameExtra > 0 ? Board::kFrameExtra : 1];
      JM corr[Board::kCornerSize > 0 ? Board::kCornerSize : 1];
      for (int e = 0; e < Board::kFrameExtra; ++e) extra[e] = JM(frame[kPoseSize + e], e);
      for (int c = 0; c < Board::kCornerSize; ++c) corr[c] = JM(corner[c], Board::kFrameExtra + c);
      JM out[3];
      Board::Point(x_, extra, corr, out);
      for (int i = 0; i < 3; ++i) {
        X[i] = out[i].a;
        for (int k = 0; k < kModel; ++k) dX[i][k] = out[i].v[k];
      }
    } else {
      Board::Point(x_, static_cast<const double*>(nullptr), static_cast<const double*>(nullptr), X);
    }

    if (jacobians == nullptr) {
      double xc[3], uv[2];
      TransformPoint(frame, X, xc);
      if (kRig) {
        double xk[3];
        TransformPoint(rig, xc, xk);
        std::copy(xk, xk + 3, xc);
      }
      if (!Lens::Project(intrinsics, xc, uv)) return false;
      r[0] = w_ * (u_ - uv[0]);
      r[1] = w_ * (v_ - uv[1]);
      return true;
    }

    // xc = R X + t, its pose derivatives in closed form; dxc/dX = R.
    double xc[3], R[9], dxc_dw[9];
    TransformPointWithJacobian(frame, X, xc, R, dxc_dw);

    // Rig: xk = R_k xc + t_k; dxk/dxc = R_k.
    double cam[3] = {xc[0], xc[1], xc[2]};
    double dcam_dxc[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    double dcam_drig[3][kPoseSize] = {};
    if (kRig) {
      double dk_dw[9];
      TransformPointWithJacobian(rig, xc, cam, dcam_dxc, dk_dw);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) dcam_drig[i][j] = dk_dw[3 * i + j];
        dcam_drig[i][3 + i] = 1.0;
      }
    }

    // Projection and its Jacobian over intrinsics and the camera point.
    constexpr int kLens = Lens::kNumParams;
    double uv[2], duv[2][kLens + 3];
    if (!Lens::ProjectWithJacobian(intrinsics, cam, uv, &duv[0][0])) return false;
    r[0] = w_ * (u_ - uv[0]);
    r[1] = w_ * (v_ - uv[1]);

    // dr/dcam (2x3) and dr/dxc = dr/dcam * dcam/dxc.
    double dr_dcam[2][3], dr_dxc[2][3];
    for (int k = 0; k < 2; ++k) {
      for (int c = 0; c < 3; ++c) dr_dcam[k][c] = -w_ * duv[k][kLens + c];
      for (int c = 0; c < 3; ++c) {
        dr_dxc[k][c] = dr_dcam[k][0] * dcam_dxc[c] + dr_dcam[k][1] * dcam_dxc[3 + c] +
                       dr_dcam[k][2] * dcam_dxc[6 + c];
      }
    }
    int b = 0;
    if (double* J = jacobians[b++]) {
      for (int k = 0; k < 2; ++k)
        for (int i = 0; i < kLens; ++i) J[k * kLens + i] = -w_ * duv[k][i];
    }
    if (kRig) {
      if (double* J = jacobians[b]) {
        for (int k = 0; k < 2; ++k)
          for (int j = 0; j < kPoseSize; ++j)
            J[k * kPoseSize + j] = dr_dcam[k][0] * dcam_drig[0][j] + dr_dcam[k][1] * dcam_drig[1][j] +
                                   dr_dcam[k][2] * dcam_drig[2][j];
      }
      ++b;
    }
    // dr/dX = dr/dxc * R, used for the model's parameters.
    double dr_dX[2][3];
    for (int k = 0; k < 2; ++k)
      for (int m = 0; m < 3; ++m)
        dr_dX[k][m] = dr_dxc[k][0] * R[m] + dr_dxc[k][1] * R[3 + m] + dr_dxc[k][2] * R[6 + m];
    if (double* J = jacobians[b]) {
      for (int k = 0; k < 2; ++k) {
        for (int j = 0; j < 3; ++j) {
          J[k * kFrameSize + j] = dr_dxc[k][0] * dxc_dw[j] + dr_dxc[k][1] * dxc_dw[3 + j] +
                                  dr_dxc[k][2] * dxc_dw[6 + j];
          J[k * kFrameSize + 3 + j] = dr_dxc[k][j];
        }
        for (int e = 0; e < Board::kFrameExtra; ++e) {
          J[k * kFrameSize + kPoseSize + e] =
              dr_dX[k][0] * dX[0][e] + dr_dX[k][1] * dX[1][e] + dr_dX[k][2] * dX[2][e];
        }
      }
    }
    ++b;
    if (Board::kCornerSize > 0) {
      if (double* J = jacobians[b]) {
        const int width = parameter_block_sizes()[b];
        if (width != Board::kCornerSize) std::fill(J, J + 2 * width, 0.0);
        for (int k = 0; k < 2; ++k)
          for (int c = 0; c < Board::kCornerSize; ++c) {
            const int m = Board::kFrameExtra + c;
            J[k * width + corner_offset_ + c] =
                dr_dX[k][0] * dX[0][m] + dr_dX[k][1] * dX[1][m] + dr_dX[k][2] * dX[2][m];
          }
      }
    }
    return true;
  }

 private:
  double u_, v_, w_;
  double x_[3];
  int corner_offset_ = 0;
};

// Cauchy's rho(s) = a^2 ln(1 + s/a^2) folded into a corner's residual, since a
// cost function with several corners cannot hand Ceres a per-corner
// LossFunction (Ceres applies one to the whole block).  The residual becomes
// r~ = f r with f = sqrt(rho(s)/s), so |r~|^2 = rho(|r|^2) and the cost and its
// gradient are the loss's exactly: the optimum is the same.  The Jacobian is
// M J with M = sqrt(rho') P_t + (rho'/f) P_r (P_r = r r^T/s, P_t = I - P_r):
// radially the exact derivative of r~, tangentially the sqrt(rho') of Ceres'
// own (clamped Triggs) correction, which is exact there, so the Gauss-Newton
// model is closer to the loss's Hessian than either alone (fewer iterations).
struct CauchyFold {
  double a2 = 0.0;  // squared scale; 0 means no loss

  // f, and M's tangential and radial factors.
  void Scale(double s, double* f, double* mt, double* mr) const {
    if (a2 == 0.0) {
      *f = *mt = *mr = 1.0;
      return;
    }
    const double x = s / a2;
    const double drho = 1.0 / (1.0 + x);  // rho'(s)
    // rho(s)/s; the closed form cancels near zero, where the series is exact.
    const double rho_s = x < 1e-6 ? 1.0 - x / 2.0 + x * x / 3.0 : std::log1p(x) / x;
    *f = std::sqrt(rho_s);
    *mt = std::sqrt(drho);
    *mr = drho / *f;
  }

  // f and M = mt I + (mr - mt) e e^T / s for the residual e (s = |e|^2).
  void Fold(const double e[2], double* f, double M[2][2]) const {
    const double s = e[0] * e[0] + e[1] * e[1];
    double mt, mr;
    Scale(s, f, &mt, &mr);
    M[0][0] = M[1][1] = mt;
    M[0][1] = M[1][0] = 0.0;
    if (mr != mt && s > 0.0) {
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) M[a][b] += (mr - mt) * e[a] * e[b] / s;
    }
  }
};

// A one-corner block with the Cauchy loss folded in as a view block folds it
// (CauchyFold), for a static correction's per-corner blocks: with Ceres' own
// LossFunction (the loss's curvature dropped from Gauss-Newton) its stage took
// more iterations, each step about half the one before.  The cost and the
// optimum are the loss's; a loss scale factor of 0 gives the plain residual, as
// for the view blocks.
class FoldedCorner final : public ceres::CostFunction {
 public:
  FoldedCorner(ceres::CostFunction* corner, CauchyFold loss, std::shared_ptr<const double> loss_scale_factor)
      : corner_(corner), loss_(loss), loss_scale_factor_(std::move(loss_scale_factor)) {
    set_num_residuals(2);
    *mutable_parameter_block_sizes() = corner->parameter_block_sizes();
  }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    if (!corner_->Evaluate(p, r, jacobians)) return false;
    const double k = *loss_scale_factor_;
    const CauchyFold loss{loss_.a2 * k * k};
    double f, M[2][2];
    loss.Fold(r, &f, M);
    r[0] *= f;
    r[1] *= f;
    if (jacobians == nullptr) return true;
    const std::vector<int32_t>& sizes = parameter_block_sizes();
    for (size_t b = 0; b < sizes.size(); ++b) {
      double* J = jacobians[b];
      if (J == nullptr) continue;
      const int n = sizes[b];
      for (int c = 0; c < n; ++c) {
        const double j0 = J[c], j1 = J[n + c];
        J[c] = M[0][0] * j0 + M[0][1] * j1;
        J[n + c] = M[1][0] * j0 + M[1][1] * j1;
      }
    }
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> corner_;
  CauchyFold loss_;
  std::shared_ptr<const double> loss_scale_factor_;
};

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

// ViewBlock hides the lens and board so that the assembly collects views of
// several lens models in one map.
class ViewBlock : public ceres::CostFunction {
 public:
  virtual void Add(double u, double v, double w, const double* x) = 0;
  // Fixes the block layout once every corner is added.
  virtual void Finish() = 0;
};

template <class Lens, class Board, bool kRig>
class ViewReprojection final : public ViewBlock {
 public:
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  static constexpr int kModel = Board::kFrameExtra + Board::kCornerSize;

  ViewReprojection(CauchyFold loss, std::shared_ptr<const double> loss_scale_factor)
      : loss_(loss), loss_scale_factor_(std::move(loss_scale_factor)) {}

  void Add(double u, double v, double w, const double* x) override {
    obs_.push_back({u, v, w, {x[0], x[1], x[2]}});
  }
  void Finish() override {
    set_num_residuals(2 * static_cast<int>(obs_.size()));
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(Lens::kNumParams);
    if (kRig) sizes->push_back(kPoseSize);
    sizes->push_back(kFrameSize);
    if (Board::kCornerSize > 0) {
      for (size_t i = 0; i < obs_.size(); ++i) sizes->push_back(Board::kCornerSize);
    }
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const double* intrinsics = p[0];
    const double* rig = kRig ? p[1] : nullptr;
    const int fb = kRig ? 2 : 1;
    const double* frame = p[fb];
    const double k = *loss_scale_factor_;
    const CauchyFold loss{loss_.a2 * k * k};
    const size_t n = obs_.size();
    double R[9], Jl[9], Rk[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, Jlk[9];
    RotationAndJacobian(frame, R, Jl);
    if (kRig) RotationAndJacobian(rig, Rk, Jlk);
    double* Ji = jacobians ? jacobians[0] : nullptr;
    double* Jr = jacobians && kRig ? jacobians[1] : nullptr;
    double* Jf = jacobians ? jacobians[fb] : nullptr;
    if (jacobians && Board::kCornerSize > 0) {
      for (size_t i = 0; i < n; ++i) {
        if (double* Jc = jacobians[fb + 1 + i]) {
          std::fill(Jc, Jc + 2 * n * Board::kCornerSize, 0.0);
        }
      }
    }
    for (size_t i = 0; i < n; ++i) {
      const Obs& o = obs_[i];
      const double* corner = Board::kCornerSize > 0 ? p[fb + 1 + i] : nullptr;
      double X[3];
      double dX[3][kModel > 0 ? kModel : 1] = {};
      BoardPoint(o.x, frame + kPoseSize, corner, X, dX);
      double y[3], xc[3], cam[3];
      for (int a = 0; a < 3; ++a) {
        y[a] = R[3 * a] * X[0] + R[3 * a + 1] * X[1] + R[3 * a + 2] * X[2];
        xc[a] = y[a] + frame[3 + a];
      }
      for (int a = 0; a < 3; ++a) {
        cam[a] = kRig ? Rk[3 * a] * xc[0] + Rk[3 * a + 1] * xc[1] + Rk[3 * a + 2] * xc[2] + rig[3 + a]
                      : xc[a];
      }
      double* ri = r + 2 * i;
      if (jacobians == nullptr) {
        double uv[2];
        if (!Lens::Project(intrinsics, cam, uv)) return false;
        ri[0] = o.w * (o.u - uv[0]);
        ri[1] = o.w * (o.v - uv[1]);
        double f, mt, mr;
        loss.Scale(ri[0] * ri[0] + ri[1] * ri[1], &f, &mt, &mr);
        ri[0] *= f;
        ri[1] *= f;
        continue;
      }
      constexpr int kLens = Lens::kNumParams;
      double uv[2], duv[2][kLens + 3];
      if (!Lens::ProjectWithJacobian(intrinsics, cam, uv, &duv[0][0])) return false;
      const double e[2] = {o.w * (o.u - uv[0]), o.w * (o.v - uv[1])};
      double f, M[2][2];
      loss.Fold(e, &f, M);
      ri[0] = f * e[0];
      ri[1] = f * e[1];
      // dr~/dintrinsics and dr~/dcam: -w M duv.
      double dcam[2][3];
      for (int a = 0; a < 2; ++a) {
        for (int k = 0; k < kLens + 3; ++k) {
          const double d = -o.w * (M[a][0] * duv[0][k] + M[a][1] * duv[1][k]);
          if (k < kLens) {
            if (Ji) Ji[(2 * i + a) * kLens + k] = d;
          } else {
            dcam[a][k - kLens] = d;
          }
        }
      }
      // dr~/dxc = dcam Rk (identity without a rig).
      double dxc[2][3];
      for (int a = 0; a < 2; ++a)
        for (int c = 0; c < 3; ++c)
          dxc[a][c] = dcam[a][0] * Rk[c] + dcam[a][1] * Rk[3 + c] + dcam[a][2] * Rk[6 + c];
      if (kRig && Jr) {
        // dcam/dw_k = -[Rk xc]_x Jlk, dcam/dt_k = I.
        double yk[3];
        for (int a = 0; a < 3; ++a) yk[a] = cam[a] - rig[3 + a];
        double Dk[9];
        SkewTimes(yk, Jlk, Dk);
        for (int a = 0; a < 2; ++a) {
          double* row = Jr + (2 * i + a) * kPoseSize;
          for (int c = 0; c < 3; ++c) {
            row[c] = dcam[a][0] * Dk[c] + dcam[a][1] * Dk[3 + c] + dcam[a][2] * Dk[6 + c];
            row[3 + c] = dcam[a][c];
          }
        }
      }
      // dr~/dX = dxc R.
      double dXr[2][3];
      for (int a = 0; a < 2; ++a)
        for (int m = 0; m < 3; ++m)
          dXr[a][m] = dxc[a][0] * R[m] + dxc[a][1] * R[3 + m] + dxc[a][2] * R[6 + m];
      if (Jf) {
        double D[9];
        SkewTimes(y, Jl, D);  // dxc/dw = -[y]_x Jl
        for (int a = 0; a < 2; ++a) {
          double* row = Jf + (2 * i + a) * kFrameSize;
          for (int c = 0; c < 3; ++c) {
            row[c] = dxc[a][0] * D[c] + dxc[a][1] * D[3 + c] + dxc[a][2] * D[6 + c];
            row[3 + c] = dxc[a][c];
          }
          for (int m = 0; m < Board::kFrameExtra; ++m)
            row[kPoseSize + m] = dXr[a][0] * dX[0][m] + dXr[a][1] * dX[1][m] + dXr[a][2] * dX[2][m];
        }
      }
      if (Board::kCornerSize > 0) {
        if (double* Jc = jacobians[fb + 1 + i]) {
          for (int a = 0; a < 2; ++a)
            for (int c = 0; c < Board::kCornerSize; ++c) {
              const int m = Board::kFrameExtra + c;
              Jc[(2 * i + a) * Board::kCornerSize + c] =
                  dXr[a][0] * dX[0][m] + dXr[a][1] * dX[1][m] + dXr[a][2] * dX[2][m];
            }
        }
      }
    }
    return true;
  }

 private:
  struct Obs {
    double u, v, w;
    double x[3];
  };

  // R(w) and the left Jacobian J_l of the rotation (TransformPointWithJacobian's).
  static void RotationAndJacobian(const double* pose, double* R, double* Jl) {
    RotationWithLeftJacobian(pose, R, Jl);
  }
  // D = -[y]_x J.
  static void SkewTimes(const double* y, const double* J, double* D) {
    const double S[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        D[3 * a + b] = S[3 * a] * J[b] + S[3 * a + 1] * J[3 + b] + S[3 * a + 2] * J[6 + b];
  }
  // The board point and its derivatives over the model's parameters (Jets).
  static void BoardPoint(const double* x, const double* extra_in, const double* corner_in,
                         double* X, double (*dX)[kModel > 0 ? kModel : 1]) {
    if constexpr (kModel > 0) {
      using JM = ceres::Jet<double, kModel>;
      JM extra[Board::kFrameExtra > 0 ? Board::kFrameExtra : 1];
      JM corr[Board::kCornerSize > 0 ? Board::kCornerSize : 1];
      for (int e = 0; e < Board::kFrameExtra; ++e) extra[e] = JM(extra_in[e], e);
      for (int c = 0; c < Board::kCornerSize; ++c) corr[c] = JM(corner_in[c], Board::kFrameExtra + c);
      JM out[3];
      Board::Point(x, extra, corr, out);
      for (int i = 0; i < 3; ++i) {
        X[i] = out[i].a;
        for (int k = 0; k < kModel; ++k) dX[i][k] = out[i].v[k];
      }
    } else {
      Board::Point(x, static_cast<const double*>(nullptr), static_cast<const double*>(nullptr), X);
    }
  }

  CauchyFold loss_;
  std::shared_ptr<const double> loss_scale_factor_;
  std::vector<Obs> obs_;
};

// Residuals of the corners of one view when only the board pose is free (a
// test-error refit): board points, intrinsics and rig pose are constants, the
// rotation is applied once per view, and the Jets carry 6 derivatives.  Without
// a robust loss one block holds a whole view; with one, a single corner.
// PoseOnlyView hides the lens so that views of several lens models share a map.
class PoseOnlyView {
 public:
  virtual ~PoseOnlyView() = default;
  virtual void Add(double u, double v, double w, const double* board_point) = 0;
  // Hands the functor to a new cost function, which owns it.
  virtual ceres::CostFunction* Release() = 0;
};

template <class Lens>
class ViewPoseError {
 public:
  ViewPoseError(const double* intrinsics, const double* rig) : has_rig_(rig != nullptr) {
    std::copy(intrinsics, intrinsics + Lens::kNumParams, intrinsics_);
    if (rig) std::copy(rig, rig + kPoseSize, rig_);
  }

  void Add(double u, double v, double w, const double* board_point) {
    uv_.push_back(u);
    uv_.push_back(v);
    w_.push_back(w);
    points_.insert(points_.end(), board_point, board_point + 3);
  }
  int NumResiduals() const { return static_cast<int>(uv_.size()); }

  template <typename T>
  bool operator()(const T* const pose, T* r) const {
    T rotation[9];
    ceres::AngleAxisToRotationMatrix(pose, ceres::RowMajorAdapter3x3(rotation));
    T intrinsics[Lens::kNumParams];
    for (int i = 0; i < Lens::kNumParams; ++i) intrinsics[i] = T(intrinsics_[i]);
    for (size_t k = 0; k < uv_.size() / 2; ++k) {
      const double* x = &points_[3 * k];
      T xc[3];
      for (int i = 0; i < 3; ++i) {
        xc[i] = rotation[3 * i] * x[0] + rotation[3 * i + 1] * x[1] + rotation[3 * i + 2] * x[2] +
                pose[3 + i];
      }
      if (has_rig_) {
        T rig[kPoseSize], xk[3];
        for (int i = 0; i < kPoseSize; ++i) rig[i] = T(rig_[i]);
        TransformPoint(rig, xc, xk);
        std::copy(xk, xk + 3, xc);
      }
      T uv[2];
      if (!Lens::Project(intrinsics, xc, uv)) return false;
      r[2 * k] = w_[k] * (T(uv_[2 * k]) - uv[0]);
      r[2 * k + 1] = w_[k] * (T(uv_[2 * k + 1]) - uv[1]);
    }
    return true;
  }

 private:
  bool has_rig_;
  double intrinsics_[Lens::kNumParams];
  double rig_[kPoseSize] = {};
  std::vector<double> uv_, w_, points_;
};

template <class Lens>
class PoseOnlyViewOf final : public PoseOnlyView {
 public:
  PoseOnlyViewOf(const double* intrinsics, const double* rig)
      : f_(new ViewPoseError<Lens>(intrinsics, rig)) {}
  ~PoseOnlyViewOf() override { delete f_; }
  void Add(double u, double v, double w, const double* board_point) override {
    f_->Add(u, v, w, board_point);
  }
  ceres::CostFunction* Release() override {
    const int n = f_->NumResiduals();
    auto* cost =
        new ceres::AutoDiffCostFunction<ViewPoseError<Lens>, ceres::DYNAMIC, kPoseSize>(f_, n);
    f_ = nullptr;
    return cost;
  }

 private:
  ViewPoseError<Lens>* f_;
};

}  // namespace deformcal
