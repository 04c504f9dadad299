#pragma once
// The residual of RsReprojectionCost (paper eq. 9) with its Jacobian chained by hand
// (docs/formulation.md §15). The residual depends on the 24 control-point parameters and on d
// only through the pose state x(t) = sum_j w_j(u) c_j at u = t_i - span_start + v d:
//   dr/dc_j = dr/dx w_j(u),   dr/dd = dr/dx x'(u) v,   x'(u) = sum_j w_j'(u) c_j
// (the spline is a plain cubic B-spline in R^6, linear in its control points). Only dr/dx
// (2 x 6) needs autodiff: ceres::Jet<double, 6> instead of the 25-wide Jets of the functor.
//
// Parameter blocks as RsReprojectionCost: c0..c3 (6 each, span-3 .. span), line_delay (1).
#include <ceres/sized_cost_function.h>

#include "rscalib/rs/rs_projection.hpp"

namespace rscalib::rs {

class RsReprojectionAnalyticCost : public ceres::SizedCostFunction<2, 6, 6, 6, 6, 1> {
 public:
  RsReprojectionAnalyticCost(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                             double frame_time_minus_span_start_s, const double* uv_measured,
                             const double* point_w, const Eigen::Matrix2d& sqrt_information);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  spline::SpanPowerBasis basis_;  // span_start 0: u is relative to the span start
  SpanCamera cam_;
  double frame_offset_s_;
  WeightedMeasurement measurement_;
};

}  // namespace rscalib::rs
