// pinhole: a pinhole camera without distortion.
//   u = fx x / z + cx,  v = fy y / z + cy
// Parameters fx fy cx cy, f > 0; every point is projected (z > 0 is the
// caller's business, as for the OpenCV family).
#pragma once

#include "deformcal/cpp/lens/common.h"

namespace deformcal {

struct Pinhole {
  static constexpr const char* kName = "pinhole";
  static constexpr int kNumParams = 4;  // fx fy cx cy
  static constexpr bool kPerCornerWithoutPrior = false;

  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    const T xn = xc[0] / xc[2];
    const T yn = xc[1] / xc[2];
    uv[0] = p[0] * xn + p[2];
    uv[1] = p[1] * yn + p[3];
    return true;
  }

  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    double* Ju = J;
    double* Jv = StartJacobian<Pinhole>(p, xc, uv, J);
    const double iz = 1.0 / xc[2];
    const double xn = xc[0] / xc[2], yn = xc[1] / xc[2];
    Ju[0] = xn;
    Ju[2] = 1.0;
    Jv[1] = yn;
    Jv[3] = 1.0;
    Ju[kNumParams] = p[0] * iz;
    Ju[kNumParams + 2] = -p[0] * xn * iz;
    Jv[kNumParams + 1] = p[1] * iz;
    Jv[kNumParams + 2] = -p[1] * yn * iz;
    return true;
  }
};

}  // namespace deformcal
