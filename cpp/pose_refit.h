// Pose-only refits (the protocol's test error): with the intrinsics, the rig,
// the board model's parameters held and no robust loss, a calibration problem
// falls apart into one 6-parameter least squares per frame.  Each is solved on
// its own by Levenberg-Marquardt on closed-form 6x6 normal equations, without a
// Ceres problem: the joint solve spent most of its time building and factoring a
// block-diagonal system.  A refit prepared for many intrinsics starts each
// frame from its optimum under the prepared ones moved to first order
// (PoseSensitivity).  Knows nothing of how the problem data are laid out.
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <memory>
#include <vector>

#include "deformcal/cpp/camera.h"

namespace deformcal {

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

// One corner of a view: its observed pixel, weight and held board point.
struct PoseCorner {
  double u, v, w;
  double x[3];
};

// What one evaluation of a frame's views sums at a pose.
struct FrameSums {
  double cost = 0.0;           // 1/2 |r|^2 of the weighted residuals
  double squared_error = 0.0;  // |observed - projected|^2, unweighted (the test error's)
  Matrix6 jtj = Matrix6::Zero();  // J^T J over the pose (angle-axis, then translation)
  Vector6 jtr = Vector6::Zero();  // J^T r
};

// What a pass over a frame's corners sums besides the cost and squared error.
enum class PoseSums { kGradient, kNormals };

// One camera's corners in one frame, their board points held; PoseView hides
// the lens so that the views of one frame may mix lens models.
class PoseView {
 public:
  virtual ~PoseView() = default;
  // Adds the view's cost, squared error and J^T r at `pose` to `s`, and with
  // kNormals J^T J.  False where a point has no image.
  virtual bool Accumulate(const double* pose, PoseSums what, FrameSums* s) const = 0;
  // Adds J^T J (upper triangle) to `jtj` and, row-major 6 x NumIntrinsics(),
  // J^T J_intrinsics to `coupling`: how the optimal pose moves with the
  // intrinsics, to first order.  False where a point has no image.
  virtual bool Coupling(const double* pose, Matrix6* jtj, double* coupling) const = 0;
  virtual int NumIntrinsics() const = 0;
  // The weighted residuals w (observed - projected), two per corner in order.
  virtual bool Residuals(const double* pose, double* r) const = 0;
};

// The residuals of ViewPoseError (residuals.h), with the Jacobian chained by
// hand: the projection's by Lens::ProjectWithJacobian (closed form), and
// d(R X)/dw = -[R X]_x J_l(w).  The normal equations are summed over the left
// perturbation of the rotation (-[R X]_x alone) and taken through J_l once per
// view: J_l is the same for every corner, and the product per corner was a
// third of the refit's arithmetic.  The view without a rig (the protocol's one
// camera) has its own loop, free of the rig's transform and its branches.
template <class Lens>
class PoseViewOf final : public PoseView {
 public:
  static constexpr int kIntrinsics = Lens::kNumParams;

  // `corners` must outlive the view.
  PoseViewOf(const double* intrinsics, const double* rig, const std::vector<PoseCorner>& corners)
      : has_rig_(rig != nullptr), obs_(corners) {
    for (int i = 0; i < kIntrinsics; ++i) intrinsics_[i] = intrinsics[i];
    if (has_rig_) {
      double unused[9];
      RotationWithLeftJacobian(rig, rig_rotation_, unused);
      for (int i = 0; i < 3; ++i) rig_translation_[i] = rig[3 + i];
    }
  }

  bool Accumulate(const double* pose, PoseSums what, FrameSums* s) const override {
    if (what == PoseSums::kGradient) {
      return has_rig_ ? Pass<true, false>(pose, s, nullptr) : Pass<false, false>(pose, s, nullptr);
    }
    return has_rig_ ? Pass<true, true>(pose, s, nullptr) : Pass<false, true>(pose, s, nullptr);
  }

  bool Coupling(const double* pose, Matrix6* jtj, double* coupling) const override {
    FrameSums s;
    const bool ok = has_rig_ ? Pass<true, true>(pose, &s, coupling) : Pass<false, true>(pose, &s, coupling);
    *jtj += s.jtj;
    return ok;
  }

  int NumIntrinsics() const override { return kIntrinsics; }

  bool Residuals(const double* pose, double* r) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    for (size_t i = 0; i < obs_.size(); ++i) {
      const PoseCorner& o = obs_[i];
      double y[3], cam[3], uv[2];
      Camera<true>(R, pose, o.x, y, cam);
      if (!Lens::Project(intrinsics_, cam, uv)) return false;
      r[2 * i] = o.w * (o.u - uv[0]);
      r[2 * i + 1] = o.w * (o.v - uv[1]);
    }
    return true;
  }

 private:
  // One pass over the corners: cost, squared error and J^T r, with kNormals
  // J^T J, with `coupling` J^T J_intrinsics too.  Flattened: with the projection
  // inlined, its unused Jacobian over the intrinsics is never computed.
  template <bool kRig, bool kNormals>
  [[gnu::flatten]] bool Pass(const double* pose, FrameSums* s, double* coupling) const {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    constexpr int n = kIntrinsics + 3;
    // Over (left rotation perturbation, translation): the upper triangle of
    // J^T J row by row, then J^T r, as plain sums the compiler keeps in registers.
    double sums[27] = {};
    double cost = 0.0, squared = 0.0;
    for (const PoseCorner& o : obs_) {
      double y[3], cam[3], uv[2], J[2 * n];
      Camera<kRig>(R, pose, o.x, y, cam);
      if (!Lens::ProjectWithJacobian(intrinsics_, cam, uv, J)) return false;
      const double du = o.u - uv[0], dv = o.v - uv[1];
      squared += du * du + dv * dv;
      const double e[2] = {o.w * du, o.w * dv};
      cost += e[0] * e[0] + e[1] * e[1];
      {
        double row[2][6];
        for (int a = 0; a < 2; ++a) {
          // dr/dxc = -w duv/dcam Rk (Rk the identity without a rig).
          const double* dcam = J + a * n + kIntrinsics;
          double* d = row[a] + 3;
          for (int c = 0; c < 3; ++c) {
            d[c] = kRig ? -o.w * (dcam[0] * rig_rotation_[c] + dcam[1] * rig_rotation_[3 + c] +
                                  dcam[2] * rig_rotation_[6 + c])
                        : -o.w * dcam[c];
          }
          // dxc/dw_left = -[y]_x, dxc/dt = I.
          row[a][0] = d[2] * y[1] - d[1] * y[2];
          row[a][1] = d[0] * y[2] - d[2] * y[0];
          row[a][2] = d[1] * y[0] - d[0] * y[1];
        }
        if constexpr (kNormals) {
          int at = 0;
#pragma GCC unroll 6
          for (int i = 0; i < 6; ++i) {
#pragma GCC unroll 6
            for (int k = i; k < 6; ++k) sums[at++] += row[0][i] * row[0][k] + row[1][i] * row[1][k];
          }
        }
#pragma GCC unroll 6
        for (int i = 0; i < 6; ++i) sums[21 + i] += row[0][i] * e[0] + row[1][i] * e[1];
        if (kNormals && coupling != nullptr) {
          // dr/dintrinsics = -w duv/dintrinsics; summed over the left perturbation too.
          for (int i = 0; i < 6; ++i) {
            for (int q = 0; q < kIntrinsics; ++q) {
              coupling[i * kIntrinsics + q] -= o.w * (row[0][i] * J[q] + row[1][i] * J[n + q]);
            }
          }
        }
      }
    }
    s->cost += 0.5 * cost;
    s->squared_error += squared;
    // Through dw_left/dw = J_l: A <- T^T A T, g <- T^T g with T = diag(J_l, I).
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> L(Jl);
    Vector6 g;
    for (int i = 0; i < 6; ++i) g(i) = sums[21 + i];
    s->jtr.head<3>() += L.transpose() * g.head<3>();
    s->jtr.tail<3>() += g.tail<3>();
    if constexpr (kNormals) {
      Matrix6 A;
      for (int i = 0, at = 0; i < 6; ++i) {
        for (int k = i; k < 6; ++k, ++at) A(i, k) = A(k, i) = sums[at];
      }
      Matrix6 T = Matrix6::Identity();
      T.topLeftCorner<3, 3>() = L;
      s->jtj += T.transpose() * A * T;
      if (coupling != nullptr) {
        // The rotation's rows of J^T J_intrinsics through J_l as well (rows 0-2).
        Eigen::Map<Eigen::Matrix<double, 6, kIntrinsics, Eigen::RowMajor>> C(coupling);
        const Eigen::Matrix<double, 3, kIntrinsics> top = L.transpose() * C.template topRows<3>();
        C.template topRows<3>() = top;
      }
    }
    return true;
  }

  // y = R x, and the point in the camera: R x + t, through the rig with kRig.
  template <bool kRig>
  void Camera(const double* R, const double* pose, const double* x, double* y, double* cam) const {
    double xc[3];
    for (int a = 0; a < 3; ++a) {
      y[a] = R[3 * a] * x[0] + R[3 * a + 1] * x[1] + R[3 * a + 2] * x[2];
      xc[a] = y[a] + pose[3 + a];
    }
    for (int a = 0; a < 3; ++a) {
      cam[a] = kRig ? rig_rotation_[3 * a] * xc[0] + rig_rotation_[3 * a + 1] * xc[1] +
                          rig_rotation_[3 * a + 2] * xc[2] + rig_translation_[a]
                    : xc[a];
    }
  }

  bool has_rig_;
  double intrinsics_[kIntrinsics];
  double rig_rotation_[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  double rig_translation_[3] = {0, 0, 0};
  const std::vector<PoseCorner>& obs_;
};

// How one frame's refit ended.
struct PoseRefitResult {
  bool ok = false;         // every evaluation had an image of every point
  bool converged = false;  // stopped by its tolerance, not by the iteration limit
  int iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
  double squared_error = 0.0;  // the unweighted residuals' at the final pose
};

// The cost, squared error, J^T r and, with kNormals, J^T J of a frame's views at `pose`.
inline bool FrameSumsAt(const std::vector<std::unique_ptr<PoseView>>& views, const double* pose,
                        PoseSums what, FrameSums* s) {
  *s = FrameSums();
  for (const auto& v : views) {
    if (!v->Accumulate(pose, what, s)) return false;
  }
  if (what == PoseSums::kNormals) s->jtj = s->jtj.selfadjointView<Eigen::Upper>();
  return std::isfinite(s->cost);
}

// The cost decrease, relative to the cost, at which a frame's refit has
// converged: far below what a test error shows (its RMSE is then within about
// 1e-12 of the optimum's, relatively), so that it does not depend on where a
// solver tolerance happened to stop.
constexpr double kPoseRefitTolerance = 1e-12;

// A step whose gain on the quadratic model is below this, relative to the
// cost, is among the last of a refit: its trial sums the gradient alone and
// the next step keeps the normal matrix, which changes little over so short a
// step (the steps after it still converge within a step or two).  Measured on
// the protocol: 15.2 us per frame against 15.8 with 1e-6; 1e-2 saved a little
// more, but a matrix kept from further away slows refits from far starts.
constexpr double kKeepNormalsBelow = 1e-4;

// Levenberg-Marquardt on one frame's pose (6 values, in place), started as
// Gauss-Newton: the start (the reference's pose, or its first-order
// prediction) is close to the optimum.  Each trial forms its gradient (and,
// far from the optimum, its normal matrix) on the way, so that an accepted
// step needs no second pass; converged where the next step would gain below
// the tolerance, or the last one did.
inline PoseRefitResult RefitFramePose(const std::vector<std::unique_ptr<PoseView>>& views,
                                      double* pose, int max_iterations) {
  PoseRefitResult out;
  FrameSums at, trial;
  if (!FrameSumsAt(views, pose, PoseSums::kNormals, &at)) return out;
  out.ok = true;
  out.initial_cost = at.cost;
  Matrix6 A = at.jtj;  // the normal matrix: at x, or kept from a point just before
  bool kept = false;
  double mu = 0.0;  // damping, relative to diag(A)
  Eigen::Map<Vector6> x(pose);
  while (out.iterations < max_iterations) {
    Matrix6 M = A;
    M.diagonal() *= 1.0 + mu;
    const Vector6 dx = M.ldlt().solve(-at.jtr);
    // What the step gains on the quadratic model: below round-off, x is the optimum.
    const double gain = -at.jtr.dot(dx) - 0.5 * dx.dot(A * dx);
    if (!(gain > kPoseRefitTolerance * at.cost)) {
      out.converged = dx.allFinite();
      if (out.converged || mu > 1e12) break;
    }
    ++out.iterations;
    const Vector6 xn = x + dx;
    const PoseSums what = gain < kKeepNormalsBelow * at.cost ? PoseSums::kGradient : PoseSums::kNormals;
    if (dx.allFinite() && FrameSumsAt(views, xn.data(), what, &trial) && trial.cost <= at.cost) {
      const bool done = at.cost - trial.cost <= kPoseRefitTolerance * at.cost;
      x = xn;
      at = trial;
      kept = what == PoseSums::kGradient;
      if (!kept) A = at.jtj;
      mu = mu < 1e-9 ? 0.0 : mu / 10.0;
      if (done) {
        out.converged = true;
        break;
      }
    } else if (kept) {
      // Rejected with a kept normal matrix: first the normal matrix at x.
      out.ok = FrameSumsAt(views, pose, PoseSums::kNormals, &at);
      if (!out.ok) return out;
      A = at.jtj;
      kept = false;
    } else {
      // Rejected: damp harder (the ratio of Levenberg-Marquardt's schedule).
      mu = mu == 0.0 ? 1e-6 : 10.0 * mu;
      if (mu > 1e12) break;
    }
  }
  out.final_cost = at.cost;
  out.squared_error = at.squared_error;
  return out;
}

// How a frame's optimal pose moves with its views' intrinsics, to first order
// (the implicit function of J^T r = 0, the residuals' second derivatives
// neglected): S = (J^T J)^-1 J^T J_intrinsics, 6 x (the views' intrinsics in
// view order), column-major; the optimum under intrinsics moved by d is about
// pose - S d.  Evaluated at an optimum `pose`; false where a point has no image
// or the normal equations are singular.
inline bool PoseSensitivity(const std::vector<std::unique_ptr<PoseView>>& views, const double* pose,
                            std::vector<double>* sensitivity) {
  int n = 0;
  for (const auto& v : views) n += v->NumIntrinsics();
  Matrix6 A = Matrix6::Zero();
  Eigen::Matrix<double, 6, Eigen::Dynamic> C(6, n);
  std::vector<double> coupling;
  int at = 0;
  for (const auto& v : views) {
    const int m = v->NumIntrinsics();
    coupling.assign(6 * m, 0.0);
    if (!v->Coupling(pose, &A, coupling.data())) return false;
    C.middleCols(at, m) =
        Eigen::Map<const Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor>>(coupling.data(), 6, m);
    at += m;
  }
  const Eigen::LDLT<Matrix6> ldlt(A.selfadjointView<Eigen::Upper>());
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
  const Eigen::Matrix<double, 6, Eigen::Dynamic> S = ldlt.solve(C);
  if (!S.allFinite()) return false;
  sensitivity->assign(S.data(), S.data() + S.size());
  return true;
}

}  // namespace deformcal
