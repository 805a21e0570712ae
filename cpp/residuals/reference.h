// The reference residual: observed minus projected pixel of one board corner,
// differentiated by Ceres' autodiff in one piece (the style of Ceres' snavely
// example).  The chained and view residuals are tested against it.
#pragma once

#include <ceres/ceres.h>

#include <type_traits>
#include <utility>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"

namespace deformcal {
template <class A, class B>
struct Concat;
template <int... A, int... B>
struct Concat<std::integer_sequence<int, A...>, std::integer_sequence<int, B...>> {
  using type = std::integer_sequence<int, A..., B...>;
};

// Residual of one observed corner, differentiated in one autodiff piece: the
// reference the chained Jacobian below is tested against.  Blocks: intrinsics,
// [camera-k-from-camera-0 if kRig], the frame's block (camera-0-from-board pose
// followed by the board model's per-frame parameters), then the corner's
// correction if the board model has one.
template <class Lens, class Board, bool kRig>
class ReprojectionError {
 public:
  ReprojectionError(double u, double v, double w, const double* x)
      : u_(u), v_(v), w_(w), x_{x[0], x[1], x[2]} {}

  template <typename T>
  bool operator()(const T* const p0, const T* const p1, T* r) const {
    const T* const p[] = {p0, p1};
    return Evaluate(p, r);
  }
  template <typename T>
  bool operator()(const T* const p0, const T* const p1, const T* const p2, T* r) const {
    const T* const p[] = {p0, p1, p2};
    return Evaluate(p, r);
  }
  template <typename T>
  bool operator()(const T* const p0, const T* const p1, const T* const p2, const T* const p3,
                  T* r) const {
    const T* const p[] = {p0, p1, p2, p3};
    return Evaluate(p, r);
  }

  // w scales the residual: 1 for a full-resolution detection, 0.5^level for a
  // corner found on a decimated image.
  static ceres::CostFunction* Create(double u, double v, double w, const double* x) {
    return Make(new ReprojectionError(u, v, w, x), BlockSizes{});
  }

 private:
  static constexpr int kFrame = kRig ? 2 : 1;
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  using LeadingSizes =
      std::conditional_t<kRig, std::integer_sequence<int, Lens::kNumParams, kPoseSize, kFrameSize>,
                         std::integer_sequence<int, Lens::kNumParams, kFrameSize>>;
  using BlockSizes = std::conditional_t<
      Board::kCornerSize == 0, LeadingSizes,
      typename Concat<LeadingSizes, std::integer_sequence<int, Board::kCornerSize>>::type>;

  template <int... Ns>
  static ceres::CostFunction* Make(ReprojectionError* f, std::integer_sequence<int, Ns...>) {
    return new ceres::AutoDiffCostFunction<ReprojectionError, 2, Ns...>(f);
  }

  template <typename T>
  bool Evaluate(const T* const* p, T* r) const {
    const T* frame = p[kFrame];
    const T* corner = Board::kCornerSize > 0 ? p[kFrame + 1] : nullptr;
    T board[3];
    Board::Point(x_, frame + kPoseSize, corner, board);
    T xc[3];
    TransformPoint(frame, board, xc);
    if constexpr (kRig) {
      T xk[3];
      TransformPoint(p[1], xc, xk);
      xc[0] = xk[0];
      xc[1] = xk[1];
      xc[2] = xk[2];
    }
    T uv[2];
    if (!Lens::Project(p[0], xc, uv)) return false;
    r[0] = w_ * (T(u_) - uv[0]);
    r[1] = w_ * (T(v_) - uv[1]);
    return true;
  }

  double u_, v_, w_;
  double x_[3];
};

}  // namespace deformcal
