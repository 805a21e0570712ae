// The assembled problem and the bookkeeping the solver and evaluator need,
// and the robust loss its blocks share.
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <cstdint>
#include <iterator>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "deformcal/cpp/residuals.h"
#include "deformcal/cpp/solver/validate.h"

namespace deformcal {
namespace {

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
  // Per frame, the rotation its corner blocks share (FrameRotation; empty
  // where several threads evaluate them).  Sized before any block points
  // into it; a move of the vector keeps its storage.
  std::vector<FrameRotation> rotations;

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

}  // namespace
}  // namespace deformcal
