// The parameter buffer: a working copy of the caller's values and views of its
// tables (the layout of src/model/state.rs, checked by validate.h).
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"
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

}  // namespace
}  // namespace deformcal
