// Ceres problem assembly and solving: turns the bridge's ProblemData into a
// ceres::Problem over one parameter buffer (laid out by the Rust side, see
// src/model/state.rs), chooses the linear solver, solves and evaluates.  The
// residual functors live in residuals.h, the models in camera.h and board.h.
#include "deformcal/cpp/bridge.h"

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <utility>
#include <vector>

#include "deformcal/cpp/pose_refit.h"
#include "deformcal/cpp/priors.h"
#include "deformcal/cpp/residuals.h"
#include "deformcal/src/solver/bridge.rs.h"

namespace deformcal {
namespace {

// A view of one parameter table inside Params' storage.
struct Table {
  double* ptr = nullptr;
  size_t n = 0;
  double& operator[](size_t i) { return ptr[i]; }
  double* data() { return ptr; }
  double* begin() { return ptr; }
  double* end() { return ptr + n; }
};

// Corners whose corrections share one parameter block (UseCornerGroups).
constexpr size_t kCornersPerGroup = 4;

// A working copy of the parameter buffer and views of its tables.  Ceres
// orders the blocks of an elimination group by address; one buffer in a fixed
// order makes that order, and so the floating-point result, the same in every
// run.  The offsets come from the Rust layout and are checked by Validate.
struct Params {
  // Room after the caller's values for the correction prior's similarity
  // (priors.h, at most 7 values): inside the buffer, so that its address keeps
  // its place among the other blocks'. Ceres orders the blocks of a linear
  // solver group by address, and a block allocated on its own landed before or
  // after the others from one solve to the next, so that the same calibration
  // in one process differed in its last bits.
  static constexpr size_t kSimilarityRoom = 7;
  std::vector<double> storage;
  size_t given;  // the caller's values, storage's first ones
  Table frames, corrections;
  std::vector<double*> intrinsics;  // camera k's lens parameters
  std::vector<double*> camera_poses;
  size_t frame_stride;

  explicit Params(const ffi::ProblemData& d)
      : storage(d.params.begin(), d.params.end()), given(d.params.size()), frame_stride(d.frame_stride) {
    storage.resize(given + kSimilarityRoom, 0.0);
    for (size_t k = 0; k < d.num_cameras; ++k) {
      intrinsics.push_back(storage.data() + d.intrinsics_offsets[k]);
      camera_poses.push_back(storage.data() + d.camera_poses_offset + kPoseSize * k);
    }
    frames.ptr = storage.data() + d.frames_offset;
    frames.n = d.frame_stride * d.num_frames;
    corrections.ptr = storage.data() + d.corrections_offset;
    corrections.n = kCorrectionStride * d.num_corners;
  }
  Params(const Params&) = delete;
  Params& operator=(const Params&) = delete;

  double* Frame(size_t j) { return frames.data() + frame_stride * j; }
  double* Correction(size_t i) { return corrections.data() + kCorrectionStride * i; }
  // Corner i's group of corrections: its block, the size of that block and the
  // offset of corner i's slot in it.
  double* Group(size_t i) { return Correction(i - i % kCornersPerGroup); }
  int GroupSize(size_t i) const {
    const size_t first = i - i % kCornersPerGroup, corners = corrections.n / kCorrectionStride;
    return kCorrectionStride * static_cast<int>(std::min(kCornersPerGroup, corners - first));
  }
  static int GroupOffset(size_t i) { return kCorrectionStride * static_cast<int>(i % kCornersPerGroup); }

  double* Similarity() { return storage.data() + given; }

  void CopyTo(ffi::ProblemData& d) const {
    std::copy(storage.begin(), storage.begin() + static_cast<std::ptrdiff_t>(given), d.params.begin());
  }
};

[[noreturn]] void Fail(const std::string& what) { throw std::invalid_argument(what); }

template <class Vec>
void RequireSize(const Vec& v, size_t expected, const char* name) {
  if (v.size() != expected) {
    std::ostringstream s;
    s << name << " has " << v.size() << " values, expected " << expected;
    Fail(s.str());
  }
}

template <class Vec>
void RequireFinite(const Vec& v, const char* name) {
  for (size_t i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i])) {
      std::ostringstream s;
      s << name << "[" << i << "] is not finite (" << v[i] << ")";
      Fail(s.str());
    }
  }
}

// The parameter buffer holds, in this order and without gaps: each camera's
// lens parameters, the camera poses, the frame blocks, the corrections.
template <class Board>
void ValidateLayout(const ffi::ProblemData& d) {
  RequireSize(d.lens_models, d.num_cameras, "lens_models");
  RequireSize(d.intrinsics_offsets, d.num_cameras, "intrinsics_offsets");
  size_t next = 0;
  for (size_t k = 0; k < d.num_cameras; ++k) {
    const std::string name(d.lens_models[k]);
    int n = 0;
    if (!DispatchLens(name, [&](auto lens) { n = decltype(lens)::kNumParams; })) {
      Fail("unknown lens model `" + name + "`");
    }
    if (d.intrinsics_offsets[k] != next) Fail("intrinsics_offsets do not follow the layout");
    next += static_cast<size_t>(n);
  }
  RequireSize(d.intrinsics_held, next, "intrinsics_held");
  if (d.camera_poses_offset != next) Fail("camera_poses_offset does not follow the layout");
  next += kPoseSize * d.num_cameras;
  if (d.frames_offset != next) Fail("frames_offset does not follow the layout");
  if (d.frame_stride != static_cast<uint32_t>(kPoseSize + Board::kFrameExtra)) {
    Fail("frame_stride does not match the board model");
  }
  next += static_cast<size_t>(d.frame_stride) * d.num_frames;
  if (d.corrections_offset != next) Fail("corrections_offset does not follow the layout");
  next += kCorrectionStride * d.num_corners;
  RequireSize(d.params, next, "params");
}

// The priors' sizes (empty: no prior) and weights (finite, non-negative).
template <class Board>
void ValidatePriors(const ffi::ProblemData& d) {
  const size_t corners = kCorrectionStride * d.num_corners;
  const size_t extra = static_cast<size_t>(Board::kFrameExtra);
  auto optional_size = [](const auto& v, size_t n, const char* name) {
    if (!v.empty()) RequireSize(v, n, name);
  };
  optional_size(d.correction_prior_weight, corners, "correction_prior_weight");
  optional_size(d.correction_prior_mean, corners, "correction_prior_mean");
  optional_size(d.bend_prior_weight, extra, "bend_prior_weight");
  optional_size(d.bend_smoothness_weight, extra, "bend_smoothness_weight");
  optional_size(d.lens_prior_weight, d.intrinsics_held.size(), "lens_prior_weight");
  RequireFinite(d.correction_prior_mean, "correction_prior_mean");
  if (!(d.bend_smoothness_loss >= 0.0 && std::isfinite(d.bend_smoothness_loss))) {
    Fail("bend_smoothness_loss must be a non-negative number");
  }
  for (const auto* w :
       {&d.correction_prior_weight, &d.bend_prior_weight, &d.bend_smoothness_weight,
        &d.lens_prior_weight}) {
    RequireFinite(*w, "prior weight");
    for (double v : *w) {
      if (v < 0.0) Fail("prior weights must not be negative");
    }
  }
}

// Everything that would otherwise trip a CHECK deep inside Ceres.
template <class Board>
void Validate(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  const size_t n = d.obs_uv.size() / 2;
  RequireSize(d.obs_uv, 2 * n, "obs_uv");
  RequireSize(d.obs_camera, n, "obs_camera");
  RequireSize(d.obs_frame, n, "obs_frame");
  RequireSize(d.obs_corner, n, "obs_corner");
  RequireSize(d.board, 3 * d.num_corners, "board");
  ValidateLayout<Board>(d);
  RequireFinite(d.obs_uv, "obs_uv");
  if (!d.obs_weight.empty()) {
    RequireSize(d.obs_weight, n, "obs_weight");
    for (size_t i = 0; i < n; ++i) {
      if (!(d.obs_weight[i] > 0.0 && std::isfinite(d.obs_weight[i]))) {
        Fail("obs_weight[" + std::to_string(i) + "] must be a positive number");
      }
    }
  }
  RequireFinite(d.board, "board");
  RequireFinite(d.params, "params");
  for (size_t i = 0; i < n; ++i) {
    if (d.obs_camera[i] >= d.num_cameras || d.obs_frame[i] >= d.num_frames ||
        d.obs_corner[i] >= d.num_corners) {
      std::ostringstream s;
      s << "observation " << i << " refers to camera " << d.obs_camera[i] << ", frame "
        << d.obs_frame[i] << ", corner " << d.obs_corner[i] << " outside the problem";
      Fail(s.str());
    }
  }
  const size_t gauge = static_cast<size_t>(Board::kGaugeCorners);
  if (o.fix_gauge && !d.hold_corrections && d.gauge_corners.size() < gauge) {
    Fail("the board model needs " + std::to_string(gauge) + " gauge corners");
  }
  for (size_t i = 0; i < d.gauge_corners.size(); ++i) {
    if (d.gauge_corners[i] >= d.num_corners) Fail("gauge corner outside the board");
    for (size_t k = 0; k < i; ++k) {
      if (d.gauge_corners[i] == d.gauge_corners[k]) Fail("gauge corners must be distinct");
    }
  }
  for (uint32_t c : d.frozen_corners) {
    if (c >= d.num_corners) Fail("frozen corner outside the board");
  }
  ValidatePriors<Board>(d);
  if (o.loss == ffi::LossKind::Cauchy && !(o.loss_scale_px > 0.0 && std::isfinite(o.loss_scale_px))) {
    Fail("loss_scale_px must be a positive number");
  }
  if (!(o.warm_up_share >= 0.0 && o.warm_up_share <= 1.0) ||
      !(o.warm_up_scale_factor >= 0.0 && std::isfinite(o.warm_up_scale_factor))) {
    Fail("warm_up_share must lie in [0, 1] and warm_up_scale_factor must be a non-negative number");
  }
  if (o.num_threads < 1) Fail("num_threads must be at least 1");
  if (o.max_iterations < 0) Fail("max_iterations must not be negative");
  if (!(o.function_tolerance >= 0.0) || !(o.parameter_tolerance >= 0.0) ||
      !(o.gradient_tolerance >= 0.0)) {
    Fail("solver tolerances must be non-negative numbers");
  }
}

void SilenceGlogOnce() {
  static std::once_flag once;
  // Without InitGoogleLogging glog writes to stderr.  Ceres' own failure
  // messages come back in the solver summary, so nothing below FATAL is shown.
  std::call_once(once, [] { FLAGS_minloglevel = google::GLOG_FATAL; });
}

// The assembled problem with the bookkeeping the solver and evaluator need.
struct Assembled {
  // Every cost function of the problem, owned here rather than by the problem:
  // Ceres would keep a hash map of reference counts over the ~1.7 M
  // observation blocks of a 10 000-image problem to delete them.  Declared
  // before the problem, so that it outlives it.
  std::vector<std::unique_ptr<ceres::CostFunction>> costs;
  std::unique_ptr<ceres::Problem> problem;
  std::vector<ceres::ResidualBlockId> residuals;
  // The observations behind residual block k, in its residual order:
  // block_observations[block_observation_begin[k] .. block_observation_begin[k + 1]].
  std::vector<uint32_t> block_observations;
  std::vector<size_t> block_observation_begin{0};
  std::vector<double*> frame_pose_blocks;
  std::vector<double*> correction_blocks;  // free corrections, none partly held
  bool corner_groups = false;              // corrections in groups (UseCornerGroups)
  // Per corner: observed, and with a free correction component.
  std::vector<bool> correction_observed, correction_free;
  // The priors' residuals (priors.h): solved with, never reported as observations.
  std::vector<ceres::ResidualBlockId> prior_residuals;
  // The correction prior's similarity (priors.h): a free block in Params' room
  // after the caller's values, solved with the rest and never reported.
  double* similarity = nullptr;
  bool frames_linked = false;  // a prior ties frame blocks together (no Schur on frames)
  // The robust loss's scale, as a multiple of the configured one (0: no loss):
  // shared with every loss and view block, so that one problem serves the
  // warm-up, the robust solve and the plain residuals read after it.
  std::shared_ptr<double> loss_scale_factor = std::make_shared<double>(1.0);
  // View blocks go to the problem as CompressedRows (for solving only: their
  // rows are then no observations' residuals; PlainCost reads through them).
  bool compress_views = false;

  // Adds a residual block of `cost` (owned here from now on) over `blocks`.
  template <class... Blocks>
  ceres::ResidualBlockId Add(ceres::CostFunction* cost, ceres::LossFunction* loss, Blocks&&... blocks) {
    costs.emplace_back(cost);
    return problem->AddResidualBlock(cost, loss, std::forward<Blocks>(blocks)...);
  }

  // Adds an observation block: its residual block and the observations behind it.
  template <class Observations, class... Blocks>
  void AddObservations(const Observations& observations, ceres::CostFunction* cost,
                       ceres::LossFunction* loss, Blocks&&... blocks) {
    residuals.push_back(Add(cost, loss, std::forward<Blocks>(blocks)...));
    block_observations.insert(block_observations.end(), std::begin(observations), std::end(observations));
    block_observation_begin.push_back(block_observations.size());
  }

  // Residual block k's cost function with one row per observation coordinate:
  // the one inside a CompressedRows.
  const ceres::CostFunction& PlainCost(size_t k) const {
    const ceres::CostFunction* f = problem->GetCostFunctionForResidualBlock(residuals[k]);
    if (const auto* c = dynamic_cast<const CompressedRows*>(f)) return c->inner();
    return *f;
  }

  // The observations behind residual block k, whose cost function has
  // `num_residuals` rows: two per observation, checked before anyone writes them.
  const uint32_t* ObservationsOf(size_t k, int num_residuals) const {
    const size_t begin = block_observation_begin[k], end = block_observation_begin[k + 1];
    if (static_cast<size_t>(num_residuals) != 2 * (end - begin)) {
      Fail("a residual block does not have 2 rows per observation");
    }
    return block_observations.data() + begin;
  }
};

// Ceres' Cauchy loss behind a shared scale factor (0: plain squares).  Ceres
// takes ownership of one instance shared by every per-corner block.
class SwitchableCauchy final : public ceres::LossFunction {
 public:
  SwitchableCauchy(double scale, std::shared_ptr<const double> factor)
      : scale_(scale), cauchy_(scale), factor_(std::move(factor)) {}
  void Evaluate(double s, double rho[3]) const override {
    const double k = *factor_;
    if (k == 1.0) {
      cauchy_.Evaluate(s, rho);
    } else if (k == 0.0) {
      rho[0] = s;
      rho[1] = 1.0;
      rho[2] = 0.0;
    } else {
      ceres::CauchyLoss(scale_ * k).Evaluate(s, rho);
    }
  }

 private:
  double scale_;
  ceres::CauchyLoss cauchy_;
  std::shared_ptr<const double> factor_;
};

// How residuals of one camera are made: its lens model chosen once per camera.
template <class Board>
struct LensOps {
  // corner_offset, corner_width: the corner's slot in its correction block.
  ceres::CostFunction* (*cost)(double u, double v, double w, const double* x, bool rig,
                               bool reference, int corner_offset, int corner_width);
  PoseOnlyView* (*view)(const double* intrinsics, const double* rig);
  ViewBlock* (*view_block)(bool rig, CauchyFold loss, std::shared_ptr<const double> loss_scale_factor);
};

template <class Lens, class Board>
ViewBlock* MakeViewBlock(bool rig, CauchyFold loss, std::shared_ptr<const double> loss_scale_factor) {
  if (rig) return new ViewReprojection<Lens, Board, true>(loss, std::move(loss_scale_factor));
  return new ViewReprojection<Lens, Board, false>(loss, std::move(loss_scale_factor));
}

template <class Lens, class Board>
ceres::CostFunction* MakeCost(double u, double v, double w, const double* x, bool rig,
                              bool reference, int corner_offset, int corner_width) {
  if (reference) {
    if (corner_width != Board::kCornerSize) Fail("the reference residual has no corner groups");
    return rig ? ReprojectionError<Lens, Board, true>::Create(u, v, w, x)
               : ReprojectionError<Lens, Board, false>::Create(u, v, w, x);
  }
  auto place = [&](auto* f) {
    if (corner_width != Board::kCornerSize) f->PlaceCorner(corner_offset, corner_width);
    return f;
  };
  if (rig) return place(new ChainedReprojection<Lens, Board, true>(u, v, w, x));
  return place(new ChainedReprojection<Lens, Board, false>(u, v, w, x));
}

template <class Lens>
PoseOnlyView* MakeView(const double* intrinsics, const double* rig) {
  return new PoseOnlyViewOf<Lens>(intrinsics, rig);
}

template <class Board>
std::vector<LensOps<Board>> LensOpsPerCamera(const ffi::ProblemData& d) {
  std::vector<LensOps<Board>> ops;
  for (size_t k = 0; k < d.num_cameras; ++k) {
    DispatchLens(std::string(d.lens_models[k]), [&](auto lens) {
      using Lens = decltype(lens);
      ops.push_back({&MakeCost<Lens, Board>, &MakeView<Lens>, &MakeViewBlock<Lens, Board>});
    });
  }
  return ops;
}

// Holds what the problem data asks to hold: intrinsics (all or named ones),
// camera poses and the board model's per-frame parameters.
template <class Board>
void HoldParameters(const ffi::ProblemData& d, bool pose_only, Params& p, Assembled& a) {
  ceres::Problem& problem = *a.problem;
  for (size_t k = 0; k < d.num_cameras; ++k) {
    double* intr = p.intrinsics[k];
    if (problem.HasParameterBlock(intr)) {
      const int n = problem.ParameterBlockSize(intr);
      std::vector<int> held;
      for (int i = 0; i < n; ++i) {
        if (d.intrinsics_held[d.intrinsics_offsets[k] + i]) held.push_back(i);
      }
      if (d.hold_intrinsics || static_cast<int>(held.size()) == n) {
        problem.SetParameterBlockConstant(intr);
      } else if (!held.empty()) {
        problem.SetManifold(intr, new ceres::SubsetManifold(n, held));
      }
    }
    double* pose = p.camera_poses[k];
    if (k > 0 && d.hold_camera_poses && problem.HasParameterBlock(pose)) {
      problem.SetParameterBlockConstant(pose);
    }
  }
  if (Board::kFrameExtra > 0 && d.hold_deformations && !pose_only) {
    // Hold the per-frame parameters, keep the pose free.
    std::vector<int> held;
    for (int e = 0; e < Board::kFrameExtra; ++e) held.push_back(kPoseSize + e);
    for (double* block : a.frame_pose_blocks) {
      problem.SetManifold(block, new ceres::SubsetManifold(kPoseSize + Board::kFrameExtra, held));
    }
  }
}

// Which components of each corner's correction (kCorrectionStride per corner)
// are held: all of a corner never observed or frozen, those beyond the board
// model's kCornerSize, and those the gauge holds.
template <class Board>
std::vector<bool> HeldCorrectionComponents(const ffi::ProblemData& d, const ffi::SolveOptions& o,
                                           const std::vector<bool>& corner_used) {
  std::vector<bool> held(kCorrectionStride * d.num_corners);
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    for (int k = 0; k < kCorrectionStride; ++k) {
      held[kCorrectionStride * c + k] = !corner_used[c] || k >= Board::kCornerSize;
    }
  }
  for (uint32_t c : d.frozen_corners) {
    for (int k = 0; k < Board::kCornerSize; ++k) held[kCorrectionStride * c + k] = true;
  }
  if (o.fix_gauge) {
    for (size_t g = 0; g < d.gauge_corners.size(); ++g) {
      for (int k : Board::GaugeHeld(g)) held[kCorrectionStride * d.gauge_corners[g] + k] = true;
    }
  }
  return held;
}

// Holds the components of `block` (`size` values) that `held` marks: the whole
// block when all are, else through a SubsetManifold.
void HoldComponents(ceres::Problem& problem, double* block, int size, const bool* held) {
  std::vector<int> subset;
  for (int k = 0; k < size; ++k) {
    if (held[k]) subset.push_back(k);
  }
  if (static_cast<int>(subset.size()) == size) {
    problem.SetParameterBlockConstant(block);
  } else if (!subset.empty()) {
    problem.SetManifold(block, new ceres::SubsetManifold(size, subset));
  }
}

// Holds corrections that are fixed, frozen or carry the gauge, and lists the
// free ones the Schur solver may eliminate.
template <class Board>
void HoldCorrections(const ffi::ProblemData& d, const ffi::SolveOptions& o,
                     const std::vector<bool>& corner_used, Params& p, Assembled& a) {
  ceres::Problem& problem = *a.problem;
  a.correction_observed = corner_used;
  a.correction_free.assign(d.num_corners, false);
  if (d.hold_corrections) {
    for (uint32_t c = 0; c < d.num_corners; ++c) {
      if (problem.HasParameterBlock(p.Correction(c))) problem.SetParameterBlockConstant(p.Correction(c));
    }
    return;
  }
  if (o.fix_gauge) {
    for (uint32_t c : d.gauge_corners) {
      if (!corner_used[c]) Fail("gauge corner " + std::to_string(c) + " is never observed");
    }
  }
  const std::vector<bool> held_values = HeldCorrectionComponents<Board>(d, o, corner_used);
  // std::vector<bool> has no data(): a plain copy to hand out slices of.
  const std::unique_ptr<bool[]> held(new bool[held_values.size()]);
  std::copy(held_values.begin(), held_values.end(), held.get());
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    for (int k = 0; k < Board::kCornerSize; ++k) {
      a.correction_free[c] = a.correction_free[c] || !held[kCorrectionStride * c + k];
    }
  }
  if (a.corner_groups) {
    for (uint32_t first = 0; first < d.num_corners; first += kCornersPerGroup) {
      double* block = p.Correction(first);
      if (problem.HasParameterBlock(block)) {
        HoldComponents(problem, block, p.GroupSize(first), &held[kCorrectionStride * first]);
      }
    }
    return;
  }
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    if (corner_used[c]) HoldComponents(problem, p.Correction(c), Board::kCornerSize, &held[kCorrectionStride * c]);
  }
  // A partly held gauge corner stays out of the eliminated set: with every
  // eliminated block the same size, Ceres uses its fixed-size Schur kernels.
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    double* block = p.Correction(c);
    if (corner_used[c] && !problem.IsParameterBlockConstant(block) &&
        problem.ParameterBlockTangentSize(block) == Board::kCornerSize) {
      a.correction_blocks.push_back(block);
    }
  }
}

// Views (camera, image) whose corners share one ViewBlock, in the order of
// their first observation, so that the parameter blocks enter the problem in
// the same order as with one block per corner.
struct ViewCollector {
  std::map<std::pair<uint32_t, uint32_t>, size_t> index;
  std::vector<std::unique_ptr<ViewBlock>> costs;
  std::vector<std::vector<double*>> blocks;
  std::vector<std::vector<uint32_t>> observations;

  void AddTo(Assembled& a) {
    for (size_t k = 0; k < costs.size(); ++k) {
      costs[k]->Finish();
      ceres::CostFunction* f = costs[k].release();
      if (a.compress_views && CompressedRows::Pays(*f)) f = new CompressedRows(f);
      a.AddObservations(observations[k], f, nullptr, blocks[k]);
    }
  }
};

// Whether the problem keeps the previous path (one block per corner, Ceres'
// loss from the start): asked for, or a camera with the rational opencv8 model
// solved without the lens prior.  Without it opencv8 wanders along the valley
// where its denominator trades off against its numerator, and stops 0.05 to
// 1.4 px (mapping error) short of its converged optimum on either path
// (benches/speed.rs); that problem, OpenCV's and mrcal's, keeps the path its
// comparisons were checked on.
bool PreviousPath(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (o.per_corner_blocks) return true;
  if (!d.lens_prior_weight.empty()) return false;  // the prior holds the valley
  for (const auto& m : d.lens_models) {
    if (std::string(m) == OpenCv8::kName) return true;
  }
  return false;
}

// One block per view for board models without per-corner parameters (a view
// block of a model with them would carry a mostly-zero 2N x kCornerSize
// Jacobian per corner: N times the work and memory); the reference paths keep
// one block per corner.
template <class Board>
bool UseViewBlocks(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  return Board::kCornerSize == 0 && !o.reference_jacobian && !PreviousPath(d, o);
}

// Whether the corrections share blocks of kCornersPerGroup corners: when the
// Schur solver is to eliminate the image blocks (at least as many free values in
// them as in the corrections, as ChooseLinearSolver decides, and no prior ties
// the frames).  Every image then adds a dense update over all the corrections,
// which Ceres does cell by cell: one 2 x 2 cell per pair of corners with a block
// each (about 14 500 per t2 image, 0.55 ms per image and iteration at 1 600
// images), 16 times fewer and larger with four corners a block.  The reference
// paths keep one block per corner.
template <class Board>
bool UseCornerGroups(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (Board::kCornerSize == 0 || d.hold_corrections || o.reference_jacobian || PreviousPath(d, o) ||
      !d.bend_smoothness_weight.empty()) {
    return false;
  }
  std::vector<bool> frame_used(d.num_frames, false), corner_used(d.num_corners, false);
  for (size_t i = 0; i < d.obs_frame.size(); ++i) {
    frame_used[d.obs_frame[i]] = true;
    corner_used[d.obs_corner[i]] = true;
  }
  const size_t frames = std::count(frame_used.begin(), frame_used.end(), true);
  const size_t corners = std::count(corner_used.begin(), corner_used.end(), true);
  const size_t per_frame = kPoseSize + (d.hold_deformations ? 0 : Board::kFrameExtra);
  return frames * per_frame >= corners * Board::kCornerSize;
}

template <class Board>
void AddResiduals(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p,
                  Assembled& a) {
  a.corner_groups = UseCornerGroups<Board>(d, o);
  const bool cauchy = o.loss == ffi::LossKind::Cauchy;
  ceres::LossFunction* loss = cauchy ? new SwitchableCauchy(o.loss_scale_px, a.loss_scale_factor) : nullptr;
  const CauchyFold fold{cauchy ? o.loss_scale_px * o.loss_scale_px : 0.0};
  const size_t n = d.obs_uv.size() / 2;
  constexpr bool kHasCorner = Board::kCornerSize > 0;
  constexpr bool kHasFrameExtra = Board::kFrameExtra > 0;
  const bool pose_only = d.hold_intrinsics && (d.num_cameras == 1 || d.hold_camera_poses) &&
                         (!kHasCorner || d.hold_corrections) &&
                         (!kHasFrameExtra || d.hold_deformations);
  const bool per_view = UseViewBlocks<Board>(d, o);
  // A static correction's per-corner blocks fold the loss in as view blocks do:
  // over 6 t2 sets its stage took 12-17 % fewer iterations (radial3, kb4; 6 %
  // for ds) to the same optimum (3.7e-3 px).  Where per-frame bends start flat
  // (full) the corners they move start far beyond the scale, where the folded
  // model pulls less than Ceres' correction: 10-33 % more iterations, so no fold.
  const bool fold_corners = cauchy && Board::kFrameExtra == 0 && !o.reference_jacobian && !PreviousPath(d, o);
  const std::vector<LensOps<Board>> ops = LensOpsPerCamera<Board>(d);
  std::vector<double*> blocks;
  std::vector<bool> corner_used(d.num_corners, false);
  std::vector<bool> frame_used(d.num_frames, false);
  a.residuals.reserve(n);
  // Pose-only views being collected: (camera, frame) -> functor and its observations.
  std::map<std::pair<uint32_t, uint32_t>,
           std::pair<std::unique_ptr<PoseOnlyView>, std::vector<uint32_t>>>
      views;
  ViewCollector full_views;
  bool loss_used = false;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t cam = d.obs_camera[i], frame = d.obs_frame[i], corner = d.obs_corner[i];
    double* intrinsics = p.intrinsics[cam];
    double* rig = cam > 0 ? p.camera_poses[cam] : nullptr;
    double* frame_block = p.Frame(frame);
    double* correction = kHasCorner ? p.Correction(corner) : nullptr;
    const double* x = &d.board[3 * corner];
    const double u = d.obs_uv[2 * i], v = d.obs_uv[2 * i + 1];
    const double w = d.obs_weight.empty() ? 1.0 : d.obs_weight[i];
    if (pose_only) {
      double point[3];
      Board::Point(x, frame_block + kPoseSize, correction, point);
      // The pose is the first kPoseSize values of the frame's block.
      if (loss == nullptr) {
        auto& view = views[{cam, frame}];
        if (!view.first) view.first.reset(ops[cam].view(intrinsics, rig));
        view.first->Add(u, v, w, point);
        view.second.push_back(static_cast<uint32_t>(i));
      } else {
        std::unique_ptr<PoseOnlyView> f(ops[cam].view(intrinsics, rig));
        f->Add(u, v, w, point);
        a.AddObservations(std::array<uint32_t, 1>{static_cast<uint32_t>(i)}, f->Release(), loss, frame_block);
        loss_used = true;
      }
    } else if (per_view) {
      const auto [it, fresh] = full_views.index.try_emplace({cam, frame}, full_views.costs.size());
      if (fresh) {
        full_views.costs.emplace_back(ops[cam].view_block(rig != nullptr, fold, a.loss_scale_factor));
        full_views.blocks.push_back({intrinsics});
        if (rig) full_views.blocks.back().push_back(rig);
        full_views.blocks.back().push_back(frame_block);
        full_views.observations.emplace_back();
      }
      full_views.costs[it->second]->Add(u, v, w, x);
      full_views.observations[it->second].push_back(static_cast<uint32_t>(i));
    } else {
      blocks.clear();
      blocks.push_back(intrinsics);
      if (rig) blocks.push_back(rig);
      blocks.push_back(frame_block);
      if (kHasCorner) blocks.push_back(a.corner_groups ? p.Group(corner) : correction);
      const bool grouped = kHasCorner && a.corner_groups;
      ceres::CostFunction* cost =
          ops[cam].cost(u, v, w, x, rig != nullptr, o.reference_jacobian,
                        grouped ? Params::GroupOffset(corner) : 0,
                        grouped ? p.GroupSize(corner) : Board::kCornerSize);
      if (fold_corners) cost = new FoldedCorner(cost, fold, a.loss_scale_factor);
      a.AddObservations(std::array<uint32_t, 1>{static_cast<uint32_t>(i)}, cost, fold_corners ? nullptr : loss, blocks);
      loss_used |= !fold_corners;
    }
    corner_used[corner] = true;
    frame_used[frame] = true;
  }
  full_views.AddTo(a);
  if (!loss_used) delete loss;  // Ceres owns it once a block uses it
  for (auto& [key, view] : views) {
    a.AddObservations(view.second, view.first->Release(), nullptr, p.Frame(key.second));
  }
  for (uint32_t f = 0; f < d.num_frames; ++f) {
    if (frame_used[f]) a.frame_pose_blocks.push_back(p.Frame(f));
  }
  HoldParameters<Board>(d, pose_only, p, a);
  if (kHasCorner) HoldCorrections<Board>(d, o, corner_used, p, a);
}

// The lens prior of priors.h on every camera whose intrinsics are estimated.
void AddLensPriors(const ffi::ProblemData& d, Params& p, Assembled& a) {
  if (d.lens_prior_weight.empty()) return;
  ceres::Problem& problem = *a.problem;
  for (size_t k = 0; k < d.num_cameras; ++k) {
    double* block = p.intrinsics[k];
    if (!problem.HasParameterBlock(block) || problem.IsParameterBlockConstant(block)) continue;
    const size_t begin = d.intrinsics_offsets[k], n = problem.ParameterBlockSize(block);
    std::vector<double> weight(d.lens_prior_weight.begin() + begin,
                               d.lens_prior_weight.begin() + begin + n);
    bool any = false;
    for (double w : weight) any = any || w > 0.0;
    if (any) {
      a.prior_residuals.push_back(
          a.Add(new LensPrior(std::move(weight)), nullptr, block));
    }
  }
}

// The static-correction prior of priors.h on every corner whose correction is
// free or carries the gauge: the gauge's held values (zero) are part of the
// correction field whose best-fitting similarity the prior leaves free, so with a
// tight prior that similarity is pinned by them and the correction held at zero.
template <int N>
void AddCorrectionPrior(const ffi::ProblemData& d, Params& p, Assembled& a) {
  if (d.correction_prior_weight.empty()) return;
  const auto free = [&](uint32_t c) { return static_cast<bool>(a.correction_free[c]); };
  bool any_free = false;
  for (uint32_t c = 0; c < d.num_corners && !any_free; ++c) any_free = free(c);
  if (!any_free) return;
  static_assert(SimilaritySize(N) <= Params::kSimilarityRoom, "room for the similarity");
  a.similarity = p.Similarity();
  // Starts at zero; the prior is linear in it, so any start will do.
  std::fill(a.similarity, a.similarity + SimilaritySize(N), 0.0);
  const double zeros[kCorrectionStride] = {0.0, 0.0, 0.0};
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    const bool gauge = std::find(d.gauge_corners.begin(), d.gauge_corners.end(), c) !=
                       d.gauge_corners.end();
    if (!free(c) && !(gauge && a.correction_observed[c])) continue;
    const double* mean =
        d.correction_prior_mean.empty() ? zeros : &d.correction_prior_mean[kCorrectionStride * c];
    ceres::CostFunction* prior =
        new CorrectionPrior<N>(mean, &d.correction_prior_weight[kCorrectionStride * c], &d.board[3 * c]);
    if (a.corner_groups) prior = new InCornerGroup(prior, 0, Params::GroupOffset(c), p.GroupSize(c));
    a.prior_residuals.push_back(a.Add(
        prior, nullptr, a.corner_groups ? p.Group(c) : p.Correction(c), a.similarity));
  }
}

// The priors of priors.h on the free board-model parameters (off when the
// problem data gives no weights): after the reprojection residuals, which decide
// which blocks exist and which are held.
template <class Board>
void AddPriors(const ffi::ProblemData& d, Params& p, Assembled& a) {
  constexpr int N = Board::kCornerSize, E = Board::kFrameExtra;
  AddLensPriors(d, p, a);
  if constexpr (N > 0) AddCorrectionPrior<N>(d, p, a);
  if constexpr (E > 0) {
    if (d.hold_deformations) return;
    if (!d.bend_prior_weight.empty()) {
      for (double* block : a.frame_pose_blocks) {
        a.prior_residuals.push_back(
            a.Add(new BendPrior<E>(d.bend_prior_weight.data()), nullptr, block));
      }
    }
    if (!d.bend_smoothness_weight.empty()) {
      // Frames in index order are in time order; a frame no view kept is skipped.
      for (size_t k = 1; k < a.frame_pose_blocks.size(); ++k) {
        ceres::LossFunction* loss = d.bend_smoothness_loss > 0.0
                                        ? new ceres::CauchyLoss(d.bend_smoothness_loss)
                                        : nullptr;
        a.prior_residuals.push_back(a.Add(
            new BendSmoothness<E>(d.bend_smoothness_weight.data()), loss,
            a.frame_pose_blocks[k - 1], a.frame_pose_blocks[k]));
        a.frames_linked = true;
      }
    }
  }
}

// `compress_views`: view blocks as CompressedRows, for a problem that is solved.
Assembled Assemble(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p,
                   bool compress_views = false) {
  SilenceGlogOnce();
  Assembled a;
  a.compress_views = compress_views;
  ceres::Problem::Options options;
  options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // Assembled::costs
  // ValidateProblem checked every offset, so no two blocks overlap; the checks
  // would sort a copy of every block's parameter list.
  options.disable_all_safety_checks = true;
  a.problem = std::make_unique<ceres::Problem>(options);
  DispatchBoard(std::string(d.board_model),
                [&](auto board) {
                  AddResiduals<decltype(board)>(d, o, p, a);
                  AddPriors<decltype(board)>(d, p, a);
                });
  return a;
}

// Validates the problem data before anything reads through its offsets.
void ValidateProblem(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (d.num_cameras == 0) Fail("the problem has no camera");
  if (d.num_frames == 0) Fail("the problem has no image");
  if (d.num_corners == 0) Fail("the board has no corner");
  if (d.obs_uv.size() < 2) Fail("the problem has no observation");
  const bool known = DispatchBoard(std::string(d.board_model),
                                   [&](auto board) { Validate<decltype(board)>(d, o); });
  if (!known) Fail("unknown board model `" + std::string(d.board_model) + "`");
}

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
// 4.1 s at 1600; for `standard` at 1600 dense 0.74 s, iterative 0.80 s.  So
// dense stays up to 1200 reduced parameters and iterative Schur is not used.
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

// Relative tolerances of the warm-up: it only needs to come close.
constexpr double kWarmUpTolerance = 1e-3;

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
void DirectJacobian(const Assembled& a, const double* base, size_t num_observations,
                    ffi::Jacobian& out) {
  const ceres::Problem& problem = *a.problem;
  *a.loss_scale_factor = 0.0;  // the Jacobian of the plain residuals
  const FreeColumns f = FreeColumnsOf(a, base);
  // Rows come block by block; observation i's two rows go to rows 2i, 2i+1.
  std::vector<uint32_t> cols;
  std::vector<double> vals;
  std::vector<std::pair<uint32_t, uint32_t>> spans(2 * num_observations);  // into cols/vals
  out.residuals.assign(2 * num_observations, 0.0);
  std::vector<double*> blocks;
  std::vector<std::vector<double>> jac;
  std::vector<double*> jac_ptr;
  std::vector<const std::pair<uint32_t, std::vector<int>>*> free;
  std::vector<double> r;
  for (size_t k = 0; k < a.residuals.size(); ++k) {
    const ceres::CostFunction* cost = &a.PlainCost(k);
    problem.GetParameterBlocksForResidualBlock(a.residuals[k], &blocks);
    const std::vector<int32_t>& sizes = cost->parameter_block_sizes();
    const int nres = cost->num_residuals();
    jac.resize(blocks.size());
    jac_ptr.assign(blocks.size(), nullptr);
    free.assign(blocks.size(), nullptr);
    for (size_t b = 0; b < blocks.size(); ++b) {
      jac[b].assign(static_cast<size_t>(nres) * sizes[b], 0.0);
      const auto it = f.blocks.find(blocks[b]);
      if (it != f.blocks.end()) {
        jac_ptr[b] = jac[b].data();
        free[b] = &it->second;
      }
    }
    r.assign(nres, 0.0);
    if (!cost->Evaluate(blocks.data(), r.data(), jac_ptr.data())) {
      Fail("the residuals could not be evaluated (a point behind the camera?)");
    }
    const uint32_t* obs = a.ObservationsOf(k, nres);
    for (int row = 0; row < nres; ++row) {
      const size_t target = 2 * obs[row / 2] + row % 2;
      out.residuals[target] = r[row];
      spans[target].first = static_cast<uint32_t>(cols.size());
      for (size_t b = 0; b < blocks.size(); ++b) {
        if (free[b] == nullptr) continue;
        const auto& [first, coords] = *free[b];
        const double* jrow = jac[b].data() + static_cast<size_t>(row) * sizes[b];
        for (size_t j = 0; j < coords.size(); ++j) {
          cols.push_back(first + static_cast<uint32_t>(j));
          vals.push_back(jrow[coords[j]]);
        }
      }
      spans[target].second = static_cast<uint32_t>(cols.size());
    }
  }
  out.cols = f.params.size();
  out.col_idx.reserve(cols.size());
  out.values.reserve(vals.size());
  out.row_ptr.reserve(spans.size() + 1);
  out.row_ptr.push_back(0);
  for (const auto& [lo, hi] : spans) {
    out.col_idx.insert(out.col_idx.end(), cols.begin() + lo, cols.begin() + hi);
    out.values.insert(out.values.end(), vals.begin() + lo, vals.begin() + hi);
    out.row_ptr.push_back(static_cast<uint32_t>(out.col_idx.size()));
  }
  out.col_param = f.params;
}

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

namespace ffi {

// What a prepared pose refit keeps: everything but the intrinsics.
struct PoseRefitState {
  FrameCorners frames;
  std::vector<double> start_poses;  // kPoseSize per frame
  std::vector<MakePoseViewFn> make;
  std::vector<size_t> num_params;  // per camera
  std::vector<double> rig_poses;   // kPoseSize per camera
  int max_iterations = 0;
};

PoseRefit::PoseRefit(std::unique_ptr<const PoseRefitState> state) : state_(std::move(state)) {}
PoseRefit::~PoseRefit() = default;

double PoseRefit::rmse_px(rust::Slice<const double> intrinsics) const {
  const PoseRefitState& s = *state_;
  std::vector<const double*> lens(s.num_params.size()), rigs(s.num_params.size(), nullptr);
  size_t at = 0;
  for (size_t k = 0; k < s.num_params.size(); ++k) {
    lens[k] = intrinsics.data() + at;
    at += s.num_params[k];
    if (k > 0) rigs[k] = &s.rig_poses[kPoseSize * k];
  }
  if (at != intrinsics.size()) {
    Fail("the refit's intrinsics have " + std::to_string(intrinsics.size()) + " values, expected " +
         std::to_string(at));
  }
  double sum = 0.0;
  size_t corners = 0;
  for (size_t j = 0; j < s.frames.size(); ++j) {
    if (s.frames[j].empty()) continue;
    double pose[kPoseSize];
    std::copy_n(&s.start_poses[kPoseSize * j], kPoseSize, pose);
    const auto views = FrameViews(s.frames[j], s.make, lens, rigs);
    bool ok = RefitFramePose(views, pose, s.max_iterations).ok;
    for (size_t v = 0; v < views.size() && ok; ++v) {
      ok = views[v]->SquaredError(pose, &sum);
      corners += s.frames[j][v].corners.size();
    }
    if (!ok || !std::isfinite(sum)) {
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
  for (size_t j = 0; j < data.num_frames; ++j) {
    state->start_poses.insert(state->start_poses.end(), params.Frame(j), params.Frame(j) + kPoseSize);
  }
  state->make = PoseViewMakers(data);
  for (size_t k = 0; k < data.num_cameras; ++k) {
    DispatchLens(std::string(data.lens_models[k]),
                 [&](auto lens) { state->num_params.push_back(decltype(lens)::kNumParams); });
    state->rig_poses.insert(state->rig_poses.end(), params.camera_poses[k],
                            params.camera_poses[k] + kPoseSize);
  }
  state->max_iterations = options.max_iterations;
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
  ceres::Solve(s, a.problem.get(), &summary);

  SolveReport report;
  report.usable = summary.IsSolutionUsable();
  report.converged = summary.termination_type == ceres::CONVERGENCE;
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
