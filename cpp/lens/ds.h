// ds: double sphere (Usenko, Demmel, Cremers 2018); fields of view beyond 180°.
//   d1 = |(x, y, z)|, zz = ξ d1 + z, d2 = |(x, y, zz)|, m = α d2 + (1 - α) zz
//   u = fx x / m + cx,  v = fy y / m + cy
// Parameters fx fy cx cy xi alpha, f > 0, α in [0, 1] (ξ typically in
// [-1, 1]); a point is in the model's domain where z > -w2 d1 (the paper's
// eq. 43), which the Rust side checks (src/model/lens/ds.rs).
#pragma once

#include <cmath>

#include "deformcal/cpp/lens/common.h"

namespace deformcal {

struct DoubleSphere {
  static constexpr const char* kName = "ds";
  static constexpr int kNumParams = 6;  // fx fy cx cy xi alpha
  static constexpr bool kPerCornerWithoutPrior = false;

  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    using std::sqrt;
    const T& xi = p[4];
    const T& alpha = p[5];
    const T d1 = sqrt(xc[0] * xc[0] + xc[1] * xc[1] + xc[2] * xc[2]);
    const T zz = xi * d1 + xc[2];
    const T d2 = sqrt(xc[0] * xc[0] + xc[1] * xc[1] + zz * zz);
    const T m = alpha * d2 + (T(1.0) - alpha) * zz;
    uv[0] = p[0] * xc[0] / m + p[2];
    uv[1] = p[1] * xc[1] / m + p[3];
    return true;
  }

  // Through m: (u, v) = f (x, y) / m + c.
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    double* Ju = J;
    double* Jv = StartJacobian<DoubleSphere>(p, xc, uv, J);
    const double x = xc[0], y = xc[1], z = xc[2];
    const double fx = p[0], fy = p[1], xi = p[4], alpha = p[5];
    const double d1 = std::sqrt(x * x + y * y + z * z);
    const double zz = xi * d1 + z;
    const double d2 = std::sqrt(x * x + y * y + zz * zz);
    const double m = alpha * d2 + (1.0 - alpha) * zz;
    const double im = 1.0 / m;
    // dm/dzz, and dm/d(x, y, z) through d2 and zz = xi d1 + z.
    const double dm_dzz = alpha * zz / d2 + 1.0 - alpha;
    const double dm_dxi = dm_dzz * d1;
    const double dm_dalpha = d2 - zz;
    const double dm[3] = {alpha * x / d2 + dm_dzz * xi * x / d1,
                          alpha * y / d2 + dm_dzz * xi * y / d1, dm_dzz * (xi * z / d1 + 1.0)};
    const double gu = -fx * x * im * im, gv = -fy * y * im * im;  // d u / d m, d v / d m
    Ju[0] = x * im;
    Ju[2] = 1.0;
    Jv[1] = y * im;
    Jv[3] = 1.0;
    Ju[4] = gu * dm_dxi;
    Jv[4] = gv * dm_dxi;
    Ju[5] = gu * dm_dalpha;
    Jv[5] = gv * dm_dalpha;
    for (int c = 0; c < 3; ++c) {
      Ju[kNumParams + c] = gu * dm[c] + (c == 0 ? fx * im : 0.0);
      Jv[kNumParams + c] = gv * dm[c] + (c == 1 ? fy * im : 0.0);
    }
    return true;
  }
};

}  // namespace deformcal
