// opencv8: OpenCV's rational model (CALIB_RATIONAL_MODEL, ROS
// rational_polynomial; opencv_family.h has the formula).  Parameters fx fy cx cy
// k1 k2 p1 p2 k3 k4 k5 k6; any real values with f > 0 and a denominator
// 1 + k4 r² + k5 r⁴ + k6 r⁶ that stays positive over the image.
#pragma once

#include "deformcal/cpp/lens/opencv_family.h"

namespace deformcal {

struct OpenCv8 {
  static constexpr const char* kName = "opencv8";
  static constexpr int kNumParams = 12;  // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6
  // Without the lens prior the solve wanders along the valley where the
  // denominator trades off against the numerator, and the view-block path
  // stops 0.05 to 1.4 px (mapping error) short of its converged optimum
  // (benches/speed.rs): such problems keep the per-corner path that the
  // comparisons with OpenCV and mrcal were checked on.
  static constexpr bool kPerCornerWithoutPrior = true;
  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    const T xn = xc[0] / xc[2];
    const T yn = xc[1] / xc[2];
    const T r2 = xn * xn + yn * yn;
    const T num = T(1.0) + r2 * (p[4] + r2 * (p[5] + r2 * p[8]));
    const T den = T(1.0) + r2 * (p[9] + r2 * (p[10] + r2 * p[11]));
    OpenCvDistort(p, num / den, xn, yn, r2, uv);
    return true;
  }
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    return OpenCvProjectWithJacobian<OpenCv8, true, true>(p, xc, uv, J);
  }
};

}  // namespace deformcal
