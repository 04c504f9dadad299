#pragma once
// Motion prior (paper §4.1): \int x''(t)^T Q^{-1} x''(t) dt over one knot span, exact by
// 2-point Gauss quadrature (x'' is linear in a span):
//   r_g = sqrt(w_g) Q^{-1/2} x''(t_g),  g = 1, 2   -> 12 residuals, sum r^2 = the integral.
//
// Parameter blocks: c0, c1, c2, c3 : 6 each, control points span-3 .. span, [p; phi].
#include <Eigen/Core>
#include <ceres/autodiff_cost_function.h>

#include "rscalib/spline/bspline_basis.hpp"

namespace rscalib::rs {

struct MotionPriorCost {
  // second_derivative_weights[g][j] = w_j''(t_g); q_diagonal = diag(Q).
  MotionPriorCost(const double second_derivative_weights[2][4], const double quadrature_weight[2],
                  const Eigen::Matrix<double, 6, 1>& q_diagonal) {
    for (int g = 0; g < 2; ++g)
      for (int j = 0; j < 4; ++j) weights_[g][j] = second_derivative_weights[g][j];
    for (int g = 0; g < 2; ++g)
      for (int d = 0; d < 6; ++d) scale_[g][d] = std::sqrt(quadrature_weight[g] / q_diagonal[d]);
  }

  template <typename T>
  bool operator()(const T* c0, const T* c1, const T* c2, const T* c3, T* residual) const {
    const T* c[4] = {c0, c1, c2, c3};
    for (int g = 0; g < 2; ++g)
      for (int d = 0; d < 6; ++d) {
        T acceleration = weights_[g][0] * c[0][d];
        for (int j = 1; j < 4; ++j) acceleration += weights_[g][j] * c[j][d];
        residual[6 * g + d] = scale_[g][d] * acceleration;
      }
    return true;
  }

  // Cost of span `span` of the knot vector.
  static ceres::CostFunction* Create(const double* knots, int span,
                                     const Eigen::Matrix<double, 6, 1>& q_diagonal) {
    const spline::SpanQuadrature q = spline::AccelerationQuadrature(knots[span], knots[span + 1]);
    double second[2][4];
    double ders[4][4];
    for (int g = 0; g < 2; ++g) {
      spline::BasisFunctionDerivatives(knots, span, q.t[g], 2, ders);
      for (int j = 0; j < 4; ++j) second[g][j] = ders[2][j];
    }
    return new ceres::AutoDiffCostFunction<MotionPriorCost, 12, 6, 6, 6, 6>(
        new MotionPriorCost(second, q.weight, q_diagonal));
  }

 private:
  double weights_[2][4];
  double scale_[2][6];
};

}  // namespace rscalib::rs
