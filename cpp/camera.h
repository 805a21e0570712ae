// Camera side of the reprojection: rigid transforms and the lens model.
// Everything is templated on the scalar so Ceres' Jets flow through unchanged.
#pragma once

#include <ceres/rotation.h>

namespace deformcal {

// Number of intrinsic parameters of the radial3 model: fx, fy, cx, cy, k1, k2, k3.
constexpr int kIntrinsicsSize = 7;
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

// The paper's radial3 lens model, identical to OpenCV's with p1 = p2 = 0 (SPEC 1).
template <typename T>
inline void ProjectRadial3(const T* intrinsics, const T* xc, T* uv) {
  const T xn = xc[0] / xc[2];
  const T yn = xc[1] / xc[2];
  const T r2 = xn * xn + yn * yn;
  const T d = T(1.0) + r2 * (intrinsics[4] + r2 * (intrinsics[5] + r2 * intrinsics[6]));
  uv[0] = intrinsics[0] * xn * d + intrinsics[2];
  uv[1] = intrinsics[1] * yn * d + intrinsics[3];
}

}  // namespace deformcal
