// Pose-only refits (the protocol's test error): with the intrinsics, the rig,
// the board model's parameters held and no robust loss, a calibration problem
// falls apart into one 6-parameter least squares per frame.  Each is solved on
// its own by Levenberg-Marquardt on closed-form 6x6 normal equations, without a
// Ceres problem: the joint solve spent most of its time building and factoring a
// block-diagonal system.  Knows nothing of how the problem data are laid out.
#pragma once

#include <ceres/jet.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>
#include <vector>

#include "deformcal/cpp/camera.h"

namespace deformcal {

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

// One camera's corners in one frame, their board points held; PoseView hides
// the lens so that the views of one frame may mix lens models.
class PoseView {
 public:
  virtual ~PoseView() = default;
  virtual void Add(double u, double v, double w, const double* board_point) = 0;
  // Adds the view's cost 1/2 |r|^2 at `pose` and, unless jtj is null, J^T J (its
  // upper triangle) and J^T r over the pose (angle-axis, then translation) to jtj
  // and jtr.  False
  // where a point has no image.
  virtual bool Accumulate(const double* pose, double* cost, Matrix6* jtj, Vector6* jtr) const = 0;
  // The weighted residuals w (observed - projected), two per corner in the order added.
  virtual bool Residuals(const double* pose, double* r) const = 0;
};

// The residuals of ViewPoseError (residuals.h), with the Jacobian chained by
// hand: d(R X)/dw = -[R X]_x J_l(w) in closed form, Jets (3 wide) only over the
// camera point through the projection.
template <class Lens>
class PoseViewOf final : public PoseView {
 public:
  PoseViewOf(const double* intrinsics, const double* rig) : has_rig_(rig != nullptr) {
    for (int i = 0; i < Lens::kNumParams; ++i) {
      intrinsics_[i] = intrinsics[i];
      jet_intrinsics_[i] = J3(intrinsics[i]);
    }
    if (has_rig_) {
      double unused[9];
      RotationWithLeftJacobian(rig, rig_rotation_, unused);
      for (int i = 0; i < 3; ++i) rig_translation_[i] = rig[3 + i];
    }
  }

  void Add(double u, double v, double w, const double* board_point) override {
    obs_.push_back({u, v, w, {board_point[0], board_point[1], board_point[2]}});
  }

  bool Accumulate(const double* pose, double* cost, Matrix6* jtj, Vector6* jtr) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    for (const Obs& o : obs_) {
      double y[3], cam[3];
      Camera(R, pose, o.x, y, cam);
      if (jtj == nullptr) {
        double uv[2];
        if (!Lens::Project(intrinsics_, cam, uv)) return false;
        const double e0 = o.w * (o.u - uv[0]), e1 = o.w * (o.v - uv[1]);
        *cost += 0.5 * (e0 * e0 + e1 * e1);
        continue;
      }
      J3 pc[3], uv[2];
      for (int k = 0; k < 3; ++k) pc[k] = J3(cam[k], k);
      if (!Lens::Project(jet_intrinsics_, pc, uv)) return false;
      const double e[2] = {o.w * (o.u - uv[0].a), o.w * (o.v - uv[1].a)};
      *cost += 0.5 * (e[0] * e[0] + e[1] * e[1]);
      // dr/dxc = -w duv/dcam Rk (Rk the identity without a rig).
      double dxc[2][3];
      for (int a = 0; a < 2; ++a) {
        for (int c = 0; c < 3; ++c) {
          dxc[a][c] = has_rig_ ? -o.w * (uv[a].v[0] * rig_rotation_[c] +
                                         uv[a].v[1] * rig_rotation_[3 + c] +
                                         uv[a].v[2] * rig_rotation_[6 + c])
                               : -o.w * uv[a].v[c];
        }
      }
      // dxc/dw = -[y]_x J_l, dxc/dt = I.
      const double S[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
      double D[9];
      for (int m = 0; m < 3; ++m)
        for (int c = 0; c < 3; ++c)
          D[3 * m + c] = S[3 * m] * Jl[c] + S[3 * m + 1] * Jl[3 + c] + S[3 * m + 2] * Jl[6 + c];
      for (int a = 0; a < 2; ++a) {
        double row[6];
        for (int c = 0; c < 3; ++c) {
          row[c] = dxc[a][0] * D[c] + dxc[a][1] * D[3 + c] + dxc[a][2] * D[6 + c];
          row[3 + c] = dxc[a][c];
        }
        // The upper triangle only; FrameNormals mirrors it.
        for (int i = 0; i < 6; ++i) {
          for (int k = i; k < 6; ++k) (*jtj)(i, k) += row[i] * row[k];
          (*jtr)(i) += row[i] * e[a];
        }
      }
    }
    return true;
  }

  bool Residuals(const double* pose, double* r) const override {
    double R[9], Jl[9];
    RotationWithLeftJacobian(pose, R, Jl);
    for (size_t i = 0; i < obs_.size(); ++i) {
      const Obs& o = obs_[i];
      double y[3], cam[3], uv[2];
      Camera(R, pose, o.x, y, cam);
      if (!Lens::Project(intrinsics_, cam, uv)) return false;
      r[2 * i] = o.w * (o.u - uv[0]);
      r[2 * i + 1] = o.w * (o.v - uv[1]);
    }
    return true;
  }

 private:
  using J3 = ceres::Jet<double, 3>;
  struct Obs {
    double u, v, w;
    double x[3];
  };

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
  J3 jet_intrinsics_[Lens::kNumParams];
  double rig_rotation_[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  double rig_translation_[3] = {0, 0, 0};
  std::vector<Obs> obs_;
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
