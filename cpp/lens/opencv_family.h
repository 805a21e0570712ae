// The OpenCV family's shared pieces (radial3.h, opencv5.h, opencv8.h): the
// tangential terms and one closed-form ProjectWithJacobian for all three.
//   x' = x / z, y' = y / z, r² = x'² + y'²
//   d  = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
//   x'' = x' d + 2 p1 x'y' + p2 (r² + 2 x'²),  y'' = y' d + p1 (r² + 2 y'²) + 2 p2 x'y'
//   u = fx x'' + cx,  v = fy y'' + cy
// Every point is projected (z > 0 is the caller's business); past the turning
// point of d the map folds, which the Rust side's unprojection refuses.
#pragma once

#include <algorithm>

#include "deformcal/cpp/lens/common.h"

namespace deformcal {

// OpenCV's tangential terms (p1 = p[6], p2 = p[7]) on top of a radial factor d.
template <typename T>
inline void OpenCvDistort(const T* p, const T& d, const T& xn, const T& yn, const T& r2, T* uv) {
  const T& p1 = p[6];
  const T& p2 = p[7];
  const T xy = xn * yn;
  const T xd = xn * d + T(2.0) * p1 * xy + p2 * (r2 + T(2.0) * xn * xn);
  const T yd = yn * d + p1 * (r2 + T(2.0) * yn * yn) + T(2.0) * p2 * xy;
  uv[0] = p[0] * xd + p[2];
  uv[1] = p[1] * yd + p[3];
}

// The radial and tangential columns of J (row u: Ju, row v: Jv): d d / d k =
// r2^i / den (numerator), -d r2^i / den (denominator).
template <bool kTangential, bool kRational>
inline void OpenCvCoefficientColumns(double fx, double fy, double xn, double yn, double r2,
                                     double d, double iden, double* Ju, double* Jv) {
  const double powers[3] = {r2, r2 * r2, r2 * r2 * r2};
  const int num_at[3] = {4, 5, kTangential ? 8 : 6};
  for (int i = 0; i < 3; ++i) {
    const double g = powers[i] * iden;
    Ju[num_at[i]] = fx * xn * g;
    Jv[num_at[i]] = fy * yn * g;
    if (kRational) {
      Ju[9 + i] = -fx * xn * d * g;
      Jv[9 + i] = -fy * yn * d * g;
    }
  }
  if (kTangential) {
    Ju[6] = fx * 2.0 * xn * yn;
    Ju[7] = fx * (r2 + 2.0 * xn * xn);
    Jv[6] = fy * (r2 + 2.0 * yn * yn);
    Jv[7] = fy * 2.0 * xn * yn;
  }
}

// The OpenCV family's ProjectWithJacobian.  kTangential and kRational select
// p1 p2 (at 6, 7; k3 then at 8) and k4 k5 k6 (at 9, 10, 11); without p1 p2, k3
// is at 6.  The pixel itself is Lens::Project's, bit for bit.
template <class Lens, bool kTangential, bool kRational>
bool OpenCvProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
  constexpr int n = Lens::kNumParams + 3;
  Lens::Project(p, xc, uv);
  const double iz = 1.0 / xc[2];
  const double xn = xc[0] * iz, yn = xc[1] * iz;
  const double r2 = xn * xn + yn * yn;
  const double k1 = p[4], k2 = p[5], k3 = kTangential ? p[8] : p[6];
  const double p1 = kTangential ? p[6] : 0.0, p2 = kTangential ? p[7] : 0.0;
  const double num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double dnum = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);  // d num / d r2
  double den = 1.0, dden = 0.0;
  if (kRational) {
    den = 1.0 + r2 * (p[9] + r2 * (p[10] + r2 * p[11]));
    dden = p[9] + r2 * (2.0 * p[10] + 3.0 * r2 * p[11]);
  }
  const double iden = 1.0 / den;
  const double d = num * iden;
  const double dd = (dnum - d * dden) * iden;  // d d / d r2
  const double xd = xn * d + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn);
  const double yd = yn * d + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn;
  const double fx = p[0], fy = p[1];
  double* Ju = J;
  double* Jv = J + n;
  std::fill(J, J + 2 * n, 0.0);
  Ju[0] = xd;
  Ju[2] = 1.0;
  Jv[1] = yd;
  Jv[3] = 1.0;
  OpenCvCoefficientColumns<kTangential, kRational>(fx, fy, xn, yn, r2, d, iden, Ju, Jv);
  // d(xd, yd) / d(xn, yn), then through xn = x / z, yn = y / z.
  const double a = 2.0 * dd;
  const double dxx = d + a * xn * xn + 2.0 * p1 * yn + 6.0 * p2 * xn;
  const double dxy = a * xn * yn + 2.0 * p1 * xn + 2.0 * p2 * yn;
  const double dyx = a * xn * yn + 2.0 * p1 * xn + 2.0 * p2 * yn;
  const double dyy = d + a * yn * yn + 6.0 * p1 * yn + 2.0 * p2 * xn;
  const int c = Lens::kNumParams;
  Ju[c] = fx * dxx * iz;
  Ju[c + 1] = fx * dxy * iz;
  Ju[c + 2] = -fx * (dxx * xn + dxy * yn) * iz;
  Jv[c] = fy * dyx * iz;
  Jv[c + 1] = fy * dyy * iz;
  Jv[c + 2] = -fy * (dyx * xn + dyy * yn) * iz;
  return true;
}

}  // namespace deformcal
