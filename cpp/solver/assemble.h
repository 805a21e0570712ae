// Problem assembly: each observation's residual block by its camera's lens
// model and the board model, the holds (hold.h) and the priors (add_priors.h).
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "deformcal/cpp/residuals.h"
#include "deformcal/cpp/solver/add_priors.h"
#include "deformcal/cpp/solver/assembled.h"
#include "deformcal/cpp/solver/hold.h"
#include "deformcal/cpp/solver/params.h"
#include "deformcal/cpp/solver/validate.h"

namespace deformcal {
namespace {

// How residuals of one camera are made: its lens model chosen once per camera.
template <class Board>
struct LensOps {
  // corner_offset, corner_width: the corner's slot in its correction block.
  // rotation: the frame's shared rotation (FrameRotation), or null.
  ceres::CostFunction* (*cost)(double u, double v, double w, const double* x, bool rig,
                               bool reference, int corner_offset, int corner_width,
                               FrameRotation* rotation);
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
                              bool reference, int corner_offset, int corner_width,
                              FrameRotation* rotation) {
  if (reference) {
    if (corner_width != Board::kCornerSize) Fail("the reference residual has no corner groups");
    return rig ? ReprojectionError<Lens, Board, true>::Create(u, v, w, x)
               : ReprojectionError<Lens, Board, false>::Create(u, v, w, x);
  }
  auto place = [&](auto* f) {
    if (corner_width != Board::kCornerSize) f->PlaceCorner(corner_offset, corner_width);
    f->ShareRotation(rotation);
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
// loss from the start): asked for, or a camera whose lens model needs it
// without the lens prior (kPerCornerWithoutPrior in its header, e.g. the
// rational opencv8, whose comparisons with OpenCV and mrcal were checked on
// that path).
bool PreviousPath(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (o.per_corner_blocks) return true;
  if (!d.lens_prior_weight.empty()) return false;  // the prior holds the valley
  for (const auto& m : d.lens_models) {
    if (LensPerCornerWithoutPrior(std::string(m))) return true;
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

// Adds every observation's reprojection residual, in observation order (the
// order blocks enter the problem, which fixes Ceres' result bit for bit):
// pose-only views, view blocks, or one block per corner, then holds what the
// problem data hold.
template <class Board>
class ResidualAdder {
 public:
  static constexpr bool kHasCorner = Board::kCornerSize > 0;
  static constexpr bool kHasFrameExtra = Board::kFrameExtra > 0;

  ResidualAdder(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p, Assembled& a)
      : d_(d), o_(o), p_(p), a_(a), ops_(LensOpsPerCamera<Board>(d)) {
    a.corner_groups = UseCornerGroups<Board>(d, o);
    const bool cauchy = o.loss == ffi::LossKind::Cauchy;
    loss_ = cauchy ? new SwitchableCauchy(o.loss_scale_px, a.loss_scale_factor) : nullptr;
    fold_ = CauchyFold{cauchy ? o.loss_scale_px * o.loss_scale_px : 0.0};
    pose_only_ = d.hold_intrinsics && (d.num_cameras == 1 || d.hold_camera_poses) &&
                 (!kHasCorner || d.hold_corrections) && (!kHasFrameExtra || d.hold_deformations);
    per_view_ = UseViewBlocks<Board>(d, o);
    // A static correction's per-corner blocks fold the loss in as view blocks do:
    // over 6 t2 sets its stage took 12-17 % fewer iterations (radial3, kb4; 6 %
    // for ds) to the same optimum (3.7e-3 px).  Where per-frame bends start flat
    // (full) the corners they move start far beyond the scale, where the folded
    // model pulls less than Ceres' correction: 10-33 % more iterations, so no fold.
    fold_corners_ = cauchy && Board::kFrameExtra == 0 && !o.reference_jacobian && !PreviousPath(d, o);
    corner_used_.assign(d.num_corners, false);
    frame_used_.assign(d.num_frames, false);
    // Blocks share their frame's rotation where one thread evaluates them all.
    if (o.num_threads <= 1) a.rotations.resize(d.num_frames);
  }

  void Run() {
    const size_t n = d_.obs_uv.size() / 2;
    a_.residuals.reserve(n);
    for (size_t i = 0; i < n; ++i) {
      const uint32_t cam = d_.obs_camera[i], frame = d_.obs_frame[i], corner = d_.obs_corner[i];
      if (pose_only_) {
        AddPoseOnly(i, cam, frame, corner);
      } else if (per_view_) {
        AddToView(i, cam, frame, corner);
      } else {
        AddCorner(i, cam, frame, corner);
      }
      corner_used_[corner] = true;
      frame_used_[frame] = true;
    }
    full_views_.AddTo(a_);
    if (!loss_used_) delete loss_;  // Ceres owns it once a block uses it
    for (auto& [key, view] : views_) {
      a_.AddObservations(view.second, view.first->Release(), nullptr, p_.Frame(key.second));
    }
    for (uint32_t f = 0; f < d_.num_frames; ++f) {
      if (frame_used_[f]) a_.frame_pose_blocks.push_back(p_.Frame(f));
    }
    HoldParameters<Board>(d_, pose_only_, p_, a_);
    if (kHasCorner) HoldCorrections<Board>(d_, o_, corner_used_, p_, a_);
  }

 private:
  double* Rig(uint32_t cam) const { return cam > 0 ? p_.camera_poses[cam] : nullptr; }
  double Weight(size_t i) const { return d_.obs_weight.empty() ? 1.0 : d_.obs_weight[i]; }

  // The pose is the first kPoseSize values of the frame's block.
  void AddPoseOnly(size_t i, uint32_t cam, uint32_t frame, uint32_t corner) {
    double* frame_block = p_.Frame(frame);
    double* correction = kHasCorner ? p_.Correction(corner) : nullptr;
    double point[3];
    Board::Point(&d_.board[3 * corner], frame_block + kPoseSize, correction, point);
    const double u = d_.obs_uv[2 * i], v = d_.obs_uv[2 * i + 1], w = Weight(i);
    if (loss_ == nullptr) {
      auto& view = views_[{cam, frame}];
      if (!view.first) view.first.reset(ops_[cam].view(p_.intrinsics[cam], Rig(cam)));
      view.first->Add(u, v, w, point);
      view.second.push_back(static_cast<uint32_t>(i));
    } else {
      std::unique_ptr<PoseOnlyView> f(ops_[cam].view(p_.intrinsics[cam], Rig(cam)));
      f->Add(u, v, w, point);
      a_.AddObservations(std::array<uint32_t, 1>{static_cast<uint32_t>(i)}, f->Release(), loss_,
                         frame_block);
      loss_used_ = true;
    }
  }

  void AddToView(size_t i, uint32_t cam, uint32_t frame, uint32_t corner) {
    double* rig = Rig(cam);
    const auto [it, fresh] = full_views_.index.try_emplace({cam, frame}, full_views_.costs.size());
    if (fresh) {
      full_views_.costs.emplace_back(ops_[cam].view_block(rig != nullptr, fold_, a_.loss_scale_factor));
      full_views_.blocks.push_back({p_.intrinsics[cam]});
      if (rig) full_views_.blocks.back().push_back(rig);
      full_views_.blocks.back().push_back(p_.Frame(frame));
      full_views_.observations.emplace_back();
    }
    full_views_.costs[it->second]->Add(d_.obs_uv[2 * i], d_.obs_uv[2 * i + 1], Weight(i),
                                       &d_.board[3 * corner]);
    full_views_.observations[it->second].push_back(static_cast<uint32_t>(i));
  }

  void AddCorner(size_t i, uint32_t cam, uint32_t frame, uint32_t corner) {
    double* rig = Rig(cam);
    blocks_.clear();
    blocks_.push_back(p_.intrinsics[cam]);
    if (rig) blocks_.push_back(rig);
    blocks_.push_back(p_.Frame(frame));
    if (kHasCorner) blocks_.push_back(a_.corner_groups ? p_.Group(corner) : p_.Correction(corner));
    const bool grouped = kHasCorner && a_.corner_groups;
    ceres::CostFunction* cost =
        ops_[cam].cost(d_.obs_uv[2 * i], d_.obs_uv[2 * i + 1], Weight(i), &d_.board[3 * corner],
                       rig != nullptr, o_.reference_jacobian, grouped ? Params::GroupOffset(corner) : 0,
                       grouped ? p_.GroupSize(corner) : Board::kCornerSize,
                       a_.rotations.empty() ? nullptr : &a_.rotations[frame]);
    if (fold_corners_) cost = new FoldedCorner(cost, fold_, a_.loss_scale_factor);
    a_.AddObservations(std::array<uint32_t, 1>{static_cast<uint32_t>(i)}, cost,
                       fold_corners_ ? nullptr : loss_, blocks_);
    loss_used_ |= !fold_corners_;
  }

  const ffi::ProblemData& d_;
  const ffi::SolveOptions& o_;
  Params& p_;
  Assembled& a_;
  const std::vector<LensOps<Board>> ops_;
  ceres::LossFunction* loss_ = nullptr;
  CauchyFold fold_;
  bool pose_only_ = false, per_view_ = false, fold_corners_ = false, loss_used_ = false;
  std::vector<double*> blocks_;
  std::vector<bool> corner_used_, frame_used_;
  // Pose-only views being collected: (camera, frame) -> functor and its observations.
  std::map<std::pair<uint32_t, uint32_t>,
           std::pair<std::unique_ptr<PoseOnlyView>, std::vector<uint32_t>>>
      views_;
  ViewCollector full_views_;
};

template <class Board>
void AddResiduals(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p, Assembled& a) {
  ResidualAdder<Board>(d, o, p, a).Run();
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

}  // namespace
}  // namespace deformcal
