// What every lens model header shares: the stride of intrinsics tables and the
// start of a closed-form ProjectWithJacobian.  A lens model is one struct
// (docs/conventions.md §1) with
//   kName                  its config name (the Rust registry's, src/model/lens/),
//   kNumParams             its parameter count, fx fy cx cy first,
//   kPerCornerWithoutPrior whether its problems keep one block per corner unless
//                          the lens prior holds it (solver/assemble.h, PreviousPath),
//   Project<T>             camera-frame point to pixel, templated for Ceres' Jets,
//   ProjectWithJacobian    the pixel (Project's, bit for bit) and its Jacobian J:
//                          2 rows of kNumParams + 3, over the lens parameters,
//                          then the camera point, in closed form.
// Project returns false where the model has no valid image of the point.
// registry.h lists every model and checks that each has these pieces.
#pragma once

#include <algorithm>

namespace deformcal {

// The largest lens model's parameter count: the stride of intrinsics tables.
constexpr int kMaxLensParams = 12;

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

}  // namespace deformcal
