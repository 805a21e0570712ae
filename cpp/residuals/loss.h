// The Cauchy loss folded into a corner's residual (CauchyFold), and a
// one-corner block that folds it (FoldedCorner).
#pragma once

#include <ceres/ceres.h>

#include <cmath>
#include <memory>
#include <utility>
#include <vector>

namespace deformcal {
// Cauchy's rho(s) = a^2 ln(1 + s/a^2) folded into a corner's residual, since a
// cost function with several corners cannot hand Ceres a per-corner
// LossFunction (Ceres applies one to the whole block).  The residual becomes
// r~ = f r with f = sqrt(rho(s)/s), so |r~|^2 = rho(|r|^2) and the cost and its
// gradient are the loss's exactly: the optimum is the same.  The Jacobian is
// M J with M = sqrt(rho') P_t + (rho'/f) P_r (P_r = r r^T/s, P_t = I - P_r):
// radially the exact derivative of r~, tangentially the sqrt(rho') of Ceres'
// own (clamped Triggs) correction, which is exact there, so the Gauss-Newton
// model is closer to the loss's Hessian than either alone (fewer iterations).
struct CauchyFold {
  double a2 = 0.0;  // squared scale; 0 means no loss

  // f alone, for a residual without its Jacobian.
  double Factor(double s) const {
    if (a2 == 0.0) return 1.0;
    const double x = s / a2;
    // rho(s)/s; the closed form cancels near zero, where the series is exact.
    const double rho_s = x < 1e-6 ? 1.0 - x / 2.0 + x * x / 3.0 : std::log1p(x) / x;
    return std::sqrt(rho_s);
  }

  // f, and M's tangential and radial factors.
  void Scale(double s, double* f, double* mt, double* mr) const {
    if (a2 == 0.0) {
      *f = *mt = *mr = 1.0;
      return;
    }
    const double x = s / a2;
    const double drho = 1.0 / (1.0 + x);  // rho'(s)
    *f = Factor(s);
    *mt = std::sqrt(drho);
    *mr = drho / *f;
  }

  // f and M = mt I + (mr - mt) e e^T / s for the residual e (s = |e|^2).
  void Fold(const double e[2], double* f, double M[2][2]) const {
    const double s = e[0] * e[0] + e[1] * e[1];
    double mt, mr;
    Scale(s, f, &mt, &mr);
    M[0][0] = M[1][1] = mt;
    M[0][1] = M[1][0] = 0.0;
    if (mr != mt && s > 0.0) {
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) M[a][b] += (mr - mt) * e[a] * e[b] / s;
    }
  }
};

// A one-corner block with the Cauchy loss folded in as a view block folds it
// (CauchyFold), for a static correction's per-corner blocks: with Ceres' own
// LossFunction (the loss's curvature dropped from Gauss-Newton) its stage took
// more iterations, each step about half the one before.  The cost and the
// optimum are the loss's; a loss scale factor of 0 gives the plain residual, as
// for the view blocks.
class FoldedCorner final : public ceres::CostFunction {
 public:
  FoldedCorner(ceres::CostFunction* corner, CauchyFold loss, std::shared_ptr<const double> loss_scale_factor)
      : corner_(corner), loss_(loss), loss_scale_factor_(std::move(loss_scale_factor)) {
    set_num_residuals(2);
    *mutable_parameter_block_sizes() = corner->parameter_block_sizes();
  }

  bool Evaluate(double const* const* p, double* r, double** jacobians) const override {
    if (!corner_->Evaluate(p, r, jacobians)) return false;
    const double k = *loss_scale_factor_;
    const CauchyFold loss{loss_.a2 * k * k};
    if (jacobians == nullptr) {
      const double f = loss.Factor(r[0] * r[0] + r[1] * r[1]);
      r[0] *= f;
      r[1] *= f;
      return true;
    }
    double f, M[2][2];
    loss.Fold(r, &f, M);
    r[0] *= f;
    r[1] *= f;
    const std::vector<int32_t>& sizes = parameter_block_sizes();
    for (size_t b = 0; b < sizes.size(); ++b) {
      double* J = jacobians[b];
      if (J == nullptr) continue;
      const int n = sizes[b];
      for (int c = 0; c < n; ++c) {
        const double j0 = J[c], j1 = J[n + c];
        J[c] = M[0][0] * j0 + M[0][1] * j1;
        J[n + c] = M[1][0] * j0 + M[1][1] * j1;
      }
    }
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> corner_;
  CauchyFold loss_;
  std::shared_ptr<const double> loss_scale_factor_;
};

}  // namespace deformcal
