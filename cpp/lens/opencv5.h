// opencv5: OpenCV's default five coefficients (ROS plumb_bob; opencv_family.h
// has the formula).  Parameters fx fy cx cy k1 k2 p1 p2 k3; any real values,
// with f > 0.
#pragma once

#include "deformcal/cpp/lens/opencv_family.h"

namespace deformcal {

struct OpenCv5 {
  static constexpr const char* kName = "opencv5";
  static constexpr int kNumParams = 9;  // fx fy cx cy k1 k2 p1 p2 k3
  static constexpr bool kPerCornerWithoutPrior = false;
  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    const T xn = xc[0] / xc[2];
    const T yn = xc[1] / xc[2];
    const T r2 = xn * xn + yn * yn;
    const T d = T(1.0) + r2 * (p[4] + r2 * (p[5] + r2 * p[8]));
    OpenCvDistort(p, d, xn, yn, r2, uv);
    return true;
  }
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    return OpenCvProjectWithJacobian<OpenCv5, true, false>(p, xc, uv, J);
  }
};

}  // namespace deformcal
