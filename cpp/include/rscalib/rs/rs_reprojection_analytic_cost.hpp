#pragma once
// The residual of RsReprojectionCost (paper eq. 9) with its Jacobian chained by hand
// (docs/formulation.md §15). The residual depends on the 24 control-point parameters and on d
// only through the pose state x(t) = sum_j w_j(u) c_j at u = t_i - span_start + v d:
//   dr/dc_j = dr/dx w_j(u),   dr/dd = dr/dx x'(u) v,   x'(u) = sum_j w_j'(u) c_j
// (the spline is a plain cubic B-spline in R^6, linear in its control points). Only dr/dx
// (2 x 6) needs autodiff: ceres::Jet<double, 6> instead of the 25-wide Jets of the functor.
//
// Parameter blocks as RsReprojectionCost: c0..c3 (6 each, span-3 .. span), line_delay (1).
#include <vector>

#include <ceres/cost_function.h>
#include <ceres/sized_cost_function.h>

#include "rscalib/rs/rs_projection.hpp"
#include "rscalib/rs/rs_reprojection_intrinsics_cost.hpp"

namespace rscalib::rs {

// One observation's error r (2) and its Jacobian rows: the arithmetic of both costs below.
struct AnalyticReprojectionTerm {
  AnalyticReprojectionTerm(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                           double frame_time_minus_span_start_s, const double* uv_measured,
                           const double* point_w, const Eigen::Matrix2d& sqrt_information);

  // As ceres::CostFunction::Evaluate for the blocks c0..c3, d: residuals[0..1], jacobians[b]
  // (each may be null) row-major 2 x block size.
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const;

  spline::SpanPowerBasis basis;  // span_start 0: u is relative to the span start
  SpanCamera cam;
  double frame_offset_s;
  WeightedMeasurement measurement;
};

class RsReprojectionAnalyticCost : public ceres::SizedCostFunction<2, 6, 6, 6, 6, 1> {
 public:
  RsReprojectionAnalyticCost(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                             double frame_time_minus_span_start_s, const double* uv_measured,
                             const double* point_w, const Eigen::Matrix2d& sqrt_information)
      : term_(basis, cam, frame_time_minus_span_start_s, uv_measured, point_w, sqrt_information) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    return term_.Evaluate(parameters, residuals, jacobians);
  }

 private:
  AnalyticReprojectionTerm term_;
};

// The errors of several observations on the same span (the points of the frames that fall on it,
// as the solver groups them) in one residual block of 2k rows: the same numbers as k
// RsReprojectionAnalyticCost blocks, with Ceres' per-block work (evaluation, Jacobian scatter,
// J^T J) done once per group. Only for plain least squares: a robust loss applies to a whole
// block, so the solver keeps one block per observation then.
class RsReprojectionGroupCost : public ceres::CostFunction {
 public:
  explicit RsReprojectionGroupCost(std::vector<AnalyticReprojectionTerm> terms);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  std::vector<AnalyticReprojectionTerm> terms_;
};

// The residual of RsReprojectionIntrinsicsCost (the intrinsics theta as unknowns, the camera
// check and --refine-intrinsics) with the same chaining: dr/dx and dr/dtheta by autodiff
// (ceres::Jet<double, 6 + kIntrinsicsBlockSize>: 15 wide instead of the functor's 34), the
// control points and d through the basis weights.
//
// Parameter blocks as RsReprojectionIntrinsicsCost: c0..c3 (6 each), line_delay (1),
// intrinsics (kIntrinsicsBlockSize).
struct AnalyticIntrinsicsTerm {
  AnalyticIntrinsicsTerm(const spline::SpanPowerBasis& basis, const CameraModelOf& camera,
                         double frame_time_minus_span_start_s, const double* uv_measured,
                         const double* point_w, const Eigen::Matrix2d& sqrt_information);

  // As ceres::CostFunction::Evaluate for the blocks c0..c3, d, theta.
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const;

  spline::SpanPowerBasis basis;  // span_start 0
  CameraModelOf camera;
  double frame_offset_s;
  WeightedMeasurement measurement;
};

// Several AnalyticIntrinsicsTerm of one span in one block of 2k rows (as RsReprojectionGroupCost;
// one member per block under a robust loss).
class RsReprojectionIntrinsicsGroupCost : public ceres::CostFunction {
 public:
  explicit RsReprojectionIntrinsicsGroupCost(std::vector<AnalyticIntrinsicsTerm> terms);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  std::vector<AnalyticIntrinsicsTerm> terms_;
};

}  // namespace rscalib::rs
