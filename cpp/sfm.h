// Bundle adjustment of the structure-from-motion experiment (src/solver/sfm.rs):
// camera poses and 3D points against feature observations, the intrinsics held
// constant at the calibration under test, a Cauchy loss.  Reuses the templated
// lens models of lens/registry.h, so every lens model works.  Included once, at
// the end of solver.cc (after solver/*.h: Fail, SilenceGlogOnce).
#pragma once

#include <ceres/ceres.h>

#include <cmath>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "deformcal/cpp/camera.h"

namespace deformcal {
namespace {

// R(ω) and SO(3)'s left Jacobian of one frame's pose, computed once per pose value
// instead of once per residual: a window's few frames are shared by thousands of
// residuals, and the sincos and the two 3x3 matrices were a sixth of the run.  The
// solve is single-threaded and each solve owns its caches, so there is no race.
struct PoseCache {
  double omega[3] = {NAN, NAN, NAN};
  double R[9], Jl[9];
  void Update(const double* w) {
    if (w[0] == omega[0] && w[1] == omega[1] && w[2] == omega[2]) return;
    RotationWithLeftJacobian(w, R, Jl);
    for (int i = 0; i < 3; ++i) omega[i] = w[i];
  }
};

// Observed minus projected pixel of a world point in a camera-from-world pose.
// The Jacobian is chained by hand: the rigid transform's in closed form (as
// TransformPointWithJacobian, with the rotation from the frame's PoseCache), the
// lens's by three-wide Jets on the camera point; nine-wide Jets through the whole
// chain cost four times as much.
template <class Lens>
class BundleResidual : public ceres::SizedCostFunction<2, kPoseSize, 3> {
 public:
  BundleResidual(const double* intrinsics, double u, double v, PoseCache* cache)
      : u_(u), v_(v), cache_(cache) {
    for (int i = 0; i < Lens::kNumParams; ++i) p_[i] = intrinsics[i];
  }
  bool Evaluate(double const* const* params, double* r, double** jac) const override {
    const double* pose = params[0];
    const double* X = params[1];
    cache_->Update(pose);
    const double* R = cache_->R;
    double y[3], xc[3];
    for (int i = 0; i < 3; ++i) y[i] = R[3 * i] * X[0] + R[3 * i + 1] * X[1] + R[3 * i + 2] * X[2];
    for (int i = 0; i < 3; ++i) xc[i] = y[i] + pose[3 + i];
    using J3 = ceres::Jet<double, 3>;
    J3 x[3], p[Lens::kNumParams], uv[2];
    for (int i = 0; i < 3; ++i) x[i] = J3(xc[i], i);
    for (int i = 0; i < Lens::kNumParams; ++i) p[i] = J3(p_[i]);
    if (!Lens::Project(p, x, uv)) return false;
    r[0] = u_ - uv[0].a;
    r[1] = v_ - uv[1].a;
    if (!std::isfinite(r[0]) || !std::isfinite(r[1])) return false;
    if (jac == nullptr) return true;
    // d(R x)/dω = -[y]_× J_l (TransformPointWithJacobian's closed form).
    double d_omega[9] = {};
    if (jac[0] != nullptr) {
      const double* Jl = cache_->Jl;
      const double Ny[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          d_omega[3 * i + j] =
              Ny[3 * i] * Jl[j] + Ny[3 * i + 1] * Jl[3 + j] + Ny[3 * i + 2] * Jl[6 + j];
    }
    for (int row = 0; row < 2; ++row) {
      const auto& g = uv[row].v;  // d uv[row] / d xc
      if (jac[0] != nullptr) {
        for (int c = 0; c < 3; ++c) {
          jac[0][row * kPoseSize + c] =
              -(g[0] * d_omega[c] + g[1] * d_omega[3 + c] + g[2] * d_omega[6 + c]);
          jac[0][row * kPoseSize + 3 + c] = -g[c];
        }
      }
      if (jac[1] != nullptr) {
        for (int c = 0; c < 3; ++c) {
          jac[1][row * 3 + c] = -(g[0] * R[c] + g[1] * R[3 + c] + g[2] * R[6 + c]);
        }
      }
    }
    return true;
  }

 private:
  double p_[Lens::kNumParams];
  double u_, v_;
  PoseCache* cache_;
};

void ValidateBundle(const ffi::BundleData& d) {
  const size_t frames = d.poses.size() / kPoseSize, points = d.points.size() / 3;
  if (d.poses.size() % kPoseSize != 0 || d.points.size() % 3 != 0) Fail("poses or points");
  if (d.held_frames.size() != frames || d.held_points.size() != points) Fail("held flags");
  const size_t n = d.obs_frame.size();
  if (d.obs_point.size() != n || d.obs_uv.size() != 2 * n) Fail("observation sizes");
  for (size_t i = 0; i < n; ++i) {
    if (d.obs_frame[i] >= frames || d.obs_point[i] >= points) Fail("observation index");
  }
  for (double v : d.poses) if (!std::isfinite(v)) Fail("a pose is not finite");
  for (double v : d.points) if (!std::isfinite(v)) Fail("a point is not finite");
  for (double v : d.obs_uv) if (!std::isfinite(v)) Fail("an observation is not finite");
  if (!(d.loss_scale_px >= 0.0) || d.max_iterations < 1) Fail("loss scale or iterations");
}

// Holds the held frames and points, and gives the linear solver its
// elimination order: points first, given rather than searched for (the search
// costs as much as the solve in a window this small).  A pose-only fit (every
// point held) has nothing to eliminate.
void HoldAndOrder(ffi::BundleData& d, ceres::Problem& problem, ceres::Solver::Options& s) {
  for (size_t j = 0; j < d.held_frames.size(); ++j) {
    double* b = d.poses.data() + kPoseSize * j;
    if (d.held_frames[j] && problem.HasParameterBlock(b)) problem.SetParameterBlockConstant(b);
  }
  for (size_t i = 0; i < d.held_points.size(); ++i) {
    double* b = d.points.data() + 3 * i;
    if (d.held_points[i] && problem.HasParameterBlock(b)) problem.SetParameterBlockConstant(b);
  }
  auto* ordering = new ceres::ParameterBlockOrdering;
  size_t free_points = 0;
  for (size_t i = 0; i < d.held_points.size(); ++i) {
    double* b = d.points.data() + 3 * i;
    if (!d.held_points[i] && problem.HasParameterBlock(b)) {
      ordering->AddElementToGroup(b, 0);
      ++free_points;
    }
  }
  for (size_t j = 0; j < d.held_frames.size(); ++j) {
    double* b = d.poses.data() + kPoseSize * j;
    if (!d.held_frames[j] && problem.HasParameterBlock(b)) ordering->AddElementToGroup(b, 1);
  }
  if (free_points > 0) {
    s.linear_solver_type = ceres::DENSE_SCHUR;
    s.linear_solver_ordering.reset(ordering);
  } else {
    s.linear_solver_type = ceres::DENSE_QR;
    delete ordering;
  }
}

}  // namespace

namespace ffi {

BundleReport solve_bundle(BundleData& d) {
  SilenceGlogOnce();
  ValidateBundle(d);
  // One pose cache per frame, and the residuals in a few allocations (not one
  // each): both must outlive the problem, so they are declared before it.
  std::vector<PoseCache> caches(d.held_frames.size());
  std::shared_ptr<void> residuals;
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  po.disable_all_safety_checks = true;  // ValidateBundle checked the indices and values
  ceres::Problem problem(po);
  ceres::CauchyLoss cauchy(d.loss_scale_px > 0.0 ? d.loss_scale_px : 1.0);
  ceres::LossFunction* loss = d.loss_scale_px > 0.0 ? &cauchy : nullptr;
  const bool known = DispatchLens(std::string(d.lens_model), [&](auto lens) {
    using Lens = decltype(lens);
    if (d.intrinsics.size() != static_cast<size_t>(Lens::kNumParams)) Fail("intrinsics size");
    // A deque never moves its elements (cost functions cannot be moved).
    auto costs = std::make_shared<std::deque<BundleResidual<Lens>>>();
    residuals = costs;
    for (size_t i = 0; i < d.obs_frame.size(); ++i) {
      costs->emplace_back(d.intrinsics.data(), d.obs_uv[2 * i], d.obs_uv[2 * i + 1],
                          &caches[d.obs_frame[i]]);
      problem.AddResidualBlock(&costs->back(), loss, d.poses.data() + kPoseSize * d.obs_frame[i],
                               d.points.data() + 3 * d.obs_point[i]);
    }
  });
  if (!known) Fail("unknown lens model `" + std::string(d.lens_model) + "`");
  ceres::Solver::Options s;
  HoldAndOrder(d, problem, s);
  s.max_num_iterations = d.max_iterations;
  s.num_threads = 1;
  s.logging_type = ceres::SILENT;
  s.function_tolerance = 1e-6;
  ceres::Solver::Summary summary;
  BundleReport r{};
  if (problem.NumResidualBlocks() == 0) {
    r.usable = false;
    r.message = "no observations";
    return r;
  }
  ceres::Solve(s, &problem, &summary);
  r.usable = summary.IsSolutionUsable();
  r.converged = summary.termination_type == ceres::CONVERGENCE;
  r.iterations = static_cast<int>(summary.iterations.size());
  r.initial_cost = summary.initial_cost;
  r.final_cost = summary.final_cost;
  r.message = summary.message;
  return r;
}

}  // namespace ffi
}  // namespace deformcal
