// The C++ side of the cxx bridge.  Deliberately free of Ceres and Eigen
// includes: the cxx-generated header includes this file before it defines the
// shared structs, so they are only forward-declared here.
#pragma once

#include "rust/cxx.h"

namespace deformcal {
namespace ffi {

struct ProblemData;
struct SolveOptions;
struct SolveReport;
struct Evaluation;

// Builds the Ceres problem for data.board_model, solves it and writes the refined
// parameters back into data.  Invalid input throws (a Rust Err), never aborts.
SolveReport solve(ProblemData& data, const SolveOptions& options);

// Residuals (observed minus projected, loss not applied) at the current
// parameters, and optionally the Jacobian over the free parameters.
Evaluation evaluate(const ProblemData& data, const SolveOptions& options, bool with_jacobian);

// The C++ registries, exposed so that a test can check them against Rust's.
size_t lens_num_params(rust::Str model);
rust::Vec<double> project_points(rust::Str model, rust::Slice<const double> params,
                                 rust::Slice<const double> points);
rust::Vec<size_t> board_model_sizes(rust::Str model);
rust::Vec<double> board_point(rust::Str model, rust::Slice<const double> nominal,
                              rust::Slice<const double> frame_extra,
                              rust::Slice<const double> correction);

}  // namespace ffi
}  // namespace deformcal
