// Board models: where corner i sits on the (possibly deformed) board of image j.
//
// Each model is one struct: its name (the method's, docs/conventions.md §2), how many
// parameters it adds per frame and per corner, the templated board point, and
// the gauge it must hold fixed.  The reprojection functor and the problem
// assembly are generic over these structs, so a new board model is one more
// struct here and one line in DispatchBoard; the Rust registry
// (src/model/board.rs) describes the same sizes and a test checks they agree.
#pragma once

#include <ceres/manifold.h>
#include <ceres/problem.h>

#include <cstdint>
#include <string>
#include <vector>

namespace deformcal {

// Size of the per-corner correction table rows; models use a prefix of it.
constexpr int kCorrectionStride = 3;
// Size of the per-image paraboloid (a, b, c).
constexpr int kParaboloidSize = 3;

// a x^2 + b y^2 + c x y on the nominal board coordinates (docs/conventions.md §2).
template <typename T>
inline T Paraboloid(const double* x, const T* abc) {
  return abc[0] * (x[0] * x[0]) + abc[1] * (x[1] * x[1]) + abc[2] * (x[0] * x[1]);
}

// A model's per-image parameters (kFrameExtra of them) ride in the same block as
// the image's pose, so the Schur solver eliminates them together with it; its
// per-corner correction (kCornerSize values, 0 for none) is a block of its own
// (or a slot in a block of a few corners, solver.cc).  GaugeHeld(k) lists the
// components of the k-th gauge corner's correction held at their value.

// Rigid, perfectly planar board.
struct StandardBoard {
  static constexpr const char* kName = "standard";
  static constexpr int kGaugeCorners = 0;
  static constexpr int kFrameExtra = 0;
  static constexpr int kCornerSize = 0;

  template <typename T>
  static void Point(const double* x, const T* /*frame_extra*/, const T* /*corner*/, T* out) {
    out[0] = T(x[0]);
    out[1] = T(x[1]);
    out[2] = T(x[2]);
  }
  static std::vector<int> GaugeHeld(size_t /*k*/) { return {}; }
};

// One 3D correction per corner for the whole dataset (Strobl & Hirzinger).
struct StaticBoard {
  static constexpr const char* kName = "static";
  static constexpr int kGaugeCorners = 3;
  static constexpr int kFrameExtra = 0;
  static constexpr int kCornerSize = 3;

  template <typename T>
  static void Point(const double* x, const T* /*frame_extra*/, const T* corner, T* out) {
    out[0] = x[0] + corner[0];
    out[1] = x[1] + corner[1];
    out[2] = x[2] + corner[2];
  }
  // 7 DOF: two corners fully, the z of a third; together they pin the pose and scale.
  static std::vector<int> GaugeHeld(size_t k) {
    if (k < 2) return {0, 1, 2};
    return {2};
  }
};

// A paraboloid out-of-plane bend per image (the paper's dynamic model).
struct DynamicBoard {
  static constexpr const char* kName = "dynamic";
  static constexpr int kGaugeCorners = 0;
  static constexpr int kFrameExtra = kParaboloidSize;
  static constexpr int kCornerSize = 0;

  template <typename T>
  static void Point(const double* x, const T* frame_extra, const T* /*corner*/, T* out) {
    out[0] = T(x[0]);
    out[1] = T(x[1]);
    out[2] = x[2] + Paraboloid(x, frame_extra);
  }
  static std::vector<int> GaugeHeld(size_t /*k*/) { return {}; }
};

// Static in-plane correction per corner plus the per-image paraboloid.
struct FullBoard {
  static constexpr const char* kName = "full";
  static constexpr int kGaugeCorners = 2;
  static constexpr int kFrameExtra = kParaboloidSize;
  static constexpr int kCornerSize = 2;

  template <typename T>
  static void Point(const double* x, const T* frame_extra, const T* corner, T* out) {
    out[0] = x[0] + corner[0];
    out[1] = x[1] + corner[1];
    out[2] = x[2] + Paraboloid(x, frame_extra);
  }
  // 4 DOF: in-plane translation, rotation and scale, pinned by two corners.
  static std::vector<int> GaugeHeld(size_t /*k*/) { return {0, 1}; }
};

// Richer bends (beyond the paper): Δz = Σ c_k x^m y^n over every monomial with
// 2 <= m + n <= Order (no constant or linear term: they would trade off against
// the pose).  The first three coefficients are the paraboloid's (x², y², x y) in
// its order, so an order-2 bend is exactly DynamicBoard's; then degree by degree,
// within a degree by falling power of x (x³, x²y, x y², y³, x⁴, ..., y⁴).
constexpr int BendTerms(int order) { return (order + 1) * (order + 2) / 2 - 3; }

template <int Order, typename T>
inline T PolynomialBend(const double* x, const T* c) {
  T z = Paraboloid(x, c);
  int k = kParaboloidSize;
  for (int degree = 3; degree <= Order; ++degree) {
    for (int m = degree; m >= 0; --m) {
      double monomial = 1.0;
      for (int i = 0; i < m; ++i) monomial *= x[0];
      for (int i = 0; i < degree - m; ++i) monomial *= x[1];
      z += c[k++] * monomial;
    }
  }
  return z;
}

// The per-image polynomial bend of order 3 or 4, with (kInPlane) or without the
// static in-plane correction of `full`: "dynamic3", "dynamic4", "full3", "full4".
template <int Order, bool kInPlane>
struct PolynomialBoard {
  static_assert(Order == 3 || Order == 4, "orders 3 and 4 (order 2 is dynamic / full)");
  static constexpr const char* kName =
      kInPlane ? (Order == 3 ? "full3" : "full4") : (Order == 3 ? "dynamic3" : "dynamic4");
  static constexpr int kGaugeCorners = kInPlane ? FullBoard::kGaugeCorners : 0;
  static constexpr int kFrameExtra = BendTerms(Order);
  static constexpr int kCornerSize = kInPlane ? FullBoard::kCornerSize : 0;

  template <typename T>
  static void Point(const double* x, const T* frame_extra, const T* corner, T* out) {
    out[0] = kInPlane ? x[0] + corner[0] : T(x[0]);
    out[1] = kInPlane ? x[1] + corner[1] : T(x[1]);
    out[2] = x[2] + PolynomialBend<Order>(x, frame_extra);
  }
  static std::vector<int> GaugeHeld(size_t k) {
    if (kInPlane) return FullBoard::GaugeHeld(k);
    return {};
  }
};

// The board-model registry: DispatchBoard calls f with the model whose kName
// matches, or returns false.
template <class F>
bool DispatchBoard(const std::string& name, F&& f) {
  bool found = false;
  auto try_one = [&](auto board) {
    if (!found && name == decltype(board)::kName) {
      found = true;
      f(board);
    }
  };
  try_one(StandardBoard{});
  try_one(StaticBoard{});
  try_one(DynamicBoard{});
  try_one(FullBoard{});
  try_one(PolynomialBoard<3, false>{});
  try_one(PolynomialBoard<4, false>{});
  try_one(PolynomialBoard<3, true>{});
  try_one(PolynomialBoard<4, true>{});
  return found;
}

}  // namespace deformcal
