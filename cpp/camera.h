// Camera side of the reprojection: rigid transforms, templated on the scalar
// so Ceres' Jets flow through unchanged, and in closed form with their
// Jacobians; the lens models come with their registry (lens/registry.h).
#pragma once

#include <ceres/rotation.h>

#include <cmath>

#include "deformcal/cpp/lens/registry.h"

namespace deformcal {

// Angle-axis rotation followed by translation.
constexpr int kPoseSize = 6;

// x_out = R(pose[0..3]) * x + pose[3..6]
template <typename T>
inline void TransformPoint(const T* pose, const T* x, T* x_out) {
  ceres::AngleAxisRotatePoint(pose, x, x_out);
  x_out[0] += pose[3];
  x_out[1] += pose[4];
  x_out[2] += pose[5];
}

// R(ω) and SO(3)'s left Jacobian J_l(ω) (see TransformPointWithJacobian).
inline void RotationWithLeftJacobian(const double* w, double* R, double* Jl) {
  const double t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
  double a, b, c;
  if (t2 < 1e-4) {
    // Taylor series: the closed forms cancel catastrophically near zero.
    a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0;
    b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0;
    c = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0;
  } else {
    const double t = std::sqrt(t2);
    const double s = std::sin(t), co = std::cos(t);
    a = s / t;
    b = (1.0 - co) / t2;
    c = (t - s) / (t2 * t);
  }
  // [ω]_× and [ω]_×² = ω ωᵀ - |ω|² I.
  const double W[9] = {0, -w[2], w[1], w[2], 0, -w[0], -w[1], w[0], 0};
  double W2[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) W2[3 * i + j] = w[i] * w[j] - (i == j ? t2 : 0.0);
  for (int k = 0; k < 9; ++k) {
    const double id = (k % 4 == 0) ? 1.0 : 0.0;
    R[k] = id + a * W[k] + b * W2[k];
    Jl[k] = id + b * W[k] + c * W2[k];
  }
}

// x_out = R x + t and dx_out/dω (row-major 3x3) from the pose's R and J_l:
// d(R x)/dω = -[R x]_× J_l(ω); dx_out/dt is the identity.
inline void TransformWithRotation(const double* pose, const double* R, const double* Jl, const double* x,
                                  double* x_out, double* d_omega) {
  double y[3];
  for (int i = 0; i < 3; ++i) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
  // -[y]_× rows, times J_l.
  const double Ny[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      d_omega[3 * i + j] = Ny[3 * i] * Jl[j] + Ny[3 * i + 1] * Jl[3 + j] + Ny[3 * i + 2] * Jl[6 + j];
  for (int i = 0; i < 3; ++i) x_out[i] = y[i] + pose[3 + i];
}

// x_out = R x + t for a double pose, with R and dx_out/dω (both row-major 3x3);
// dx_out/dt is the identity.  Closed form, so the pose's derivatives cost one
// sincos instead of six-wide Jets, with SO(3)'s left Jacobian
// J_l = I + b [ω]_× + c [ω]_×² and R = I + a [ω]_× + b [ω]_×².
inline void TransformPointWithJacobian(const double* pose, const double* x, double* x_out,
                                       double* R, double* d_omega) {
  double Jl[9];
  RotationWithLeftJacobian(pose, R, Jl);
  TransformWithRotation(pose, R, Jl, x, x_out, d_omega);
}

// One frame's R(ω) and J_l(ω), shared by the blocks of its corners and made
// again only when ω changes: a solve evaluates every corner block of a frame
// at the same ω, and each made its own (a sincos, about a fifth of a `static`
// corner's Jacobian).  The same values as RotationWithLeftJacobian's, to the bit.
struct FrameRotation {
  double w[3] = {std::nan(""), std::nan(""), std::nan("")};
  double R[9] = {}, Jl[9] = {};

  void At(const double* omega) {
    if (omega[0] == w[0] && omega[1] == w[1] && omega[2] == w[2]) return;
    RotationWithLeftJacobian(omega, R, Jl);
    for (int i = 0; i < 3; ++i) w[i] = omega[i];
  }
};

}  // namespace deformcal
