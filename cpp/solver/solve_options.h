// How a problem is solved: the linear solver and its elimination order, the
// Ceres options, the warm-up decision and progress on stderr.
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "deformcal/cpp/solver/assembled.h"
#include "deformcal/cpp/solver/jacobian.h"

namespace deformcal {
namespace {

// Schur elimination of whichever independent set of blocks (image poses or
// corner corrections) leaves the smaller reduced system; dense below a size
// where the reduced matrix fits comfortably, sparse above it.  Measured on 25
// t2 images (issue 17, CPU time of whole calibrations): for `static`, dense
// Schur eliminating the corrections beats eliminating the poses by 3x and
// sparse Schur by 1.4x; iterative Schur with Schur-Jacobi ties with it for
// `static` but takes 2.8x the iterations for `full` (inexact steps on the
// weakly determined bend); on the 650-image reference it saved under 10%.
// At 400 and 1600 t2 images (`cargo bench --bench speed -- growth`, `full`,
// poses eliminated, a 341-wide reduced system) dense Schur took 0.97 s and
// 3.5 s, iterative Schur 1.4 s and 7.8 s (more iterations again), sparse Schur
// 4.1 s at 1600; for `standard` at 1600 dense 0.74 s, iterative 0.80 s.  Again
// on 2026-12-05 at 400 `full` images: dense 0.92 s, iterative with eta 0.1,
// 0.01 and 0.001 1.33, 1.21 and 1.16 s (the explicit update costs each image
// the same as the products of the conjugate gradients, so no size changes
// this).  So dense stays up to 1200 reduced parameters and iterative Schur is
// not used.  At 25 images (2026-12-05, docs/benchmarks.md "The protocol") the
// Schur elimination is two thirds of a `static` or `full` iteration, and
// nothing tried beat it: sparse normal Cholesky 4x slower, LAPACK no faster,
// corrections in blocks of 2-8 corners slower, and Ceres' fixed-size kernel
// (the intrinsics padded to two pose-wide blocks) 10 % faster in the
// elimination but no faster in all, for the extra block's evaluation.
void ChooseLinearSolver(const Assembled& a, ceres::Solver::Options& s) {
  ceres::Problem& problem = *a.problem;
  std::vector<double*> all;
  problem.GetParameterBlocks(&all);
  int total = 0, free_poses = 0, free_corrections = 0;
  for (double* b : all) {
    if (problem.IsParameterBlockConstant(b)) continue;
    total += problem.ParameterBlockTangentSize(b);
  }
  for (double* b : a.frame_pose_blocks) {
    if (!problem.IsParameterBlockConstant(b)) free_poses += problem.ParameterBlockTangentSize(b);
  }
  for (double* b : a.correction_blocks) free_corrections += problem.ParameterBlockTangentSize(b);

  const int reduced_poses = total - free_poses;
  const int reduced_corrections = total - free_corrections;
  const bool eliminate_corrections = free_corrections > 0 &&
                                     (reduced_corrections < reduced_poses || a.frames_linked);
  if (a.frames_linked && !eliminate_corrections) {
    // Frame blocks tied by the smoothness prior are no independent set to eliminate.
    s.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    return;
  }
  const std::vector<double*>& eliminated =
      eliminate_corrections ? a.correction_blocks : a.frame_pose_blocks;
  const int reduced = eliminate_corrections ? reduced_corrections : reduced_poses;
  if (reduced == 0) {
    // Only independent per-image blocks are free (e.g. a poses-only refit).
    s.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    return;
  }
  // Everything not eliminated, the correction prior's similarity among it (it
  // ties every correction, so it can never be eliminated with them), is kept.
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (double* b : all) ordering->AddElementToGroup(b, 1);
  for (double* b : eliminated) ordering->AddElementToGroup(b, 0);
  s.linear_solver_ordering = ordering;
  s.linear_solver_type = reduced <= 1200 ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
}

// Per-iteration progress on stderr: stdout belongs to the CLI, and glog's INFO
// stream is off.
class StderrProgress : public ceres::IterationCallback {
 public:
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    std::fprintf(stderr, "  iter %3d  cost %.6e  |step| %.3e  tr-radius %.2e  linear-iters %d  %.1f ms\n",
                 s.iteration, s.cost, s.step_norm, s.trust_region_radius, s.linear_solver_iterations,
                 1e3 * s.cumulative_time_in_seconds);
    return ceres::SOLVER_CONTINUE;
  }
};

// Stops a solve that starts next to its optimum after a successful step that
// changed the cost by at most `fraction` of it.  Ceres' tolerance tests refuse
// the step they test, so a solve that stops on them has computed one step more
// than it keeps: for a re-solve after outlier rejection, whose first step lands
// on the optimum, a second Jacobian and linear solve for nothing.  Here the
// step is kept and no further one computed: the same answer as that solve's.
class SettleAfterStep : public ceres::IterationCallback {
 public:
  explicit SettleAfterStep(double fraction) : fraction_(fraction) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (s.iteration > 0 && s.step_is_successful && std::abs(s.cost_change) <= fraction_ * s.cost) {
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    }
    return ceres::SOLVER_CONTINUE;
  }

 private:
  double fraction_;
};

// Relative tolerances of the warm-up: it only needs to come close.
constexpr double kWarmUpTolerance = 1e-3;

// Whether more than `warm_up_share` of the corners sit beyond the loss's scale:
// then the start is far from the optimum and a warm-up (loss-free, or with a
// wider loss) pays.  With most
// corners there (the default share of one half) that is Zhang's start.  From near
// an optimum (a re-solve after outlier rejection) the warm-up would walk to the
// plain optimum and back.  A `dynamic` stage starts from unbent boards, where the
// few corners its bends move most sit beyond the scale; the loss down-weights
// just those, and its robust solve crawled (kb4: 21 iterations against 3 after a
// warm-up), so Rust asks for a warm-up there at a smaller share.
bool FarFromOptimum(Assembled& a, const ffi::SolveOptions& o) {
  std::vector<double> r;
  if (!PlainResiduals(a, &r, nullptr) || r.empty()) return false;
  std::vector<double> s(r.size() / 2);
  for (size_t i = 0; i < s.size(); ++i) s[i] = r[2 * i] * r[2 * i] + r[2 * i + 1] * r[2 * i + 1];
  // The corner at this rank (from the bottom) is beyond the loss's scale exactly
  // when more than `warm_up_share` of them are.
  const double below = std::clamp(1.0 - o.warm_up_share, 0.0, 1.0);
  const size_t k = std::min(s.size() - 1, static_cast<size_t>(below * static_cast<double>(s.size())));
  std::nth_element(s.begin(), s.begin() + k, s.end());
  return s[k] > o.loss_scale_px * o.loss_scale_px;
}

ceres::Solver::Options MakeSolverOptions(const ffi::SolveOptions& o) {
  ceres::Solver::Options s;
  s.max_num_iterations = o.max_iterations;
  s.function_tolerance = o.function_tolerance;
  s.gradient_tolerance = o.gradient_tolerance;
  s.parameter_tolerance = o.parameter_tolerance;
  s.num_threads = o.num_threads;
  s.minimizer_progress_to_stdout = false;  // stdout belongs to the CLI
  s.logging_type = ceres::SILENT;
  // Every solve starts near its optimum (Zhang, or the previous stage), where
  // Gauss-Newton steps are good.  Ceres' default radius (1e4) damps the weakly
  // determined directions (k3, the board's bend against the pose) so much that
  // they crawl in for many iterations; LM still shrinks the radius on a bad step.
  s.initial_trust_region_radius = 1e8;
  return s;
}

}  // namespace
}  // namespace deformcal
