// Pose-only refits (the protocol's test error): with the intrinsics, the rig,
// the board model's parameters held and no robust loss, a calibration problem
// falls apart into one 6-parameter least squares per frame.  Each is solved on
// its own by Levenberg-Marquardt on closed-form 6x6 normal equations, without a
// Ceres problem: the joint solve spent most of its time building and factoring a
// block-diagonal system.  Knows nothing of how the problem data are laid out.
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

// One camera's corners in one frame, their board points held; PoseView hides
// the lens so that the views of one frame may mix lens models.
class PoseView {
 public:
  virtual ~PoseView() = default;
  // Adds the view's cost 1/2 |r|^2 at `pose` and, unless jtj is null, J^T J (its
  // upper triangle) and J^T r over the pose (angle-axis, then translation) to jtj
  // and jtr.  False
  // where a point has no image.
  virtual bool Accumulate(const double* pose, double* cost, Matrix6* jtj, Vector6* jtr) const = 0;
  // The weighted residuals w (observed - projected), two per corner in order.
  virtual bool Residuals(const double* pose, double* r) const = 0;
  // Adds the squares of the unweighted residuals (observed - projected) at `pose`.
  virtual bool SquaredError(const double* pose, double* sum) const = 0;
};

// The residuals of ViewPoseError (residuals.h), with the Jacobian chained by
// hand: the projection's by Lens::ProjectWithJacobian (closed form), and
// d(R X)/dw = -[R X]_x J_l(w).  The normal equations are summed over the left
// perturbation of the rotation (-[R X]_x alone) and taken through J_l once per
// view: J_l is the same for every corner, and the product per corner was a
// third of the refit's arithmetic.
template <class Lens>
class PoseViewOf final : public PoseView {
 public:
  // `corners` must outlive the view.
  PoseViewOf(const double* intrinsics, const double* rig, const std::vector<PoseCorner>& corners)
      : has_rig_(rig != nullptr), obs_(corners) {
    for (int i = 0; i < Lens::kNumParams; ++i) intrinsics_[i] = intrinsics[i];
    if (has_rig_) {
      double unused[9];
      RotationWithLeftJacobian(rig, rig_rotation_, unused);
      for (int i = 0; i < 3; ++i) rig_translation_[i] = rig[3 + i];
    }
  }

  // Flattened: with the projection inlined, its unused Jacobian over the
  // intrinsics is never computed.
  [[gnu::flatten]] bool Accumulate(const double* pose, double* cost, Matrix6* jtj,
                                   Vector6* jtr) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    if (jtj == nullptr) {
      for (const PoseCorner& o : obs_) {
        double y[3], cam[3], uv[2];
        Camera(R, pose, o.x, y, cam);
        if (!Lens::Project(intrinsics_, cam, uv)) return false;
        const double e0 = o.w * (o.u - uv[0]), e1 = o.w * (o.v - uv[1]);
        *cost += 0.5 * (e0 * e0 + e1 * e1);
      }
      return true;
    }
    constexpr int n = Lens::kNumParams + 3;
    // Over (left rotation perturbation, translation): the upper triangle of
    // J^T J row by row, then J^T r, as plain sums the compiler keeps in registers.
    double sums[27] = {};
    for (const PoseCorner& o : obs_) {
      double y[3], cam[3], uv[2], J[2 * n];
      Camera(R, pose, o.x, y, cam);
      if (!Lens::ProjectWithJacobian(intrinsics_, cam, uv, J)) return false;
      const double e[2] = {o.w * (o.u - uv[0]), o.w * (o.v - uv[1])};
      *cost += 0.5 * (e[0] * e[0] + e[1] * e[1]);
      double row[2][6];
      for (int a = 0; a < 2; ++a) {
        // dr/dxc = -w duv/dcam Rk (Rk the identity without a rig).
        const double* dcam = J + a * n + Lens::kNumParams;
        double* d = row[a] + 3;
        for (int c = 0; c < 3; ++c) {
          d[c] = has_rig_ ? -o.w * (dcam[0] * rig_rotation_[c] + dcam[1] * rig_rotation_[3 + c] +
                                    dcam[2] * rig_rotation_[6 + c])
                          : -o.w * dcam[c];
        }
        // dxc/dw_left = -[y]_x, dxc/dt = I.
        row[a][0] = d[2] * y[1] - d[1] * y[2];
        row[a][1] = d[0] * y[2] - d[2] * y[0];
        row[a][2] = d[1] * y[0] - d[0] * y[1];
      }
      int at = 0;
#pragma GCC unroll 6
      for (int i = 0; i < 6; ++i) {
#pragma GCC unroll 6
        for (int k = i; k < 6; ++k) sums[at++] += row[0][i] * row[0][k] + row[1][i] * row[1][k];
      }
#pragma GCC unroll 6
      for (int i = 0; i < 6; ++i) sums[21 + i] += row[0][i] * e[0] + row[1][i] * e[1];
    }
    Matrix6 A;
    Vector6 g;
    for (int i = 0, at = 0; i < 6; ++i) {
      for (int k = i; k < 6; ++k, ++at) A(i, k) = A(k, i) = sums[at];
      g(i) = sums[21 + i];
    }
    // Through dw_left/dw = J_l: A <- T^T A T, g <- T^T g with T = diag(J_l, I).
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> L(Jl);
    Matrix6 T = Matrix6::Identity();
    T.topLeftCorner<3, 3>() = L;
    *jtj += T.transpose() * A * T;
    *jtr += T.transpose() * g;
    return true;
  }

  bool Residuals(const double* pose, double* r) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    for (size_t i = 0; i < obs_.size(); ++i) {
      const PoseCorner& o = obs_[i];
      double y[3], cam[3], uv[2];
      Camera(R, pose, o.x, y, cam);
      if (!Lens::Project(intrinsics_, cam, uv)) return false;
      r[2 * i] = o.w * (o.u - uv[0]);
      r[2 * i + 1] = o.w * (o.v - uv[1]);
    }
    return true;
  }

  bool SquaredError(const double* pose, double* sum) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    for (const PoseCorner& o : obs_) {
      double y[3], cam[3], uv[2];
      Camera(R, pose, o.x, y, cam);
      if (!Lens::Project(intrinsics_, cam, uv)) return false;
      const double du = o.u - uv[0], dv = o.v - uv[1];
      *sum += du * du + dv * dv;
    }
    return true;
  }

 private:
  // y = R x, and the point in the camera: R x + t, through the rig if any.
  void Camera(const double* R, const double* pose, const double* x, double* y,
              double* cam) const {
    double xc[3];
    for (int a = 0; a < 3; ++a) {
      y[a] = R[3 * a] * x[0] + R[3 * a + 1] * x[1] + R[3 * a + 2] * x[2];
      xc[a] = y[a] + pose[3 + a];
    }
    for (int a = 0; a < 3; ++a) {
      cam[a] = has_rig_ ? rig_rotation_[3 * a] * xc[0] + rig_rotation_[3 * a + 1] * xc[1] +
                              rig_rotation_[3 * a + 2] * xc[2] + rig_translation_[a]
                        : xc[a];
    }
  }

  bool has_rig_;
  double intrinsics_[Lens::kNumParams];
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
};

// The cost and, with jtj, the normal equations of a frame's views at `pose`.
inline bool FrameNormals(const std::vector<std::unique_ptr<PoseView>>& views, const double* pose,
                         double* cost, Matrix6* jtj, Vector6* jtr) {
  *cost = 0.0;
  if (jtj != nullptr) {
    jtj->setZero();
    jtr->setZero();
  }
  for (const auto& v : views) {
    if (!v->Accumulate(pose, cost, jtj, jtr)) return false;
  }
  if (jtj != nullptr) *jtj = jtj->selfadjointView<Eigen::Upper>();
  return std::isfinite(*cost);
}

// The cost decrease, relative to the cost, at which a frame's refit has
// converged: far below what a test error shows (its RMSE is then within about
// 1e-12 of the optimum's, relatively), so that it does not depend on where a
// solver tolerance happened to stop.
constexpr double kPoseRefitTolerance = 1e-12;

// Levenberg-Marquardt on one frame's pose (6 values, in place), started as
// Gauss-Newton: the start (the reference's pose) is close to the optimum.
inline PoseRefitResult RefitFramePose(const std::vector<std::unique_ptr<PoseView>>& views,
                                      double* pose, int max_iterations) {
  PoseRefitResult out;
  Matrix6 A, An;
  Vector6 g, gn;
  double cost = 0.0;
  if (!FrameNormals(views, pose, &cost, &A, &g)) return out;
  out.ok = true;
  out.initial_cost = out.final_cost = cost;
  double mu = 0.0;  // damping, relative to diag(A)
  Eigen::Map<Vector6> x(pose);
  while (out.iterations < max_iterations) {
    Matrix6 M = A;
    M.diagonal() *= 1.0 + mu;
    const Vector6 dx = M.ldlt().solve(-g);
    // What the step gains on the quadratic model: below round-off, x is the optimum.
    const double gain = -g.dot(dx) - 0.5 * dx.dot(A * dx);
    if (!(gain > kPoseRefitTolerance * cost)) {
      out.converged = dx.allFinite();
      if (out.converged || mu > 1e12) break;
    }
    ++out.iterations;
    const Vector6 xn = x + dx;
    double cn = 0.0;
    if (dx.allFinite() && FrameNormals(views, xn.data(), &cn, &An, &gn) && cn <= cost) {
      const bool done = cost - cn <= kPoseRefitTolerance * cost;
      x = xn;
      cost = cn;
      A = An;
      g = gn;
      mu = mu < 1e-9 ? 0.0 : mu / 10.0;
      if (done) {
        out.converged = true;
        break;
      }
    } else {
      // Rejected: damp harder (the ratio of Levenberg-Marquardt's schedule).
      mu = mu == 0.0 ? 1e-6 : 10.0 * mu;
      if (mu > 1e12) break;
    }
  }
  out.final_cost = cost;
  return out;
}

}  // namespace deformcal
