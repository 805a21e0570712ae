// kb4: Kannala-Brandt equidistant fisheye (OpenCV fisheye, Kalibr pinhole-equi,
// ROS equidistant).
//   r = sqrt(x² + y²), θ = atan2(r, z), θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)
//   u = fx x θd / r + cx,  v = fy y θd / r + cy   (on the axis: (x, y) / z)
// Parameters fx fy cx cy k1 k2 k3 k4, f > 0; valid up to the angle where θd(θ)
// stops increasing, beyond 90° from the axis if the coefficients allow it.
#pragma once

#include <cmath>

#include "deformcal/cpp/lens/common.h"

namespace deformcal {

struct Kb4 {
  static constexpr const char* kName = "kb4";
  static constexpr int kNumParams = 8;  // fx fy cx cy k1 k2 k3 k4
  static constexpr bool kPerCornerWithoutPrior = false;

  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    using std::atan2;
    using std::sqrt;
    const T r2 = xc[0] * xc[0] + xc[1] * xc[1];
    T xd, yd;
    // On the axis theta_d / r tends to 1 / z; sqrt has no derivative at 0.
    if (r2 < T(1e-30) * xc[2] * xc[2]) {
      xd = xc[0] / xc[2];
      yd = xc[1] / xc[2];
    } else {
      const T r = sqrt(r2);
      const T theta = atan2(r, xc[2]);
      const T t2 = theta * theta;
      const T theta_d = theta * (T(1.0) + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7]))));
      const T s = theta_d / r;
      xd = xc[0] * s;
      yd = xc[1] * s;
    }
    uv[0] = p[0] * xd + p[2];
    uv[1] = p[1] * yd + p[3];
    return true;
  }

  // (xd, yd) = (x, y) theta_d / r; the axis branch as Project's.
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
    double* Ju = J;
    double* Jv = StartJacobian<Kb4>(p, xc, uv, J);
    const double x = xc[0], y = xc[1], z = xc[2];
    const double fx = p[0], fy = p[1];
    const double r2 = x * x + y * y;
    Ju[2] = 1.0;
    Jv[3] = 1.0;
    if (r2 < 1e-30 * z * z) {  // Project's axis branch: (xd, yd) = (x, y) / z
      Ju[0] = x / z;
      Jv[1] = y / z;
      Ju[8] = fx / z;
      Ju[10] = -fx * x / (z * z);
      Jv[9] = fy / z;
      Jv[10] = -fy * y / (z * z);
      return true;
    }
    OffAxisJacobian(p, x, y, z, r2, Ju, Jv);
    return true;
  }

 private:
  static void OffAxisJacobian(const double* p, double x, double y, double z, double r2, double* Ju,
                              double* Jv) {
    const double fx = p[0], fy = p[1];
    const double r = std::sqrt(r2);
    const double theta = std::atan2(r, z);
    const double t2 = theta * theta;
    const double poly = 1.0 + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7])));
    const double theta_d = theta * poly;
    // d theta_d / d theta.
    const double g =
        1.0 + t2 * (3.0 * p[4] + t2 * (5.0 * p[5] + t2 * (7.0 * p[6] + t2 * 9.0 * p[7])));
    const double ir = 1.0 / r;
    const double s = theta_d * ir;
    Ju[0] = x * s;
    Jv[1] = y * s;
    double tp = theta * t2;  // theta^3, ^5, ^7, ^9
    for (int i = 0; i < 4; ++i) {
      Ju[4 + i] = fx * x * tp * ir;
      Jv[4 + i] = fy * y * tp * ir;
      tp *= t2;
    }
    // d theta / d(x, y, z) with rho2 = r2 + z2; ds = g dtheta / r - theta_d dr / r2.
    const double irho2 = 1.0 / (r2 + z * z);
    const double dth_dr = z * irho2;  // d theta / d r
    const double ds_dr = (g * dth_dr - s) * ir;
    const double ds[3] = {ds_dr * x * ir, ds_dr * y * ir, -g * r * irho2 * ir};
    for (int c = 0; c < 3; ++c) {
      Ju[kNumParams + c] = fx * (x * ds[c] + (c == 0 ? s : 0.0));
      Jv[kNumParams + c] = fy * (y * ds[c] + (c == 1 ? s : 0.0));
    }
  }
};

}  // namespace deformcal
