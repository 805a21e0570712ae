// What the problem holds: intrinsics, camera poses, per-frame bend
// parameters and corner corrections (fixed, frozen or carrying the gauge).
// Part of solver.cc's one translation unit (compile time: one unit, parsed once).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "deformcal/cpp/solver/assembled.h"
#include "deformcal/cpp/solver/params.h"

namespace deformcal {
namespace {

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

}  // namespace
}  // namespace deformcal
