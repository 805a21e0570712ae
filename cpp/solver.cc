// Ceres problem assembly and solving for all board models and camera rigs.
#include "deformcal/cpp/bridge.h"

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <chrono>
#include <cstdio>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "deformcal/cpp/board.h"
#include "deformcal/cpp/camera.h"
#include "deformcal/src/solver/bridge.rs.h"

namespace deformcal {
namespace {

template <class A, class B>
struct Concat;
template <int... A, int... B>
struct Concat<std::integer_sequence<int, A...>, std::integer_sequence<int, B...>> {
  using type = std::integer_sequence<int, A..., B...>;
};

// Residual of one observed corner.  Blocks: intrinsics, [camera-k-from-camera-0
// if kRig], the image's block (camera-0-from-board pose followed by the model's
// per-image parameters), then the corner's correction if the model has one.
template <class Board, bool kRig>
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
      std::conditional_t<kRig, std::integer_sequence<int, kIntrinsicsSize, kPoseSize, kFrameSize>,
                         std::integer_sequence<int, kIntrinsicsSize, kFrameSize>>;
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
    ProjectRadial3(p[0], xc, uv);
    r[0] = w_ * (T(u_) - uv[0]);
    r[1] = w_ * (T(v_) - uv[1]);
    return true;
  }

  double u_, v_, w_;
  double x_[3];
};

// The same residual with its Jacobian assembled by the chain rule from three
// pieces: the board point (Jets over the model's own parameters), the rigid
// transform (closed form; d/dX is the rotation matrix), and the projection (Jets
// over intrinsics and the camera point).  The Jets carry 3 to 10 derivatives
// instead of up to 21, which makes the Jacobian several times cheaper;
// ReprojectionError stays as the reference it is tested against.
template <class Board, bool kRig>
class ChainedReprojection final : public ceres::CostFunction {
 public:
  static constexpr int kFrameSize = kPoseSize + Board::kFrameExtra;
  static constexpr int kModel = Board::kFrameExtra + Board::kCornerSize;

  ChainedReprojection(double u, double v, double w, const double* x)
      : u_(u), v_(v), w_(w), x_{x[0], x[1], x[2]} {
    set_num_residuals(2);
    auto* sizes = mutable_parameter_block_sizes();
    sizes->push_back(kIntrinsicsSize);
    if (kRig) sizes->push_back(kPoseSize);
    sizes->push_back(kFrameSize);
    if (Board::kCornerSize > 0) sizes->push_back(Board::kCornerSize);
  }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    const double* intrinsics = p[0];
    const double* rig = kRig ? p[1] : nullptr;
    const double* frame = p[kRig ? 2 : 1];
    const double* corner = Board::kCornerSize > 0 ? p[kRig ? 3 : 2] : nullptr;

    // Board point X and dX/d(frame extra, corner).
    double X[3];
    double dX[3][kModel > 0 ? kModel : 1] = {};
    if constexpr (kModel > 0) {
      using JM = ceres::Jet<double, kModel>;
      JM extra[Board::kFrameExtra > 0 ? Board::kFrameExtra : 1];
      JM corr[Board::kCornerSize > 0 ? Board::kCornerSize : 1];
      for (int e = 0; e < Board::kFrameExtra; ++e) extra[e] = JM(frame[kPoseSize + e], e);
      for (int c = 0; c < Board::kCornerSize; ++c) corr[c] = JM(corner[c], Board::kFrameExtra + c);
      JM out[3];
      Board::Point(x_, extra, corr, out);
      for (int i = 0; i < 3; ++i) {
        X[i] = out[i].a;
        for (int k = 0; k < kModel; ++k) dX[i][k] = out[i].v[k];
      }
    } else {
      Board::Point(x_, static_cast<const double*>(nullptr), static_cast<const double*>(nullptr), X);
    }

    if (jacobians == nullptr) {
      double xc[3], uv[2];
      TransformPoint(frame, X, xc);
      if (kRig) {
        double xk[3];
        TransformPoint(rig, xc, xk);
        std::copy(xk, xk + 3, xc);
      }
      ProjectRadial3(intrinsics, xc, uv);
      r[0] = w_ * (u_ - uv[0]);
      r[1] = w_ * (v_ - uv[1]);
      return true;
    }

    // xc = R X + t, its pose derivatives in closed form; dxc/dX = R.
    double xc[3], R[9], dxc_dw[9];
    TransformPointWithJacobian(frame, X, xc, R, dxc_dw);

    // Rig: xk = R_k xc + t_k; dxk/dxc = R_k.
    double cam[3] = {xc[0], xc[1], xc[2]};
    double dcam_dxc[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    double dcam_drig[3][kPoseSize] = {};
    if (kRig) {
      double dk_dw[9];
      TransformPointWithJacobian(rig, xc, cam, dcam_dxc, dk_dw);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) dcam_drig[i][j] = dk_dw[3 * i + j];
        dcam_drig[i][3 + i] = 1.0;
      }
    }

    // Projection: Jets over intrinsics and the camera point.
    using JP = ceres::Jet<double, kIntrinsicsSize + 3>;
    JP ij[kIntrinsicsSize], pc[3], uv[2];
    for (int i = 0; i < kIntrinsicsSize; ++i) ij[i] = JP(intrinsics[i], i);
    for (int i = 0; i < 3; ++i) pc[i] = JP(cam[i], kIntrinsicsSize + i);
    ProjectRadial3(ij, pc, uv);
    r[0] = w_ * (u_ - uv[0].a);
    r[1] = w_ * (v_ - uv[1].a);

    // dr/dcam (2x3) and dr/dxc = dr/dcam * dcam/dxc.
    double dr_dcam[2][3], dr_dxc[2][3];
    for (int k = 0; k < 2; ++k) {
      for (int c = 0; c < 3; ++c) dr_dcam[k][c] = -w_ * uv[k].v[kIntrinsicsSize + c];
      for (int c = 0; c < 3; ++c) {
        dr_dxc[k][c] = dr_dcam[k][0] * dcam_dxc[c] + dr_dcam[k][1] * dcam_dxc[3 + c] +
                       dr_dcam[k][2] * dcam_dxc[6 + c];
      }
    }
    int b = 0;
    if (double* J = jacobians[b++]) {
      for (int k = 0; k < 2; ++k)
        for (int i = 0; i < kIntrinsicsSize; ++i) J[k * kIntrinsicsSize + i] = -w_ * uv[k].v[i];
    }
    if (kRig) {
      if (double* J = jacobians[b]) {
        for (int k = 0; k < 2; ++k)
          for (int j = 0; j < kPoseSize; ++j)
            J[k * kPoseSize + j] = dr_dcam[k][0] * dcam_drig[0][j] + dr_dcam[k][1] * dcam_drig[1][j] +
                                   dr_dcam[k][2] * dcam_drig[2][j];
      }
      ++b;
    }
    // dr/dX = dr/dxc * R, used for the model's parameters.
    double dr_dX[2][3];
    for (int k = 0; k < 2; ++k)
      for (int m = 0; m < 3; ++m)
        dr_dX[k][m] = dr_dxc[k][0] * R[m] + dr_dxc[k][1] * R[3 + m] + dr_dxc[k][2] * R[6 + m];
    if (double* J = jacobians[b]) {
      for (int k = 0; k < 2; ++k) {
        for (int j = 0; j < 3; ++j) {
          J[k * kFrameSize + j] = dr_dxc[k][0] * dxc_dw[j] + dr_dxc[k][1] * dxc_dw[3 + j] +
                                  dr_dxc[k][2] * dxc_dw[6 + j];
          J[k * kFrameSize + 3 + j] = dr_dxc[k][j];
        }
        for (int e = 0; e < Board::kFrameExtra; ++e) {
          J[k * kFrameSize + kPoseSize + e] =
              dr_dX[k][0] * dX[0][e] + dr_dX[k][1] * dX[1][e] + dr_dX[k][2] * dX[2][e];
        }
      }
    }
    ++b;
    if (Board::kCornerSize > 0) {
      if (double* J = jacobians[b]) {
        for (int k = 0; k < 2; ++k)
          for (int c = 0; c < Board::kCornerSize; ++c) {
            const int m = Board::kFrameExtra + c;
            J[k * Board::kCornerSize + c] =
                dr_dX[k][0] * dX[0][m] + dr_dX[k][1] * dX[1][m] + dr_dX[k][2] * dX[2][m];
          }
      }
    }
    return true;
  }

 private:
  double u_, v_, w_;
  double x_[3];
};

// Residuals of the corners of one view when only the board pose is free (a
// test-error refit): board points, intrinsics and rig pose are constants, the
// rotation is applied once per view, and the Jets carry 6 derivatives.  Without
// a robust loss one block holds a whole view; with one, a single corner.
class ViewPoseError {
 public:
  ViewPoseError(const double* intrinsics, const double* rig) : has_rig_(rig != nullptr) {
    std::copy(intrinsics, intrinsics + kIntrinsicsSize, intrinsics_);
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
    T intrinsics[kIntrinsicsSize];
    for (int i = 0; i < kIntrinsicsSize; ++i) intrinsics[i] = T(intrinsics_[i]);
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
      ProjectRadial3(intrinsics, xc, uv);
      r[2 * k] = w_[k] * (T(uv_[2 * k]) - uv[0]);
      r[2 * k + 1] = w_[k] * (T(uv_[2 * k + 1]) - uv[1]);
    }
    return true;
  }

  static ceres::CostFunction* Create(ViewPoseError* f) {
    const int n = f->NumResiduals();
    return new ceres::AutoDiffCostFunction<ViewPoseError, ceres::DYNAMIC, kPoseSize>(f, n);
  }

 private:
  bool has_rig_;
  double intrinsics_[kIntrinsicsSize];
  double rig_[kPoseSize] = {};
  std::vector<double> uv_, w_, points_;
};

// A view of one parameter table inside Params' storage.
struct Table {
  double* ptr = nullptr;
  size_t n = 0;
  double& operator[](size_t i) { return ptr[i]; }
  double* data() { return ptr; }
  double* begin() { return ptr; }
  double* end() { return ptr + n; }
};

// Working copies of the parameter tables, in one allocation.  Ceres orders the
// blocks of an elimination group by address; one buffer in a fixed table order
// makes that order, and so the floating-point result, the same in every run.
// Each image's pose and the model's per-image parameters sit side by side.
struct Params {
  std::vector<double> storage;
  Table intrinsics, camera_poses, frames, corrections;
  int frame_stride;

  Params(const ffi::ProblemData& d, int frame_extra) : frame_stride(kPoseSize + frame_extra) {
    const size_t num_frames = d.frame_poses.size() / kPoseSize;
    storage.reserve(d.intrinsics.size() + d.camera_poses.size() + num_frames * frame_stride +
                    d.corrections.size());
    storage.insert(storage.end(), d.intrinsics.begin(), d.intrinsics.end());
    storage.insert(storage.end(), d.camera_poses.begin(), d.camera_poses.end());
    for (size_t j = 0; j < num_frames; ++j) {
      storage.insert(storage.end(), d.frame_poses.begin() + kPoseSize * j,
                     d.frame_poses.begin() + kPoseSize * (j + 1));
      for (int e = 0; e < frame_extra; ++e) {
        const size_t i = kParaboloidSize * j + e;
        storage.push_back(i < d.deformations.size() ? d.deformations[i] : 0.0);
      }
    }
    storage.insert(storage.end(), d.corrections.begin(), d.corrections.end());
    size_t offset = 0;
    for (auto [table, n] : {std::pair{&intrinsics, d.intrinsics.size()},
                            std::pair{&camera_poses, d.camera_poses.size()},
                            std::pair{&frames, num_frames * frame_stride},
                            std::pair{&corrections, d.corrections.size()}}) {
      table->ptr = storage.data() + offset;
      table->n = n;
      offset += n;
    }
  }
  Params(const Params&) = delete;
  Params& operator=(const Params&) = delete;

  double* Frame(size_t j) { return frames.data() + frame_stride * j; }

  void CopyTo(ffi::ProblemData& d) {
    std::copy(intrinsics.begin(), intrinsics.end(), d.intrinsics.begin());
    std::copy(camera_poses.begin(), camera_poses.end(), d.camera_poses.begin());
    const size_t num_frames = d.frame_poses.size() / kPoseSize;
    for (size_t j = 0; j < num_frames; ++j) {
      const double* f = Frame(j);
      std::copy(f, f + kPoseSize, d.frame_poses.begin() + kPoseSize * j);
      for (int e = 0; e < frame_stride - kPoseSize; ++e) d.deformations[kParaboloidSize * j + e] = f[kPoseSize + e];
    }
    std::copy(corrections.begin(), corrections.end(), d.corrections.begin());
  }
};

[[noreturn]] void Fail(const std::string& what) { throw std::invalid_argument(what); }

template <class Vec>
void RequireSize(const Vec& v, size_t expected, const char* name) {
  if (v.size() != expected) {
    std::ostringstream s;
    s << name << " has " << v.size() << " values, expected " << expected;
    Fail(s.str());
  }
}

template <class Vec>
void RequireFinite(const Vec& v, const char* name) {
  for (size_t i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i])) {
      std::ostringstream s;
      s << name << "[" << i << "] is not finite (" << v[i] << ")";
      Fail(s.str());
    }
  }
}

int GaugeCornersNeeded(ffi::BoardModel model) {
  switch (model) {
    case ffi::BoardModel::Static:
      return 3;
    case ffi::BoardModel::Full:
      return 2;
    default:
      return 0;
  }
}

// Everything that would otherwise trip a CHECK deep inside Ceres.
void Validate(const ffi::ProblemData& d, const ffi::SolveOptions& o) {
  if (d.num_cameras == 0) Fail("the problem has no camera");
  if (d.num_frames == 0) Fail("the problem has no image");
  if (d.num_corners == 0) Fail("the board has no corner");
  const size_t n = d.obs_uv.size() / 2;
  if (n == 0) Fail("the problem has no observation");
  RequireSize(d.obs_uv, 2 * n, "obs_uv");
  RequireSize(d.obs_camera, n, "obs_camera");
  RequireSize(d.obs_frame, n, "obs_frame");
  RequireSize(d.obs_corner, n, "obs_corner");
  RequireSize(d.board, 3 * d.num_corners, "board");
  RequireSize(d.intrinsics, kIntrinsicsSize * d.num_cameras, "intrinsics");
  RequireSize(d.camera_poses, kPoseSize * d.num_cameras, "camera_poses");
  RequireSize(d.frame_poses, kPoseSize * d.num_frames, "frame_poses");
  RequireSize(d.deformations, kParaboloidSize * d.num_frames, "deformations");
  RequireSize(d.corrections, kCorrectionStride * d.num_corners, "corrections");
  RequireFinite(d.obs_uv, "obs_uv");
  if (!d.obs_weight.empty()) {
    RequireSize(d.obs_weight, n, "obs_weight");
    for (size_t i = 0; i < n; ++i) {
      if (!(d.obs_weight[i] > 0.0 && std::isfinite(d.obs_weight[i]))) {
        Fail("obs_weight[" + std::to_string(i) + "] must be a positive number");
      }
    }
  }
  RequireFinite(d.board, "board");
  RequireFinite(d.intrinsics, "intrinsics");
  RequireFinite(d.camera_poses, "camera_poses");
  RequireFinite(d.frame_poses, "frame_poses");
  RequireFinite(d.deformations, "deformations");
  RequireFinite(d.corrections, "corrections");
  for (size_t i = 0; i < n; ++i) {
    if (d.obs_camera[i] >= d.num_cameras || d.obs_frame[i] >= d.num_frames ||
        d.obs_corner[i] >= d.num_corners) {
      std::ostringstream s;
      s << "observation " << i << " refers to camera " << d.obs_camera[i] << ", frame "
        << d.obs_frame[i] << ", corner " << d.obs_corner[i] << " outside the problem";
      Fail(s.str());
    }
  }
  const size_t gauge = static_cast<size_t>(GaugeCornersNeeded(d.model));
  if (o.fix_gauge && !d.fix_corrections && d.gauge_corners.size() < gauge) {
    Fail("the board model needs " + std::to_string(gauge) + " gauge corners");
  }
  for (size_t i = 0; i < d.gauge_corners.size(); ++i) {
    if (d.gauge_corners[i] >= d.num_corners) Fail("gauge corner outside the board");
    for (size_t k = 0; k < i; ++k) {
      if (d.gauge_corners[i] == d.gauge_corners[k]) Fail("gauge corners must be distinct");
    }
  }
  for (uint32_t c : d.frozen_corners) {
    if (c >= d.num_corners) Fail("frozen corner outside the board");
  }
  if (o.loss == ffi::LossKind::Cauchy && !(o.loss_scale_px > 0.0 && std::isfinite(o.loss_scale_px))) {
    Fail("loss_scale_px must be a positive number");
  }
  if (o.num_threads < 1) Fail("num_threads must be at least 1");
  if (o.max_iterations < 0) Fail("max_iterations must not be negative");
  if (!(o.function_tolerance >= 0.0) || !(o.parameter_tolerance >= 0.0) ||
      !(o.gradient_tolerance >= 0.0)) {
    Fail("solver tolerances must be non-negative numbers");
  }
}

void SilenceGlogOnce() {
  static std::once_flag once;
  // Without InitGoogleLogging glog writes to stderr.  Ceres' own failure
  // messages come back in the solver summary, so nothing below FATAL is shown.
  std::call_once(once, [] { FLAGS_minloglevel = google::GLOG_FATAL; });
}

// The assembled problem with the bookkeeping the solver and evaluator need.
struct Assembled {
  std::unique_ptr<ceres::Problem> problem;
  std::vector<ceres::ResidualBlockId> residuals;
  // The observations behind each residual block, in its residual order.
  std::vector<std::vector<uint32_t>> block_observations;
  std::vector<double*> frame_pose_blocks;
  std::vector<double*> correction_blocks;  // free corrections, none partly held
};

template <class Board>
void AddResiduals(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p,
                  Assembled& a) {
  ceres::LossFunction* loss =
      o.loss == ffi::LossKind::Cauchy ? new ceres::CauchyLoss(o.loss_scale_px) : nullptr;
  const size_t n = d.obs_uv.size() / 2;
  constexpr bool kHasCorner = Board::kCornerSize > 0;
  constexpr bool kHasFrameExtra = Board::kFrameExtra > 0;
  const bool pose_only = d.fix_intrinsics && (d.num_cameras == 1 || d.fix_camera_poses) &&
                         (!kHasCorner || d.fix_corrections) &&
                         (!kHasFrameExtra || d.fix_deformations);
  std::vector<double*> blocks;
  std::vector<bool> corner_used(d.num_corners, false);
  std::vector<bool> frame_used(d.num_frames, false);
  a.residuals.reserve(n);
  // Pose-only views being collected: (camera, frame) -> functor and its observations.
  std::map<std::pair<uint32_t, uint32_t>, std::pair<ViewPoseError*, std::vector<uint32_t>>> views;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t cam = d.obs_camera[i], frame = d.obs_frame[i], corner = d.obs_corner[i];
    double* intrinsics = &p.intrinsics[kIntrinsicsSize * cam];
    double* rig = cam > 0 ? &p.camera_poses[kPoseSize * cam] : nullptr;
    double* frame_block = p.Frame(frame);
    double* correction = kHasCorner ? &p.corrections[kCorrectionStride * corner] : nullptr;
    const double* x = &d.board[3 * corner];
    const double u = d.obs_uv[2 * i], v = d.obs_uv[2 * i + 1];
    const double w = d.obs_weight.empty() ? 1.0 : d.obs_weight[i];
    if (pose_only) {
      double point[3];
      Board::Point(x, frame_block + kPoseSize, correction, point);
      // The pose is the first kPoseSize values of the image's block.
      if (loss == nullptr) {
        auto& view = views[{cam, frame}];
        if (view.first == nullptr) view.first = new ViewPoseError(intrinsics, rig);
        view.first->Add(u, v, w, point);
        view.second.push_back(static_cast<uint32_t>(i));
      } else {
        auto* f = new ViewPoseError(intrinsics, rig);
        f->Add(u, v, w, point);
        a.residuals.push_back(
            a.problem->AddResidualBlock(ViewPoseError::Create(f), loss, frame_block));
        a.block_observations.push_back({static_cast<uint32_t>(i)});
      }
    } else {
      blocks.clear();
      blocks.push_back(intrinsics);
      if (rig) blocks.push_back(rig);
      blocks.push_back(frame_block);
      if (kHasCorner) blocks.push_back(correction);
      ceres::CostFunction* cost;
      if (o.reference_jacobian) {
        cost = rig ? ReprojectionError<Board, true>::Create(u, v, w, x)
                   : ReprojectionError<Board, false>::Create(u, v, w, x);
      } else if (rig) {
        cost = new ChainedReprojection<Board, true>(u, v, w, x);
      } else {
        cost = new ChainedReprojection<Board, false>(u, v, w, x);
      }
      a.residuals.push_back(a.problem->AddResidualBlock(cost, loss, blocks));
      a.block_observations.push_back({static_cast<uint32_t>(i)});
    }
    corner_used[corner] = true;
    frame_used[frame] = true;
  }
  for (auto& [key, view] : views) {
    a.residuals.push_back(a.problem->AddResidualBlock(ViewPoseError::Create(view.first), nullptr,
                                                      p.Frame(key.second)));
    a.block_observations.push_back(std::move(view.second));
  }
  ceres::Problem& problem = *a.problem;
  for (uint32_t f = 0; f < d.num_frames; ++f) {
    if (frame_used[f]) a.frame_pose_blocks.push_back(p.Frame(f));
  }
  for (size_t k = 0; k < d.num_cameras; ++k) {
    double* intr = &p.intrinsics[kIntrinsicsSize * k];
    if (d.fix_intrinsics && problem.HasParameterBlock(intr)) problem.SetParameterBlockConstant(intr);
    double* pose = &p.camera_poses[kPoseSize * k];
    if (k > 0 && d.fix_camera_poses && problem.HasParameterBlock(pose)) {
      problem.SetParameterBlockConstant(pose);
    }
  }
  if (kHasFrameExtra && d.fix_deformations && !pose_only) {
    // Hold the per-image parameters, keep the pose free.
    std::vector<int> held;
    for (int e = 0; e < Board::kFrameExtra; ++e) held.push_back(kPoseSize + e);
    for (double* block : a.frame_pose_blocks) {
      problem.SetManifold(block, new ceres::SubsetManifold(kPoseSize + Board::kFrameExtra, held));
    }
  }
  if (!kHasCorner) return;
  if (d.fix_corrections) {
    for (uint32_t c = 0; c < d.num_corners; ++c) {
      double* block = &p.corrections[kCorrectionStride * c];
      if (problem.HasParameterBlock(block)) problem.SetParameterBlockConstant(block);
    }
    return;
  }
  for (uint32_t c : d.frozen_corners) {
    if (corner_used[c]) problem.SetParameterBlockConstant(&p.corrections[kCorrectionStride * c]);
  }
  if (o.fix_gauge) {
    for (uint32_t c : d.gauge_corners) {
      if (!corner_used[c]) Fail("gauge corner " + std::to_string(c) + " is never observed");
    }
    Board::FixGauge(problem, p.corrections.data(),
                    std::vector<uint32_t>(d.gauge_corners.begin(), d.gauge_corners.end()));
  }
  // A partly held gauge corner stays out of the eliminated set: with every
  // eliminated block the same size, Ceres uses its fixed-size Schur kernels.
  for (uint32_t c = 0; c < d.num_corners; ++c) {
    double* block = &p.corrections[kCorrectionStride * c];
    if (corner_used[c] && !problem.IsParameterBlockConstant(block) &&
        problem.ParameterBlockTangentSize(block) == Board::kCornerSize) {
      a.correction_blocks.push_back(block);
    }
  }
}

// Per-image parameters the model keeps beside each pose.
int FrameExtra(ffi::BoardModel model) {
  switch (model) {
    case ffi::BoardModel::Dynamic:
      return DynamicBoard::kFrameExtra;
    case ffi::BoardModel::Full:
      return FullBoard::kFrameExtra;
    default:
      return 0;
  }
}

Assembled Assemble(const ffi::ProblemData& d, const ffi::SolveOptions& o, Params& p) {
  Validate(d, o);
  SilenceGlogOnce();
  Assembled a;
  a.problem = std::make_unique<ceres::Problem>();
  switch (d.model) {
    case ffi::BoardModel::Standard:
      AddResiduals<StandardBoard>(d, o, p, a);
      break;
    case ffi::BoardModel::Static:
      AddResiduals<StaticBoard>(d, o, p, a);
      break;
    case ffi::BoardModel::Dynamic:
      AddResiduals<DynamicBoard>(d, o, p, a);
      break;
    case ffi::BoardModel::Full:
      AddResiduals<FullBoard>(d, o, p, a);
      break;
    default:
      Fail("unknown board model");
  }
  return a;
}

// Schur elimination of whichever independent set of blocks (image poses or
// corner corrections) leaves the smaller reduced system; dense below a size
// where the reduced matrix fits comfortably, sparse above it.
void ChooseLinearSolver(const Assembled& a, ceres::Solver::Options& s) {
  ceres::Problem& problem = *a.problem;
  std::vector<double*> all;
  problem.GetParameterBlocks(&all);
  int total = 0, free_poses = 0, free_corrections = 0;
  for (double* b : all) {
    if (problem.IsParameterBlockConstant(b)) continue;
    total += problem.ParameterBlockTangentSize(b);
  }
  for (double* b : a.frame_pose_blocks) {
    if (!problem.IsParameterBlockConstant(b)) free_poses += problem.ParameterBlockTangentSize(b);
  }
  for (double* b : a.correction_blocks) free_corrections += problem.ParameterBlockTangentSize(b);

  const int reduced_poses = total - free_poses;
  const int reduced_corrections = total - free_corrections;
  const bool eliminate_corrections = free_corrections > 0 && reduced_corrections < reduced_poses;
  const std::vector<double*>& eliminated =
      eliminate_corrections ? a.correction_blocks : a.frame_pose_blocks;
  const int reduced = eliminate_corrections ? reduced_corrections : reduced_poses;
  if (reduced == 0) {
    // Only independent per-image blocks are free (e.g. a poses-only refit).
    s.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    return;
  }
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (double* b : all) ordering->AddElementToGroup(b, 1);
  for (double* b : eliminated) ordering->AddElementToGroup(b, 0);
  s.linear_solver_ordering = ordering;
  s.linear_solver_type = reduced <= 1200 ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
}

// Per-iteration progress on stderr: stdout belongs to the CLI, and glog's INFO
// stream is off.
class StderrProgress : public ceres::IterationCallback {
 public:
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    std::fprintf(stderr, "  iter %3d  cost %.6e  |step| %.3e  tr-radius %.2e  linear-iters %d  %.1f ms\n",
                 s.iteration, s.cost, s.step_norm, s.trust_region_radius, s.linear_solver_iterations,
                 1e3 * s.cumulative_time_in_seconds);
    return ceres::SOLVER_CONTINUE;
  }
};

ceres::Solver::Options MakeSolverOptions(const ffi::SolveOptions& o) {
  ceres::Solver::Options s;
  s.max_num_iterations = o.max_iterations;
  s.function_tolerance = o.function_tolerance;
  s.gradient_tolerance = o.gradient_tolerance;
  s.parameter_tolerance = o.parameter_tolerance;
  s.num_threads = o.num_threads;
  s.minimizer_progress_to_stdout = false;  // stdout belongs to the CLI
  s.logging_type = ceres::SILENT;
  // Every solve starts near its optimum (Zhang, or the previous stage), where
  // Gauss-Newton steps are good.  Ceres' default radius (1e4) damps the weakly
  // determined directions (k3, the board's bend against the pose) so much that
  // they crawl in for many iterations; LM still shrinks the radius on a bad step.
  s.initial_trust_region_radius = 1e8;
  return s;
}

// Residuals (loss not applied) in observation order; Ceres orders them by block.
// With `jacobian`, also the Jacobian over the free parameter blocks.
bool OrderedResiduals(Assembled& a, size_t num_observations, int threads, double* cost,
                      std::vector<double>* out, ceres::CRSMatrix* jacobian) {
  ceres::Problem::EvaluateOptions e;
  e.residual_blocks = a.residuals;
  e.apply_loss_function = false;
  e.num_threads = threads;
  if (jacobian != nullptr) {
    std::vector<double*> all;
    a.problem->GetParameterBlocks(&all);
    for (double* b : all) {
      if (!a.problem->IsParameterBlockConstant(b)) e.parameter_blocks.push_back(b);
    }
  }
  std::vector<double> by_block;
  if (!a.problem->Evaluate(e, cost, &by_block, nullptr, jacobian)) return false;
  out->assign(2 * num_observations, 0.0);
  size_t next = 0;
  for (const auto& obs : a.block_observations) {
    for (uint32_t i : obs) {
      (*out)[2 * i] = by_block[next++];
      (*out)[2 * i + 1] = by_block[next++];
    }
  }
  return true;
}

}  // namespace

namespace ffi {

SolveReport solve(ProblemData& data, const SolveOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  Params params(data, FrameExtra(data.model));
  Assembled a = Assemble(data, options, params);
  ceres::Solver::Options s = MakeSolverOptions(options);
  ChooseLinearSolver(a, s);
  std::string why;
  if (!s.IsValid(&why)) Fail("invalid solver options: " + why);
  StderrProgress progress;
  if (options.verbose) s.callbacks.push_back(&progress);
  ceres::Solver::Summary summary;
  ceres::Solve(s, a.problem.get(), &summary);

  SolveReport report;
  report.usable = summary.IsSolutionUsable();
  report.converged = summary.termination_type == ceres::CONVERGENCE;
  report.iterations = static_cast<int32_t>(summary.iterations.size()) - 1;
  report.initial_cost = summary.initial_cost;
  report.final_cost = summary.final_cost;
  report.message = rust::String(summary.message);
  report.linear_solver = rust::String(ceres::LinearSolverTypeToString(summary.linear_solver_type_used));
  if (report.usable) {
    for (double v : params.intrinsics) report.usable = report.usable && std::isfinite(v);
    for (double v : params.frames) report.usable = report.usable && std::isfinite(v);
    if (!report.usable) report.message = rust::String("the solve produced non-finite parameters");
  }
  if (report.usable) {
    params.CopyTo(data);
    // The final residuals, from the problem already built.
    double cost = 0.0;
    std::vector<double> residuals;
    if (OrderedResiduals(a, data.obs_uv.size() / 2, options.num_threads, &cost, &residuals,
                         nullptr)) {
      for (double r : residuals) report.residuals.push_back(r);
    }
  }
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (options.verbose) std::fprintf(stderr, "%s\n", summary.FullReport().c_str());
  return report;
}

Evaluation evaluate(const ProblemData& data, const SolveOptions& options, bool with_jacobian) {
  Params params(data, FrameExtra(data.model));
  Assembled a = Assemble(data, options, params);
  double cost = 0.0;
  std::vector<double> ordered;
  ceres::CRSMatrix jacobian;
  if (!OrderedResiduals(a, data.obs_uv.size() / 2, options.num_threads, &cost, &ordered,
                        with_jacobian ? &jacobian : nullptr)) {
    Fail("the residuals could not be evaluated (a point behind the camera?)");
  }
  Evaluation out;
  out.cost = cost;
  for (double r : ordered) out.residuals.push_back(r);
  if (with_jacobian) {
    out.jacobian_rows = static_cast<size_t>(jacobian.num_rows);
    out.jacobian_cols = static_cast<size_t>(jacobian.num_cols);
    for (int v : jacobian.rows) out.jacobian_row_ptr.push_back(static_cast<uint32_t>(v));
    for (int v : jacobian.cols) out.jacobian_col_idx.push_back(static_cast<uint32_t>(v));
    for (double v : jacobian.values) out.jacobian_values.push_back(v);
  }
  return out;
}

}  // namespace ffi
}  // namespace deformcal
