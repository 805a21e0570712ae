// One residual block per view (camera, image) for board models without
// per-corner parameters: the chain rule of chained.h over all of a view's
// corners, with the Cauchy loss folded in (loss.h).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <memory>
#include <utility>
#include <vector>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"
#include "deformcal/cpp/residuals/chained.h"
#include "deformcal/cpp/residuals/loss.h"

namespace deformcal {

// ViewBlock hides the lens and board so that the assembly collects views of
// several lens models in one map.
class ViewBlock : public ceres::CostFunction {
 public:
  virtual void Add(double u, double v, double w, const double* x) = 0;
  // Fixes the block layout once every corner is added.
  virtual void Finish() = 0;
};

template <class Lens, class Board, bool kRig>
class ViewReprojection final : public ViewBlock {
 public:
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  ViewReprojection(CauchyFold loss, std::shared_ptr<const double> loss_scale_factor)
      : loss_(loss), loss_scale_factor_(std::move(loss_scale_factor)) {}

  void Add(double u, double v, double w, const double* x) override {
    obs_.push_back({u, v, w, {x[0], x[1], x[2]}});
  }
  void Finish() override {
    set_num_residuals(2 * static_cast<int>(obs_.size()));
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(Lens::kNumParams);
    if (kRig) sizes->push_back(kPoseSize);
    sizes->push_back(kFrameSize);
    if (Board::kCornerSize > 0) {
      for (size_t i = 0; i < obs_.size(); ++i) sizes->push_back(Board::kCornerSize);
    }
  }
  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const int fb = kRig ? 2 : 1;
    const double k = *loss_scale_factor_;
    View s(p[0], kRig ? p[1] : nullptr, p[fb], CauchyFold{loss_.a2 * k * k});
    RotationWithLeftJacobian(s.frame, s.R, s.Jl);
    if (kRig) RotationWithLeftJacobian(s.rig, s.Rk, s.Jlk);
    const size_t n = obs_.size();
    if (jacobians && Board::kCornerSize > 0) {
      for (size_t i = 0; i < n; ++i) {
        if (double* Jc = jacobians[fb + 1 + i]) {
          std::fill(Jc, Jc + 2 * n * Board::kCornerSize, 0.0);
        }
      }
    }
    for (size_t i = 0; i < n; ++i) {
      const double* corner = Board::kCornerSize > 0 ? p[fb + 1 + i] : nullptr;
      const Corner c(obs_[i], s, corner);
      if (jacobians == nullptr) {
        if (!Residual(obs_[i], s, c, r + 2 * i)) return false;
      } else if (!WithJacobian(i, s, c, r + 2 * i, jacobians)) {
        return false;
      }
    }
    return true;
  }

 private:
  using Point = BoardPointJacobian<Board>;
  struct Obs {
    double u, v, w;
    double x[3];
  };

  // What a view's corners share: its blocks, rotations and loss.
  struct View {
    View(const double* intrinsics_in, const double* rig_in, const double* frame_in, CauchyFold loss_in)
        : intrinsics(intrinsics_in), rig(rig_in), frame(frame_in), loss(loss_in) {}
    const double* intrinsics;
    const double* rig;
    const double* frame;
    CauchyFold loss;
    double R[9], Jl[9], Rk[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, Jlk[9];
  };

  // One corner's board point X (with dX), y = R X, camera 0's xc and camera k's cam.
  struct Corner {
    double X[3];
    double dX[3][Point::kCols] = {};
    double y[3], xc[3], cam[3];

    Corner(const Obs& o, const View& s, const double* corner) {
      Point::Eval(o.x, s.frame + kPoseSize, corner, X, dX);
      for (int a = 0; a < 3; ++a) {
        y[a] = s.R[3 * a] * X[0] + s.R[3 * a + 1] * X[1] + s.R[3 * a + 2] * X[2];
        xc[a] = y[a] + s.frame[3 + a];
      }
      for (int a = 0; a < 3; ++a) {
        cam[a] = kRig ? s.Rk[3 * a] * xc[0] + s.Rk[3 * a + 1] * xc[1] + s.Rk[3 * a + 2] * xc[2] +
                            s.rig[3 + a]
                      : xc[a];
      }
    }
  };

  // The folded residual alone.
  static bool Residual(const Obs& o, const View& s, const Corner& c, double* ri) {
    double uv[2];
    if (!Lens::Project(s.intrinsics, c.cam, uv)) return false;
    ri[0] = o.w * (o.u - uv[0]);
    ri[1] = o.w * (o.v - uv[1]);
    double f, mt, mr;
    s.loss.Scale(ri[0] * ri[0] + ri[1] * ri[1], &f, &mt, &mr);
    ri[0] *= f;
    ri[1] *= f;
    return true;
  }

  // Corner i's folded residual and its rows of every requested Jacobian.
  bool WithJacobian(size_t i, const View& s, const Corner& c, double* ri, double** jacobians) const {
    const Obs& o = obs_[i];
    constexpr int kLens = Lens::kNumParams;
    double uv[2], duv[2][kLens + 3];
    if (!Lens::ProjectWithJacobian(s.intrinsics, c.cam, uv, &duv[0][0])) return false;
    const double e[2] = {o.w * (o.u - uv[0]), o.w * (o.v - uv[1])};
    double f, M[2][2];
    s.loss.Fold(e, &f, M);
    ri[0] = f * e[0];
    ri[1] = f * e[1];
    // dr~/dintrinsics and dr~/dcam: -w M duv.
    double* Ji = jacobians[0];
    double dcam[2][3];
    for (int a = 0; a < 2; ++a) {
      for (int k = 0; k < kLens + 3; ++k) {
        const double d = -o.w * (M[a][0] * duv[0][k] + M[a][1] * duv[1][k]);
        if (k < kLens) {
          if (Ji) Ji[(2 * i + a) * kLens + k] = d;
        } else {
          dcam[a][k - kLens] = d;
        }
      }
    }
    // dr~/dxc = dcam Rk (identity without a rig).
    double dxc[2][3];
    for (int a = 0; a < 2; ++a)
      for (int k = 0; k < 3; ++k)
        dxc[a][k] = dcam[a][0] * s.Rk[k] + dcam[a][1] * s.Rk[3 + k] + dcam[a][2] * s.Rk[6 + k];
    if (kRig && jacobians[1] != nullptr) RigRows(i, s, c, dcam, jacobians[1]);
    // dr~/dX = dxc R.
    double dXr[2][3];
    for (int a = 0; a < 2; ++a)
      for (int m = 0; m < 3; ++m)
        dXr[a][m] = dxc[a][0] * s.R[m] + dxc[a][1] * s.R[3 + m] + dxc[a][2] * s.R[6 + m];
    const int fb = kRig ? 2 : 1;
    if (jacobians[fb] != nullptr) FrameRows(i, s, c, dxc, dXr, jacobians[fb]);
    if (Board::kCornerSize > 0 && jacobians[fb + 1 + i] != nullptr) {
      CornerRows(i, c, dXr, jacobians[fb + 1 + i]);
    }
    return true;
  }

  // dcam/dw_k = -[Rk xc]_x Jlk, dcam/dt_k = I.
  static void RigRows(size_t i, const View& s, const Corner& c, const double (&dcam)[2][3],
                      double* Jr) {
    double yk[3];
    for (int a = 0; a < 3; ++a) yk[a] = c.cam[a] - s.rig[3 + a];
    double Dk[9];
    SkewTimes(yk, s.Jlk, Dk);
    for (int a = 0; a < 2; ++a) {
      double* row = Jr + (2 * i + a) * kPoseSize;
      for (int k = 0; k < 3; ++k) {
        row[k] = dcam[a][0] * Dk[k] + dcam[a][1] * Dk[3 + k] + dcam[a][2] * Dk[6 + k];
        row[3 + k] = dcam[a][k];
      }
    }
  }

  static void FrameRows(size_t i, const View& s, const Corner& c, const double (&dxc)[2][3],
                        const double (&dXr)[2][3], double* Jf) {
    double D[9];
    SkewTimes(c.y, s.Jl, D);  // dxc/dw = -[y]_x Jl
    for (int a = 0; a < 2; ++a) {
      double* row = Jf + (2 * i + a) * kFrameSize;
      for (int k = 0; k < 3; ++k) {
        row[k] = dxc[a][0] * D[k] + dxc[a][1] * D[3 + k] + dxc[a][2] * D[6 + k];
        row[3 + k] = dxc[a][k];
      }
      for (int m = 0; m < Board::kFrameExtra; ++m)
        row[kPoseSize + m] = dXr[a][0] * c.dX[0][m] + dXr[a][1] * c.dX[1][m] + dXr[a][2] * c.dX[2][m];
    }
  }

  static void CornerRows(size_t i, const Corner& c, const double (&dXr)[2][3], double* Jc) {
    for (int a = 0; a < 2; ++a)
      for (int k = 0; k < Board::kCornerSize; ++k) {
        const int m = Board::kFrameExtra + k;
        Jc[(2 * i + a) * Board::kCornerSize + k] =
            dXr[a][0] * c.dX[0][m] + dXr[a][1] * c.dX[1][m] + dXr[a][2] * c.dX[2][m];
      }
  }

  // D = -[y]_x J.
  static void SkewTimes(const double* y, const double* J, double* D) {
    const double S[9] = {0, y[2], -y[1], -y[2], 0, y[0], y[1], -y[0], 0};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        D[3 * a + b] = S[3 * a] * J[b] + S[3 * a + 1] * J[3 + b] + S[3 * a + 2] * J[6 + b];
  }

  CauchyFold loss_;
  std::shared_ptr<const double> loss_scale_factor_;
  std::vector<Obs> obs_;
};

}  // namespace deformcal
