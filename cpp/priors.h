// Gaussian priors on the board model's parameters (beyond the paper, docs/conventions.md §2): extra
// residuals on top of the gauge the parameterisation fixes, never instead of it.
//
// Each prior is a whitened difference r = w (value - mean), w = sigma_noise /
// sigma_prior, so that its squared residual sits on the same pixel scale as the
// reprojection residuals.  The functors are linear with constant Jacobians and
// know nothing of the problem assembly; solver.cc adds them after the
// reprojection residuals, and keeps them out of the residuals it reports.
#pragma once

#include <ceres/sized_cost_function.h>

#include <array>
#include <utility>
#include <vector>

#include "deformcal/cpp/camera.h"

namespace deformcal {

// The number of similarity values that a correction of N values is blind to: a
// 3-D similarity (translation 3, rotation 3, scale 1) for N = 3, an in-plane one
// (translation 2, rotation about z, scale) for N = 2.
constexpr int SimilaritySize(int n) { return n == 3 ? 7 : 4; }

// The prior on one corner's static correction (its N estimated values), less a
// similarity s shared by every corner: r = w (delta - mean - B s), with B the
// similarity's Jacobian at the corner's nominal position x (rotation: omega x x;
// scale: x).  s is a free block of its own, so minimised over s this is a prior
// on the correction less its best-fitting similarity: the gauge's held corners
// make the true correction appear minus a similarity, which the data barely
// determine, and an i.i.d. prior on it would shrink that part (a bias that does
// not vanish with more images).
template <int N>
class CorrectionPrior : public ceres::SizedCostFunction<N, N, SimilaritySize(N)> {
 public:
  static constexpr int G = SimilaritySize(N);
  CorrectionPrior(const double* mean, const double* weight, const double* x) {
    for (int k = 0; k < N; ++k) {
      mean_[k] = mean[k];
      weight_[k] = weight[k];
    }
    b_.fill(0.0);
    if constexpr (N == 3) {
      // s = (t, omega, m): B = [I | -[x]_x | x].
      for (int k = 0; k < 3; ++k) b_[k * G + k] = 1.0;
      b_[0 * G + 4] = x[2], b_[0 * G + 5] = -x[1];
      b_[1 * G + 3] = -x[2], b_[1 * G + 5] = x[0];
      b_[2 * G + 3] = x[1], b_[2 * G + 4] = -x[0];
      for (int k = 0; k < 3; ++k) b_[k * G + 6] = x[k];
    } else {
      // s = (tx, ty, theta, m): B = [I | (-y, x) | (x, y)].
      b_[0 * G + 0] = 1.0, b_[0 * G + 2] = -x[1], b_[0 * G + 3] = x[0];
      b_[1 * G + 1] = 1.0, b_[1 * G + 2] = x[0], b_[1 * G + 3] = x[1];
    }
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    for (int k = 0; k < N; ++k) {
      double bs = 0.0;
      for (int g = 0; g < G; ++g) bs += b_[k * G + g] * p[1][g];
      r[k] = weight_[k] * (p[0][k] - mean_[k] - bs);
    }
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      for (int k = 0; k < N * N; ++k) jacobians[0][k] = 0.0;
      for (int k = 0; k < N; ++k) jacobians[0][k * N + k] = weight_[k];
    }
    if (jacobians != nullptr && jacobians[1] != nullptr) {
      for (int k = 0; k < N * G; ++k) jacobians[1][k] = -weight_[k / G] * b_[k];
    }
    return true;
  }

 private:
  std::array<double, N> mean_, weight_;
  std::array<double, N * SimilaritySize(N)> b_;
};

// The zero-mean prior on one image's bend coefficients (the E values after the
// pose in the frame's block): an amplitude prior.
template <int E>
class BendPrior : public ceres::SizedCostFunction<E, kPoseSize + E> {
 public:
  explicit BendPrior(const double* weight) {
    for (int k = 0; k < E; ++k) weight_[k] = weight[k];
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    for (int k = 0; k < E; ++k) r[k] = weight_[k] * p[0][kPoseSize + k];
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      for (int k = 0; k < E * (kPoseSize + E); ++k) jacobians[0][k] = 0.0;
      for (int k = 0; k < E; ++k) jacobians[0][k * (kPoseSize + E) + kPoseSize + k] = weight_[k];
    }
    return true;
  }

 private:
  std::array<double, E> weight_;
};

// Temporal smoothness: image j's bend coefficients tied to image j-1's, for
// frames in time order (a slowly flexing board bends alike in consecutive frames).
template <int E>
class BendSmoothness : public ceres::SizedCostFunction<E, kPoseSize + E, kPoseSize + E> {
 public:
  explicit BendSmoothness(const double* weight) {
    for (int k = 0; k < E; ++k) weight_[k] = weight[k];
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    for (int k = 0; k < E; ++k) r[k] = weight_[k] * (p[1][kPoseSize + k] - p[0][kPoseSize + k]);
    for (int b = 0; b < 2; ++b) {
      if (jacobians == nullptr || jacobians[b] == nullptr) continue;
      for (int k = 0; k < E * (kPoseSize + E); ++k) jacobians[b][k] = 0.0;
      for (int k = 0; k < E; ++k) {
        jacobians[b][k * (kPoseSize + E) + kPoseSize + k] = b == 0 ? -weight_[k] : weight_[k];
      }
    }
    return true;
  }

 private:
  std::array<double, E> weight_;
};

// A zero-mean prior on a lens's parameters (one camera's whole intrinsics block;
// weight 0 on a value: no prior on it).  The rational model's denominator terms
// trade off against its numerator's over the range the corners cover, and this
// holds the model where the data leave it free.
class LensPrior : public ceres::CostFunction {
 public:
  explicit LensPrior(std::vector<double> weight) : weight_(std::move(weight)) {
    set_num_residuals(static_cast<int>(weight_.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(weight_.size()));
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const size_t n = weight_.size();
    for (size_t k = 0; k < n; ++k) r[k] = weight_[k] * p[0][k];
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      for (size_t k = 0; k < n * n; ++k) jacobians[0][k] = 0.0;
      for (size_t k = 0; k < n; ++k) jacobians[0][k * n + k] = weight_[k];
    }
    return true;
  }

 private:
  std::vector<double> weight_;
};

}  // namespace deformcal
