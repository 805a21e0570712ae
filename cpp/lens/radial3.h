// radial3: the paper's model, OpenCV's with p1 = p2 = 0 (opencv_family.h has
// the formula).  Parameters fx fy cx cy k1 k2 k3; any real values, with f > 0.
#pragma once

#include "deformcal/cpp/lens/opencv_family.h"

namespace deformcal {

struct Radial3 {
  static constexpr const char* kName = "radial3";
  static constexpr int kNumParams = 7;  // fx fy cx cy k1 k2 k3
  static constexpr bool kPerCornerWithoutPrior = false;
  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    const T xn = xc[0] / xc[2];
    const T yn = xc[1] / xc[2];
    const T r2 = xn * xn + yn * yn;
    const T d = T(1.0) + r2 * (p[4] + r2 * (p[5] + r2 * p[6]));
    uv[0] = p[0] * xn * d + p[2];
    uv[1] = p[1] * yn * d + p[3];
    return true;
  }
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    return OpenCvProjectWithJacobian<Radial3, false, false>(p, xc, uv, J);
  }
};

}  // namespace deformcal
