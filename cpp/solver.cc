// The bridge's entry points (src/solver/bridge.rs): each validates the problem
// data (solver/validate.h), builds the Ceres problem over one parameter buffer
// laid out by the Rust side (solver/params.h, src/model/state.rs; assembly in
// solver/assemble.h), and solves (solver/solve_options.h), evaluates
// (solver/jacobian.h) or refits poses (solver/refit.h).  The residual functors
// live in residuals.h, the models in lens/registry.h and board.h.  One
// translation unit: the headers under solver/ are its parts.
#include "deformcal/cpp/bridge.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "deformcal/cpp/pose_refit.h"
#include "deformcal/cpp/priors.h"
#include "deformcal/cpp/residuals.h"
#include "deformcal/cpp/solver/assemble.h"
#include "deformcal/cpp/solver/jacobian.h"
#include "deformcal/cpp/solver/params.h"
#include "deformcal/cpp/solver/refit.h"
#include "deformcal/cpp/solver/solve_options.h"
#include "deformcal/cpp/solver/validate.h"
#include "deformcal/src/solver/bridge.rs.h"

namespace deformcal {
namespace ffi {

// What a prepared pose refit keeps: everything but the intrinsics, and each
// frame's optimum under the prepared intrinsics with its first-order move.
struct PoseRefitState {
  FrameCorners frames;
  std::vector<double> start_poses;  // kPoseSize per frame: the optimum under `intrinsics`
  // Per frame, PoseSensitivity at its start pose (empty where there is none).
  std::vector<std::vector<double>> sensitivities;
  std::vector<double> intrinsics;  // every camera's, in camera order, as prepared
  std::vector<size_t> offsets;     // per camera, where its intrinsics start
  std::vector<MakePoseViewFn> make;
  std::vector<size_t> num_params;  // per camera
  std::vector<double> rig_poses;   // kPoseSize per camera
  int max_iterations = 0;
};

namespace {

// Frame j's start under `lens`: its prepared optimum moved to first order by
// the change of its views' intrinsics from the prepared ones.
void PredictedPose(const PoseRefitState& s, size_t j, const std::vector<const double*>& lens,
                   double* pose) {
  std::copy_n(&s.start_poses[kPoseSize * j], kPoseSize, pose);
  const std::vector<double>& S = s.sensitivities[j];
  if (S.empty()) return;
  size_t col = 0;
  for (const ViewCorners& v : s.frames[j]) {
    const double* prepared = &s.intrinsics[s.offsets[v.camera]];
    for (size_t q = 0; q < s.num_params[v.camera]; ++q, ++col) {
      const double d = lens[v.camera][q] - prepared[q];
      for (int i = 0; i < kPoseSize; ++i) pose[i] -= S[kPoseSize * col + i] * d;
    }
  }
}

}  // namespace

PoseRefit::PoseRefit(std::unique_ptr<const PoseRefitState> state) : state_(std::move(state)) {}
PoseRefit::~PoseRefit() = default;

double PoseRefit::rmse_px(rust::Slice<const double> intrinsics) const {
  const PoseRefitState& s = *state_;
  if (s.intrinsics.size() != intrinsics.size()) {
    Fail("the refit's intrinsics have " + std::to_string(intrinsics.size()) + " values, expected " +
         std::to_string(s.intrinsics.size()));
  }
  std::vector<const double*> lens(s.num_params.size()), rigs(s.num_params.size(), nullptr);
  for (size_t k = 0; k < s.num_params.size(); ++k) {
    lens[k] = intrinsics.data() + s.offsets[k];
    if (k > 0) rigs[k] = &s.rig_poses[kPoseSize * k];
  }
  double sum = 0.0;
  size_t corners = 0;
  for (size_t j = 0; j < s.frames.size(); ++j) {
    if (s.frames[j].empty()) continue;
    double pose[kPoseSize];
    PredictedPose(s, j, lens, pose);
    const auto views = FrameViews(s.frames[j], s.make, lens, rigs);
    PoseRefitResult fit = RefitFramePose(views, pose, s.max_iterations);
    if (!fit.ok && !s.sensitivities[j].empty()) {
      // The prediction went where a point has no image: from the optimum as prepared.
      std::copy_n(&s.start_poses[kPoseSize * j], kPoseSize, pose);
      fit = RefitFramePose(views, pose, s.max_iterations);
    }
    sum += fit.squared_error;
    for (const ViewCorners& v : s.frames[j]) corners += v.corners.size();
    if (!fit.ok || !std::isfinite(sum)) {
      Fail("frame " + std::to_string(j) + ": a board point has no image under the held intrinsics");
    }
  }
  if (corners == 0) Fail("the refit has no observation");
  return std::sqrt(sum / static_cast<double>(corners));
}

std::unique_ptr<PoseRefit> prepare_pose_refit(const ProblemData& data, const SolveOptions& options) {
  ValidateProblem(data, options);
  Params params(data);
  auto state = std::make_unique<PoseRefitState>();
  DispatchBoard(std::string(data.board_model), [&](auto board) {
    using Board = decltype(board);
    RequirePoseOnly<Board>(data, options);
    state->frames = CollectFrames<Board>(data, params);
  });
  state->make = PoseViewMakers(data);
  std::vector<const double*> lens;
  for (size_t k = 0; k < data.num_cameras; ++k) {
    DispatchLens(std::string(data.lens_models[k]),
                 [&](auto lens) { state->num_params.push_back(decltype(lens)::kNumParams); });
    state->offsets.push_back(state->intrinsics.size());
    state->intrinsics.insert(state->intrinsics.end(), params.intrinsics[k],
                             params.intrinsics[k] + state->num_params[k]);
    state->rig_poses.insert(state->rig_poses.end(), params.camera_poses[k],
                            params.camera_poses[k] + kPoseSize);
  }
  for (size_t k = 0; k < data.num_cameras; ++k) lens.push_back(&state->intrinsics[state->offsets[k]]);
  const std::vector<const double*> rigs = RigPoses(params.camera_poses);
  state->sensitivities.resize(data.num_frames);
  state->max_iterations = options.max_iterations;
  // Each frame refitted under the prepared intrinsics once: a refit under
  // others then starts from this optimum moved to first order, a step or two
  // from its own.  A frame whose refit fails keeps its pose and no prediction.
  for (size_t j = 0; j < data.num_frames; ++j) {
    double pose[kPoseSize];
    std::copy_n(params.Frame(j), kPoseSize, pose);
    if (!state->frames[j].empty()) {
      const auto views = FrameViews(state->frames[j], state->make, lens, rigs);
      const PoseRefitResult fit = RefitFramePose(views, pose, options.max_iterations);
      if (!fit.ok || !fit.converged || !PoseSensitivity(views, pose, &state->sensitivities[j])) {
        std::copy_n(params.Frame(j), kPoseSize, pose);
        state->sensitivities[j].clear();
      }
    }
    state->start_poses.insert(state->start_poses.end(), pose, pose + kPoseSize);
  }
  return std::make_unique<PoseRefit>(std::move(state));
}

SolveReport solve(ProblemData& data, const SolveOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ValidateProblem(data, options);
  Params params(data);
  Assembled a = Assemble(data, options, params, options.compress_view_rows);
  ceres::Solver::Options s = MakeSolverOptions(options);
  ChooseLinearSolver(a, s);
  std::string why;
  if (!s.IsValid(&why)) Fail("invalid solver options: " + why);
  StderrProgress progress;
  if (options.verbose) s.callbacks.push_back(&progress);
  ceres::Solver::Summary summary;
  int warm_up_iterations = 0;
  if (options.loss == LossKind::Cauchy && !PreviousPath(data, options) &&
      FarFromOptimum(a, options)) {
    // Plain least squares (or a wider loss) first: from a start far off
    // (Zhang's) it takes the big steps in a few Gauss-Newton iterations, where
    // the loss's reweighting crawls; the robust solve then starts close.  The
    // answer is the robust solve's alone, so it does not change.
    *a.loss_scale_factor = options.warm_up_scale_factor;
    ceres::Solver::Options w = s;
    w.function_tolerance = std::max(s.function_tolerance, kWarmUpTolerance);
    w.parameter_tolerance = std::max(s.parameter_tolerance, kWarmUpTolerance);
    if (options.verbose) std::fprintf(stderr, "  warm-up, loss scale x%g:\n", options.warm_up_scale_factor);
    ceres::Solve(w, a.problem.get(), &summary);
    warm_up_iterations = static_cast<int>(summary.iterations.size()) - 1;
    *a.loss_scale_factor = 1.0;
    if (options.verbose) std::fprintf(stderr, "  with the loss:\n");
  }
  SettleAfterStep settle(options.settle_cost_change);
  if (options.settle_cost_change > 0.0) s.callbacks.push_back(&settle);
  ceres::Solve(s, a.problem.get(), &summary);

  SolveReport report;
  report.usable = summary.IsSolutionUsable();
  report.converged = summary.termination_type == ceres::CONVERGENCE ||
                     summary.termination_type == ceres::USER_SUCCESS;
  report.iterations = static_cast<int32_t>(summary.iterations.size()) - 1 + warm_up_iterations;
  report.initial_cost = summary.initial_cost;
  report.final_cost = summary.final_cost;
  report.message = rust::String(summary.message);
  report.linear_solver = rust::String(ceres::LinearSolverTypeToString(summary.linear_solver_type_used));
  if (report.usable) {
    for (double v : params.storage) report.usable = report.usable && std::isfinite(v);
    if (!report.usable) report.message = rust::String("the solve produced non-finite parameters");
  }
  if (report.usable) {
    params.CopyTo(data);
    // The final residuals, from the problem already built.
    double cost = 0.0;
    std::vector<double> residuals;
    if (OrderedResiduals(a, data.obs_uv.size() / 2, options.num_threads, &cost, &residuals,
                         nullptr)) {
      for (double r : residuals) report.residuals.push_back(r);
    }
  }
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (options.verbose) std::fprintf(stderr, "%s\n", summary.FullReport().c_str());
  return report;
}

SolveReport refit_poses(ProblemData& data, const SolveOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ValidateProblem(data, options);
  Params params(data);
  SolveReport report;
  DispatchBoard(std::string(data.board_model), [&](auto board) {
    using Board = decltype(board);
    RequirePoseOnly<Board>(data, options);
    const FrameCorners frames = CollectFrames<Board>(data, params);
    report = RefitEachFrame(frames, data, options, params);
  });
  for (double v : params.storage) report.usable = report.usable && std::isfinite(v);
  if (report.usable) params.CopyTo(data);
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

Evaluation evaluate(const ProblemData& data, const SolveOptions& options, bool with_jacobian) {
  ValidateProblem(data, options);
  Params params(data);
  Assembled a = Assemble(data, options, params);
  double cost = 0.0;
  std::vector<double> ordered;
  ceres::CRSMatrix jacobian;
  std::vector<uint32_t> columns;
  if (!OrderedResiduals(a, data.obs_uv.size() / 2, options.num_threads, &cost, &ordered,
                        with_jacobian ? &jacobian : nullptr, params.storage.data(), &columns)) {
    Fail("the residuals could not be evaluated (a point behind the camera?)");
  }
  Evaluation out;
  out.cost = cost;
  for (double r : ordered) out.residuals.push_back(r);
  if (with_jacobian) {
    out.jacobian_rows = static_cast<size_t>(jacobian.num_rows);
    out.jacobian_cols = static_cast<size_t>(jacobian.num_cols);
    for (int v : jacobian.rows) out.jacobian_row_ptr.push_back(static_cast<uint32_t>(v));
    for (int v : jacobian.cols) out.jacobian_col_idx.push_back(static_cast<uint32_t>(v));
    for (double v : jacobian.values) out.jacobian_values.push_back(v);
    for (uint32_t c : columns) out.jacobian_col_param.push_back(c);
  }
  return out;
}

std::unique_ptr<Jacobian> jacobian(const ProblemData& data, const SolveOptions& options) {
  ValidateProblem(data, options);
  Params params(data);
  Assembled a = Assemble(data, options, params);
  auto out = std::make_unique<Jacobian>();
  DirectJacobian(a, params.storage.data(), data.obs_uv.size() / 2, *out);
  return out;
}

size_t lens_num_params(rust::Str model) {
  size_t n = 0;
  if (!DispatchLens(std::string(model), [&](auto lens) { n = decltype(lens)::kNumParams; })) {
    Fail("unknown lens model `" + std::string(model) + "`");
  }
  return n;
}

rust::Vec<double> project_points(rust::Str model, rust::Slice<const double> params,
                                 rust::Slice<const double> points) {
  rust::Vec<double> out;
  const bool known = DispatchLens(std::string(model), [&](auto lens) {
    using Lens = decltype(lens);
    if (params.size() != Lens::kNumParams) Fail("wrong parameter count");
    for (size_t i = 0; i + 2 < points.size(); i += 3) {
      double uv[2];
      if (!Lens::Project(params.data(), points.data() + i, uv)) uv[0] = uv[1] = std::nan("");
      out.push_back(uv[0]);
      out.push_back(uv[1]);
    }
  });
  if (!known) Fail("unknown lens model `" + std::string(model) + "`");
  return out;
}

rust::Vec<size_t> board_model_sizes(rust::Str model) {
  rust::Vec<size_t> out;
  const bool known = DispatchBoard(std::string(model), [&](auto board) {
    using Board = decltype(board);
    out.push_back(Board::kFrameExtra);
    out.push_back(Board::kCornerSize);
    out.push_back(Board::kGaugeCorners);
  });
  if (!known) Fail("unknown board model `" + std::string(model) + "`");
  return out;
}

rust::Vec<double> board_point(rust::Str model, rust::Slice<const double> nominal,
                              rust::Slice<const double> frame_extra,
                              rust::Slice<const double> correction) {
  rust::Vec<double> out;
  const bool known = DispatchBoard(std::string(model), [&](auto board) {
    using Board = decltype(board);
    if (nominal.size() != 3 || frame_extra.size() != Board::kFrameExtra ||
        correction.size() != kCorrectionStride) {
      Fail("wrong sizes for the board model");
    }
    double x[3];
    Board::Point(nominal.data(), frame_extra.data(), correction.data(), x);
    for (double v : x) out.push_back(v);
  });
  if (!known) Fail("unknown board model `" + std::string(model) + "`");
  return out;
}

double correction_prior_minimum(rust::Str model, rust::Slice<const double> board,
                                rust::Slice<const double> corrections,
                                rust::Slice<const double> weight) {
  double out = 0.0;
  const bool known = DispatchBoard(std::string(model), [&](auto board_model) {
    constexpr int N = decltype(board_model)::kCornerSize;
    if constexpr (N == 0) {
      Fail("the board model has no static correction");
    } else {
      const size_t n = board.size() / 3;
      if (board.size() != 3 * n || corrections.size() != kCorrectionStride * n ||
          weight.size() != kCorrectionStride * n || n == 0) {
        Fail("wrong sizes for the correction prior");
      }
      std::vector<double> delta(corrections.begin(), corrections.end());
      std::vector<double> s(SimilaritySize(N), 0.0);
      const double zeros[kCorrectionStride] = {0.0, 0.0, 0.0};
      ceres::Problem problem;
      for (size_t c = 0; c < n; ++c) {
        double* block = &delta[kCorrectionStride * c];
        problem.AddResidualBlock(new CorrectionPrior<N>(zeros, &weight[kCorrectionStride * c],
                                                        &board[3 * c]),
                                 nullptr, block, s.data());
        problem.SetParameterBlockConstant(block);
      }
      ceres::Solver::Options o;
      o.linear_solver_type = ceres::DENSE_QR;
      o.logging_type = ceres::SILENT;
      o.function_tolerance = o.parameter_tolerance = o.gradient_tolerance = 1e-16;
      ceres::Solver::Summary summary;
      ceres::Solve(o, &problem, &summary);
      out = 2.0 * summary.final_cost;
    }
  });
  if (!known) Fail("unknown board model `" + std::string(model) + "`");
  return out;
}

}  // namespace ffi
}  // namespace deformcal

// The structure-from-motion bundle adjustment: its own functor, kept apart.
#include "deformcal/cpp/sfm.h"
