#pragma once
// Least-squares fit of a cubic B-spline to timestamped samples, with an optional
// acceleration penalty (the smoothing spline used to initialise the trajectory):
//
//   min_C  sum_s w_s |x(t_s) - y_s|^2  +  sum_d lambda_d  \int (d^2 x_d / dt^2)^2 dt
//
// The normal equations are banded; they are solved with a sparse Cholesky (LDL^T).
#include <vector>

#include <Eigen/Core>

#include "rscalib/spline/cubic_bspline.hpp"

namespace rscalib::spline {

struct SplineFitOptions {
  // Per-dimension acceleration penalty lambda_d (empty = no penalty; size 1 = same for all).
  std::vector<double> acceleration_weight;
  // Per-sample weight w_s (empty = all 1).
  std::vector<double> sample_weight;
};

// Fits control points for the given clamped knot vector. times: m values inside the
// domain; samples: m x N. Throws InputError when the problem is singular (e.g. a span
// with no samples and no penalty).
CubicBSpline FitCubicBSpline(const std::vector<double>& knots, const Eigen::VectorXd& times,
                             const Eigen::MatrixXd& samples, const SplineFitOptions& options = {});

}  // namespace rscalib::spline
