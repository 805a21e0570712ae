// Validation of the problem data and options before anything reads through
// their offsets: everything that would otherwise trip a CHECK deep inside
// Ceres comes back to Rust as an error (Fail).
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"
#include "deformcal/src/solver/bridge.rs.h"

namespace deformcal {
namespace {

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
  if (!(o.settle_cost_change >= 0.0)) {
    Fail("settle_cost_change must be a non-negative number");
  }
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

}  // namespace
}  // namespace deformcal
