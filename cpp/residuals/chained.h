// The reprojection residual of one corner with its Jacobian by the chain rule
// (ChainedReprojection), and the pieces of that chain the view blocks share.
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <stdexcept>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"

namespace deformcal {

// The board point X of a corner and dX/d(frame extra, corner): Jets over the
// board model's own parameters only.
template <class Board>
struct BoardPointJacobian {
  static constexpr int kModel = Board::kFrameExtra + Board::kCornerSize;
  static constexpr int kCols = kModel > 0 ? kModel : 1;

  static void Eval(const double* x, const double* extra_in, const double* corner_in, double* X,
                   double (*dX)[kCols]) {
    if constexpr (kModel > 0) {
      using JM = ceres::Jet<double, kModel>;
      JM extra[Board::kFrameExtra > 0 ? Board::kFrameExtra : 1];
      JM corr[Board::kCornerSize > 0 ? Board::kCornerSize : 1];
      for (int e = 0; e < Board::kFrameExtra; ++e) extra[e] = JM(extra_in[e], e);
      for (int c = 0; c < Board::kCornerSize; ++c) corr[c] = JM(corner_in[c], Board::kFrameExtra + c);
      JM out[3];
      Board::Point(x, extra, corr, out);
      for (int i = 0; i < 3; ++i) {
        X[i] = out[i].a;
        for (int k = 0; k < kModel; ++k) dX[i][k] = out[i].v[k];
      }
    } else {
      Board::Point(x, static_cast<const double*>(nullptr), static_cast<const double*>(nullptr), X);
    }
  }
};

// The camera point of a board point X through the frame's pose and, with a
// rig, camera k's: cam = R_k (R X + t) + t_k, and its derivatives.
struct RigidChain {
  double xc[3], R[9], dxc_dw[9];                   // camera 0's point, R, d xc / d w
  double cam[3];                                   // camera k's point
  double dcam_dxc[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // R_k
  double dcam_drig[3][kPoseSize] = {};

  // `rotation`: the frame's shared R and J_l (FrameRotation), or null.
  RigidChain(const double* frame, const double* rig, const double* X, FrameRotation* rotation) {
    if (rotation != nullptr) {
      rotation->At(frame);
      std::copy(rotation->R, rotation->R + 9, R);
      TransformWithRotation(frame, rotation->R, rotation->Jl, X, xc, dxc_dw);
    } else {
      TransformPointWithJacobian(frame, X, xc, R, dxc_dw);
    }
    std::copy(xc, xc + 3, cam);
    if (rig != nullptr) {
      double dk_dw[9];
      TransformPointWithJacobian(rig, xc, cam, dcam_dxc, dk_dw);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) dcam_drig[i][j] = dk_dw[3 * i + j];
        dcam_drig[i][3 + i] = 1.0;
      }
    }
  }
};

// Residual of one observed corner with its Jacobian assembled by the chain rule
// from three pieces: the board point (BoardPointJacobian), the rigid transform
// (closed form; d/dX is the rotation matrix), and the projection (closed form
// over intrinsics and the camera point, Lens::ProjectWithJacobian).  The Jets
// carry at most the board model's few derivatives instead of up to 21, which
// makes the Jacobian several times cheaper; ReprojectionError (reference.h)
// stays as the reference it is tested against.  Blocks as ReprojectionError's.
template <class Lens, class Board, bool kRig>
class ChainedReprojection final : public ceres::CostFunction {
 public:
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  using Point = BoardPointJacobian<Board>;

  ChainedReprojection(double u, double v, double w, const double* x)
      : u_(u), v_(v), w_(w), x_{x[0], x[1], x[2]} {
    set_num_residuals(2);
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(Lens::kNumParams);
    if (kRig) sizes->push_back(kPoseSize);
    sizes->push_back(kFrameSize);
    if (Board::kCornerSize > 0) sizes->push_back(Board::kCornerSize);
  }

  // Reads the corner's correction from `offset` values into a block of `width`
  // holding a group of corners' corrections (InCornerGroup's job, done here to
  // spare a wrapper per observation: 200 MB at 10 000 images).
  void PlaceCorner(int offset, int width) {
    if (Board::kCornerSize == 0 || offset < 0 || offset + Board::kCornerSize > width) {
      throw std::invalid_argument("ChainedReprojection: the corner's slot lies outside its block");
    }
    corner_offset_ = offset;
    mutable_parameter_block_sizes()->back() = width;
  }

  // Shares the frame's rotation with its other corners' blocks (FrameRotation;
  // single-threaded solves only: the blocks write it as they evaluate).
  void ShareRotation(FrameRotation* rotation) { rotation_ = rotation; }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const double* intrinsics = p[0];
    const double* rig = kRig ? p[1] : nullptr;
    const double* frame = p[kRig ? 2 : 1];
    const double* corner = Board::kCornerSize > 0 ? p[kRig ? 3 : 2] + corner_offset_ : nullptr;
    double X[3];
    if (jacobians == nullptr) {
      // The board point without its derivatives (the same value as Point's).
      Board::Point(x_, frame + kPoseSize, corner, X);
      return Residual(intrinsics, rig, frame, X, r);
    }
    double dX[3][Point::kCols] = {};
    Point::Eval(x_, frame + kPoseSize, corner, X, dX);

    const RigidChain c(frame, rig, X, rotation_);
    constexpr int kLens = Lens::kNumParams;
    double uv[2], duv[2][kLens + 3];
    if (!Lens::ProjectWithJacobian(intrinsics, c.cam, uv, &duv[0][0])) return false;
    r[0] = w_ * (u_ - uv[0]);
    r[1] = w_ * (v_ - uv[1]);
    // dr/dcam (2x3) and dr/dxc = dr/dcam * dcam/dxc.
    double dr_dcam[2][3], dr_dxc[2][3];
    for (int k = 0; k < 2; ++k) {
      for (int i = 0; i < 3; ++i) dr_dcam[k][i] = -w_ * duv[k][kLens + i];
      for (int i = 0; i < 3; ++i) {
        dr_dxc[k][i] = dr_dcam[k][0] * c.dcam_dxc[i] + dr_dcam[k][1] * c.dcam_dxc[3 + i] +
                       dr_dcam[k][2] * c.dcam_dxc[6 + i];
      }
    }
    if (double* J = jacobians[0]) {
      for (int k = 0; k < 2; ++k)
        for (int i = 0; i < kLens; ++i) J[k * kLens + i] = -w_ * duv[k][i];
    }
    if (kRig && jacobians[1] != nullptr) RigJacobian(dr_dcam, c, jacobians[1]);
    // dr/dX = dr/dxc * R, used for the model's parameters.
    double dr_dX[2][3];
    for (int k = 0; k < 2; ++k)
      for (int m = 0; m < 3; ++m)
        dr_dX[k][m] = dr_dxc[k][0] * c.R[m] + dr_dxc[k][1] * c.R[3 + m] + dr_dxc[k][2] * c.R[6 + m];
    const int b = kRig ? 2 : 1;
    if (jacobians[b] != nullptr) FrameJacobian(dr_dxc, dr_dX, c, dX, jacobians[b]);
    if (Board::kCornerSize > 0 && jacobians[b + 1] != nullptr) {
      CornerJacobian(dr_dX, dX, parameter_block_sizes()[b + 1], jacobians[b + 1]);
    }
    return true;
  }

 private:
  // The residual alone, through the templated transform and projection.
  bool Residual(const double* intrinsics, const double* rig, const double* frame, const double* X,
                double* r) const {
    double xc[3], uv[2];
    if (rotation_ != nullptr) {
      rotation_->At(frame);
      const double* R = rotation_->R;
      for (int i = 0; i < 3; ++i) xc[i] = R[3 * i] * X[0] + R[3 * i + 1] * X[1] + R[3 * i + 2] * X[2] + frame[3 + i];
    } else {
      TransformPoint(frame, X, xc);
    }
    if (kRig) {
      double xk[3];
      TransformPoint(rig, xc, xk);
      std::copy(xk, xk + 3, xc);
    }
    if (!Lens::Project(intrinsics, xc, uv)) return false;
    r[0] = w_ * (u_ - uv[0]);
    r[1] = w_ * (v_ - uv[1]);
    return true;
  }

  static void RigJacobian(const double (&dr_dcam)[2][3], const RigidChain& c, double* J) {
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < kPoseSize; ++j)
        J[k * kPoseSize + j] = dr_dcam[k][0] * c.dcam_drig[0][j] + dr_dcam[k][1] * c.dcam_drig[1][j] +
                               dr_dcam[k][2] * c.dcam_drig[2][j];
  }

  static void FrameJacobian(const double (&dr_dxc)[2][3], const double (&dr_dX)[2][3],
                            const RigidChain& c, const double (&dX)[3][Point::kCols], double* J) {
    for (int k = 0; k < 2; ++k) {
      for (int j = 0; j < 3; ++j) {
        J[k * kFrameSize + j] = dr_dxc[k][0] * c.dxc_dw[j] + dr_dxc[k][1] * c.dxc_dw[3 + j] +
                                dr_dxc[k][2] * c.dxc_dw[6 + j];
        J[k * kFrameSize + 3 + j] = dr_dxc[k][j];
      }
      for (int e = 0; e < Board::kFrameExtra; ++e) {
        J[k * kFrameSize + kPoseSize + e] =
            dr_dX[k][0] * dX[0][e] + dr_dX[k][1] * dX[1][e] + dr_dX[k][2] * dX[2][e];
      }
    }
  }

  // The corner's columns at its slot in a block of `width` (zero elsewhere).
  void CornerJacobian(const double (&dr_dX)[2][3], const double (&dX)[3][Point::kCols], int width,
                      double* J) const {
    if (width != Board::kCornerSize) std::fill(J, J + 2 * width, 0.0);
    for (int k = 0; k < 2; ++k)
      for (int c = 0; c < Board::kCornerSize; ++c) {
        const int m = Board::kFrameExtra + c;
        J[k * width + corner_offset_ + c] =
            dr_dX[k][0] * dX[0][m] + dr_dX[k][1] * dX[1][m] + dr_dX[k][2] * dX[2][m];
      }
  }

  double u_, v_, w_;
  double x_[3];
  int corner_offset_ = 0;
  FrameRotation* rotation_ = nullptr;
};
}  // namespace deformcal
