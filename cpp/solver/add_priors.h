// The priors of priors.h added to an assembled problem, after the
// reprojection residuals, which decide which blocks exist and which are held.
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <vector>

#include "deformcal/cpp/priors.h"
#include "deformcal/cpp/solver/assembled.h"
#include "deformcal/cpp/solver/params.h"

namespace deformcal {
namespace {

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

}  // namespace
}  // namespace deformcal
