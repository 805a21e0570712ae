// Camera side of the reprojection: rigid transforms and the lens model.
// Everything is templated on the scalar so Ceres' Jets flow through unchanged.
#pragma once

#include <ceres/rotation.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace deformcal {

// Angle-axis rotation followed by translation.
constexpr int kPoseSize = 6;
// The largest lens model's parameter count: the stride of intrinsics tables.
constexpr int kMaxLensParams = 12;

// x_out = R(pose[0..3]) * x + pose[3..6]
template <typename T>
inline void TransformPoint(const T* pose, const T* x, T* x_out) {
  ceres::AngleAxisRotatePoint(pose, x, x_out);
  x_out[0] += pose[3];
  x_out[1] += pose[4];
  x_out[2] += pose[5];
}

// Lens models (docs/conventions.md §1).  Each is one struct: its config name, its parameter
// count and one templated projection from a camera-frame point to a pixel, used
// by every residual, with its Jacobian in closed form for the chained residuals
// (ProjectWithJacobian, below the models).  The Rust registry
// (src/model/lens.rs) describes the same models and a test checks that both
// projections agree.  Project returns false where the model has no valid image
// of the point.

// The paper's radial3 model: OpenCV's with p1 = p2 = 0.
struct Radial3 {
  static constexpr const char* kName = "radial3";
  static constexpr int kNumParams = 7;  // fx fy cx cy k1 k2 k3
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
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J);
};

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

// OpenCV's default five-coefficient model (ROS plumb_bob).
struct OpenCv5 {
  static constexpr const char* kName = "opencv5";
  static constexpr int kNumParams = 9;  // fx fy cx cy k1 k2 p1 p2 k3
  template <typename T>
  static bool Project(const T* p, const T* xc, T* uv) {
    const T xn = xc[0] / xc[2];
    const T yn = xc[1] / xc[2];
    const T r2 = xn * xn + yn * yn;
    const T d = T(1.0) + r2 * (p[4] + r2 * (p[5] + r2 * p[8]));
    OpenCvDistort(p, d, xn, yn, r2, uv);
    return true;
  }
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J);
};

// OpenCV's rational model (CALIB_RATIONAL_MODEL, ROS rational_polynomial).
struct OpenCv8 {
  static constexpr const char* kName = "opencv8";
  static constexpr int kNumParams = 12;  // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6
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
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J);
};

// Kannala-Brandt equidistant fisheye (OpenCV fisheye, Kalibr pinhole-equi).
struct Kb4 {
  static constexpr const char* kName = "kb4";
  static constexpr int kNumParams = 8;  // fx fy cx cy k1 k2 k3 k4
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
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J);
};

// Double sphere (Usenko, Demmel, Cremers 2018); fields of view beyond 180 degrees.
struct DoubleSphere {
  static constexpr const char* kName = "ds";
  static constexpr int kNumParams = 6;  // fx fy cx cy xi alpha
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
  static bool ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J);
};

// ProjectWithJacobian: the projection's pixel and its Jacobian J (2 rows of
// kNumParams + 3: over the lens parameters, then the camera point), in closed
// form, which autodiff Jets over up to 15 derivatives (through atan2 and sqrt
// for the fisheyes) cost up to twice as much per iteration.  The pixel is
// Project's, bit for bit; the residuals' tests (tests/lens_models.rs,
// tests/engine.rs) check every model's Jacobian against the single-piece
// autodiff reference.

// The OpenCV family's ProjectWithJacobian.  kTangential and
// kRational select p1 p2 (at 6, 7; k3 then at 8) and k4 k5 k6 (at 9, 10, 11);
// without p1 p2, k3 is at 6.  The pixel itself is Lens::Project's, bit for bit.
template <class Lens, bool kTangential, bool kRational>
bool OpenCvProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
  constexpr int n = Lens::kNumParams + 3;
  Lens::Project(p, xc, uv);
  const double iz = 1.0 / xc[2];
  const double xn = xc[0] * iz, yn = xc[1] * iz;
  const double r2 = xn * xn + yn * yn, r4 = r2 * r2, r6 = r4 * r2;
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
  // The radial coefficients: d d / d k = r2^i / den (numerator), -d r2^i / den.
  const double powers[3] = {r2, r4, r6};
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

inline bool Radial3::ProjectWithJacobian(const double* p, const double* xc, double* uv,
                                         double* J) {
  return OpenCvProjectWithJacobian<Radial3, false, false>(p, xc, uv, J);
}
inline bool OpenCv5::ProjectWithJacobian(const double* p, const double* xc, double* uv,
                                         double* J) {
  return OpenCvProjectWithJacobian<OpenCv5, true, false>(p, xc, uv, J);
}
inline bool OpenCv8::ProjectWithJacobian(const double* p, const double* xc, double* uv,
                                         double* J) {
  return OpenCvProjectWithJacobian<OpenCv8, true, true>(p, xc, uv, J);
}
// The start of a closed-form ProjectWithJacobian whose Jacobian is mostly zeros:
// the pixel (Lens::Project's, bit for bit) and J zeroed; returns the row of v
// (the row of u is J itself).
template <class Lens>
double* StartJacobian(const double* p, const double* xc, double* uv, double* J) {
  constexpr int n = Lens::kNumParams + 3;
  Lens::Project(p, xc, uv);
  std::fill(J, J + 2 * n, 0.0);
  return J + n;
}

// Kannala-Brandt's ProjectWithJacobian: theta = atan2(r, z), theta_d its
// polynomial, (xd, yd) = (x, y) theta_d / r.
inline bool Kb4::ProjectWithJacobian(const double* p, const double* xc, double* uv, double* J) {
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
  return true;
}

// Double sphere's ProjectWithJacobian: m = alpha d2 + (1 - alpha) zz, (u, v) = f (x, y) / m + c.
inline bool DoubleSphere::ProjectWithJacobian(const double* p, const double* xc, double* uv,
                                              double* J) {
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

// The lens registry: every model once.  DispatchLens calls f with a
// default-constructed model struct whose kName matches, or returns false.
template <class F>
bool DispatchLens(const std::string& name, F&& f) {
  bool found = false;
  auto try_one = [&](auto lens) {
    if (!found && name == decltype(lens)::kName) {
      found = true;
      f(lens);
    }
  };
  try_one(Radial3{});
  try_one(OpenCv5{});
  try_one(OpenCv8{});
  try_one(Kb4{});
  try_one(DoubleSphere{});
  return found;
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

// x_out = R x + t for a double pose, with R and dx_out/dω (both row-major 3x3);
// dx_out/dt is the identity.  Closed form, so the pose's derivatives cost one
// sincos instead of six-wide Jets: d(R x)/dω = -[R x]_× J_l(ω), with SO(3)'s left
// Jacobian J_l = I + b [ω]_× + c [ω]_×² and R = I + a [ω]_× + b [ω]_×².
inline void TransformPointWithJacobian(const double* pose, const double* x, double* x_out,
                                       double* R, double* d_omega) {
  double Jl[9];
  RotationWithLeftJacobian(pose, R, Jl);
  double y[3];
  for (int i = 0; i < 3; ++i) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
  // -[y]_× rows, times J_l.
  const double Ny[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      d_omega[3 * i + j] = Ny[3 * i] * Jl[j] + Ny[3 * i + 1] * Jl[3 + j] + Ny[3 * i + 2] * Jl[6 + j];
  for (int i = 0; i < 3; ++i) x_out[i] = y[i] + pose[3 + i];
}

}  // namespace deformcal
