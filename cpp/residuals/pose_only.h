// Residuals of a view whose board pose alone is free (a test-error refit).
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <vector>

#include "deformcal/cpp/camera.h"

namespace deformcal {
// Residuals of the corners of one view when only the board pose is free (a
// test-error refit): board points, intrinsics and rig pose are constants, the
// rotation is applied once per view, and the Jets carry 6 derivatives.  Without
// a robust loss one block holds a whole view; with one, a single corner.
// PoseOnlyView hides the lens so that views of several lens models share a map.
class PoseOnlyView {
 public:
  virtual ~PoseOnlyView() = default;
  virtual void Add(double u, double v, double w, const double* board_point) = 0;
  // Hands the functor to a new cost function, which owns it.
  virtual ceres::CostFunction* Release() = 0;
};

template <class Lens>
class ViewPoseError {
 public:
  ViewPoseError(const double* intrinsics, const double* rig) : has_rig_(rig != nullptr) {
    std::copy(intrinsics, intrinsics + Lens::kNumParams, intrinsics_);
    if (rig) std::copy(rig, rig + kPoseSize, rig_);
  }

  void Add(double u, double v, double w, const double* board_point) {
    uv_.push_back(u);
    uv_.push_back(v);
    w_.push_back(w);
    points_.insert(points_.end(), board_point, board_point + 3);
  }
  int NumResiduals() const { return static_cast<int>(uv_.size()); }

  template <typename T>
  bool operator()(const T* const pose, T* r) const {
    T rotation[9];
    ceres::AngleAxisToRotationMatrix(pose, ceres::RowMajorAdapter3x3(rotation));
    T intrinsics[Lens::kNumParams];
    for (int i = 0; i < Lens::kNumParams; ++i) intrinsics[i] = T(intrinsics_[i]);
    for (size_t k = 0; k < uv_.size() / 2; ++k) {
      const double* x = &points_[3 * k];
      T xc[3];
      for (int i = 0; i < 3; ++i) {
        xc[i] = rotation[3 * i] * x[0] + rotation[3 * i + 1] * x[1] + rotation[3 * i + 2] * x[2] +
                pose[3 + i];
      }
      if (has_rig_) {
        T rig[kPoseSize], xk[3];
        for (int i = 0; i < kPoseSize; ++i) rig[i] = T(rig_[i]);
        TransformPoint(rig, xc, xk);
        std::copy(xk, xk + 3, xc);
      }
      T uv[2];
      if (!Lens::Project(intrinsics, xc, uv)) return false;
      r[2 * k] = w_[k] * (T(uv_[2 * k]) - uv[0]);
      r[2 * k + 1] = w_[k] * (T(uv_[2 * k + 1]) - uv[1]);
    }
    return true;
  }

 private:
  bool has_rig_;
  double intrinsics_[Lens::kNumParams];
  double rig_[kPoseSize] = {};
  std::vector<double> uv_, w_, points_;
};

template <class Lens>
class PoseOnlyViewOf final : public PoseOnlyView {
 public:
  PoseOnlyViewOf(const double* intrinsics, const double* rig)
      : f_(new ViewPoseError<Lens>(intrinsics, rig)) {}
  ~PoseOnlyViewOf() override { delete f_; }
  void Add(double u, double v, double w, const double* board_point) override {
    f_->Add(u, v, w, board_point);
  }
  ceres::CostFunction* Release() override {
    const int n = f_->NumResiduals();
    auto* cost =
        new ceres::AutoDiffCostFunction<ViewPoseError<Lens>, ceres::DYNAMIC, kPoseSize>(f_, n);
    f_ = nullptr;
    return cost;
  }

 private:
  ViewPoseError<Lens>* f_;
};

}  // namespace deformcal
