// The C++ side of the cxx bridge.  Deliberately free of Ceres and Eigen
// includes: the cxx-generated header includes this file before it defines the
// shared structs, so they are only forward-declared here.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "rust/cxx.h"

namespace deformcal {
namespace ffi {

struct ProblemData;
struct SolveOptions;
struct SolveReport;
struct Evaluation;
struct BundleData;
struct BundleReport;

// Builds the Ceres problem for data.board_model, solves it and writes the refined
// parameters back into data.  Invalid input throws (a Rust Err), never aborts.
SolveReport solve(ProblemData& data, const SolveOptions& options);

// The same solve for a pose-only refit (everything but the board poses held, no
// loss): every frame's pose on its own, without a Ceres problem (pose_refit.h).
SolveReport refit_poses(ProblemData& data, const SolveOptions& options);

// Residuals (observed minus projected, loss not applied) at the current
// parameters, and optionally the Jacobian over the free parameters.
Evaluation evaluate(const ProblemData& data, const SolveOptions& options, bool with_jacobian);

// A pose-only refit prepared once, for refits under many intrinsics (the
// protocol's test error: every calibration against the same reference).  The
// frames' corners and held board points are kept with each frame's optimum
// under the prepared intrinsics; each refit starts from those optima moved to
// first order by its intrinsics and keeps no state, so one PoseRefit may serve
// many threads.
struct PoseRefitState;
class PoseRefit {
 public:
  explicit PoseRefit(std::unique_ptr<const PoseRefitState> state);
  ~PoseRefit();
  // The RMSE of the unweighted residuals after every frame's pose is refitted
  // under `intrinsics` (every camera's lens parameters, in camera order).
  // Throws where a board point has no image.
  double rmse_px(rust::Slice<const double> intrinsics) const;

 private:
  std::unique_ptr<const PoseRefitState> state_;
};

// Prepares the pose-only refit of `data` (the same checks as refit_poses).
std::unique_ptr<PoseRefit> prepare_pose_refit(const ProblemData& data, const SolveOptions& options);

// The Jacobian of the weighted residuals (loss not applied) over the free
// parameters in CRS, rows in observation order, and the residuals; held in C++
// and read from Rust as slices, since copying element by element into a
// rust::Vec costs more than computing it.
struct Jacobian {
  std::vector<double> residuals;
  size_t cols = 0;
  std::vector<uint32_t> row_ptr, col_idx, col_param;
  std::vector<double> values;

  rust::Slice<const double> residual_values() const { return {residuals.data(), residuals.size()}; }
  size_t num_cols() const { return cols; }
  rust::Slice<const uint32_t> row_offsets() const { return {row_ptr.data(), row_ptr.size()}; }
  rust::Slice<const uint32_t> column_indices() const { return {col_idx.data(), col_idx.size()}; }
  rust::Slice<const double> entries() const { return {values.data(), values.size()}; }
  rust::Slice<const uint32_t> column_parameters() const { return {col_param.data(), col_param.size()}; }
};

// Evaluates the Jacobian directly from the cost functions (see DirectJacobian).
std::unique_ptr<Jacobian> jacobian(const ProblemData& data, const SolveOptions& options);

// A bundle adjustment with the intrinsics held (sfm.h); poses and points in place.
BundleReport solve_bundle(BundleData& data);

// The C++ registries, exposed so that a test can check them against Rust's.
size_t lens_num_params(rust::Str model);
rust::Vec<double> project_points(rust::Str model, rust::Slice<const double> params,
                                 rust::Slice<const double> points);
rust::Vec<size_t> board_model_sizes(rust::Str model);
rust::Vec<double> board_point(rust::Str model, rust::Slice<const double> nominal,
                              rust::Slice<const double> frame_extra,
                              rust::Slice<const double> correction);
// The correction prior's sum of squares over corners with `corrections` (3 each,
// the model using a prefix) and zero mean, minimised over its similarity.
double correction_prior_minimum(rust::Str model, rust::Slice<const double> board,
                                rust::Slice<const double> corrections,
                                rust::Slice<const double> weight);

}  // namespace ffi
}  // namespace deformcal
