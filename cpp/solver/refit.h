// The protocol's pose-only refit: observations grouped by frame and camera,
// each frame's pose refitted on its own (pose_refit.h); solver.cc keeps a
// prepared refit's state.
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/pose_refit.h"
#include "deformcal/cpp/solver/params.h"
#include "deformcal/cpp/solver/validate.h"

namespace deformcal {
namespace {

// One camera's corners in one frame of a pose-only refit, and the
// observations they came from, in order.
struct ViewCorners {
  uint32_t camera;
  std::vector<PoseCorner> corners;
  std::vector<uint32_t> observations;
};

// Per frame, its views (one per camera that sees it).
using FrameCorners = std::vector<std::vector<ViewCorners>>;

using MakePoseViewFn = std::unique_ptr<PoseView> (*)(const double*, const double*,
                                                     const std::vector<PoseCorner>&);

template <class Lens>
std::unique_ptr<PoseView> MakePoseView(const double* intrinsics, const double* rig,
                                       const std::vector<PoseCorner>& corners) {
  return std::make_unique<PoseViewOf<Lens>>(intrinsics, rig, corners);
}

// Each camera's view maker, by its lens model.
std::vector<MakePoseViewFn> PoseViewMakers(const ffi::ProblemData& d) {
  std::vector<MakePoseViewFn> make;
  for (size_t k = 0; k < d.num_cameras; ++k) {
    DispatchLens(std::string(d.lens_models[k]),
                 [&](auto lens) { make.push_back(&MakePoseView<decltype(lens)>); });
  }
  return make;
}

// A frame's views under camera k's `intrinsics[k]` and rig pose `rigs[k]`.
std::vector<std::unique_ptr<PoseView>> FrameViews(const std::vector<ViewCorners>& frame,
                                                  const std::vector<MakePoseViewFn>& make,
                                                  const std::vector<const double*>& intrinsics,
                                                  const std::vector<const double*>& rigs) {
  std::vector<std::unique_ptr<PoseView>> views;
  views.reserve(frame.size());
  for (const ViewCorners& v : frame) {
    views.push_back(make[v.camera](intrinsics[v.camera], rigs[v.camera], v.corners));
  }
  return views;
}

// Refuses problem data that are not a pose-only refit without a loss: then
// frames are no longer independent, and the per-frame solve would be wrong.
template <class Board>
void RequirePoseOnly(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (o.loss != ffi::LossKind::None) Fail("a pose refit is plain least squares (no loss)");
  const bool held = d.hold_intrinsics && (d.num_cameras == 1 || d.hold_camera_poses) &&
                    (Board::kCornerSize == 0 || d.hold_corrections) &&
                    (Board::kFrameExtra == 0 || d.hold_deformations);
  if (!held) Fail("a pose refit holds everything but the board poses");
}

// Groups the observations by frame and camera, each board point evaluated
// once under the held board model.
template <class Board>
FrameCorners CollectFrames(const ffi::ProblemData& d, Params& p) {
  FrameCorners f(d.num_frames);
  // Per frame, the view of camera k (index into its views), -1 when none yet.
  std::vector<std::vector<int>> slot(d.num_frames, std::vector<int>(d.num_cameras, -1));
  const size_t n = d.obs_uv.size() / 2;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t cam = d.obs_camera[i], frame = d.obs_frame[i], corner = d.obs_corner[i];
    int& s = slot[frame][cam];
    if (s < 0) {
      s = static_cast<int>(f[frame].size());
      f[frame].push_back({cam, {}, {}});
    }
    PoseCorner c{d.obs_uv[2 * i], d.obs_uv[2 * i + 1], d.obs_weight.empty() ? 1.0 : d.obs_weight[i], {}};
    const double* correction = Board::kCornerSize > 0 ? p.Correction(corner) : nullptr;
    Board::Point(&d.board[3 * corner], p.Frame(frame) + kPoseSize, correction, c.x);
    f[frame][s].corners.push_back(c);
    f[frame][s].observations.push_back(static_cast<uint32_t>(i));
  }
  return f;
}

// Each camera's rig pose (none for camera 0, the rig's reference).
std::vector<const double*> RigPoses(const std::vector<double*>& camera_poses) {
  std::vector<const double*> rigs(camera_poses.begin(), camera_poses.end());
  if (!rigs.empty()) rigs[0] = nullptr;
  return rigs;
}

// Refits every frame's pose on its own; the report as a joint solve's.
ffi::SolveReport RefitEachFrame(const FrameCorners& f, const ffi::ProblemData& d,
                                const ffi::SolveOptions& o, Params& p) {
  ffi::SolveReport report;
  report.usable = true;
  report.converged = true;
  report.linear_solver = rust::String("per-frame dense normal equations");
  const std::vector<MakePoseViewFn> make = PoseViewMakers(d);
  const std::vector<const double*> intrinsics(p.intrinsics.begin(), p.intrinsics.end());
  const std::vector<const double*> rigs = RigPoses(p.camera_poses);
  std::vector<double> residuals(d.obs_uv.size(), 0.0), r;
  for (size_t j = 0; j < f.size(); ++j) {
    if (f[j].empty()) continue;
    const auto views = FrameViews(f[j], make, intrinsics, rigs);
    const PoseRefitResult fit = RefitFramePose(views, p.Frame(j), o.max_iterations);
    report.usable = report.usable && fit.ok;
    report.converged = report.converged && fit.converged;
    report.iterations = std::max(report.iterations, fit.iterations);
    report.initial_cost += fit.initial_cost;
    report.final_cost += fit.final_cost;
    for (size_t v = 0; v < views.size() && report.usable; ++v) {
      const std::vector<uint32_t>& obs = f[j][v].observations;
      r.assign(2 * obs.size(), 0.0);
      report.usable = views[v]->Residuals(p.Frame(j), r.data());
      for (size_t k = 0; k < obs.size(); ++k) {
        residuals[2 * obs[k]] = r[2 * k];
        residuals[2 * obs[k] + 1] = r[2 * k + 1];
      }
    }
    if (!report.usable) {
      report.message = rust::String("frame " + std::to_string(j) +
                                    ": a board point has no image under the held intrinsics");
      return report;
    }
  }
  report.message = rust::String(report.converged ? "every frame converged"
                                                 : "a frame hit the iteration limit");
  for (double v : residuals) report.residuals.push_back(v);
  return report;
}

}  // namespace
}  // namespace deformcal
