#pragma once
// Rolling-shutter reprojection error (paper eq. 9), standardised:
//   r = L^{-1} (y - pi(T_cw(t_i + v d) P)),   L L^T = A R A^T  (error_standardisation.hpp)
// with the *measured* row v in the time, so de/dd flows through the spline's time
// derivative (eq. 13-14) by autodiff.
//
// Parameter blocks:
//   c0, c1, c2, c3 : 6 each, control points span-3 .. span of the pose spline, [p; phi]
//   line_delay     : 1, d in seconds per row
//
// The residual keeps the span it was attached to: if d moves t across a knot, the span's
// cubic is continued polynomially (it is C2-continuous with the neighbour there). The
// solver re-attaches every residual to its current span between solves.
#include <ceres/autodiff_cost_function.h>

#include "rscalib/rs/rs_projection.hpp"

namespace rscalib::rs {

struct RsReprojectionCost {
  RsReprojectionCost(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                     double frame_time_minus_span_start_s, const double* uv_measured,
                     const double* point_w, const Eigen::Matrix2d& sqrt_information)
      : basis_(basis),
        cam_(cam),
        frame_offset_s_(frame_time_minus_span_start_s),
        measurement_(uv_measured, point_w, sqrt_information) {}

  template <typename T>
  bool operator()(const T* c0, const T* c1, const T* c2, const T* c3, const T* line_delay,
                  T* residual) const {
    const T* control_points[4] = {c0, c1, c2, c3};
    const T u = T(frame_offset_s_) + T(measurement_.uv[1]) * line_delay[0];
    T uv[2];
    if (!ProjectAtSpanTime(basis_, cam_, measurement_.point_w, control_points, u, uv)) return false;
    measurement_.Residual(uv, residual);
    return true;
  }

  static ceres::CostFunction* Create(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                                     double frame_time_minus_span_start_s,
                                     const double* uv_measured, const double* point_w,
                                     const Eigen::Matrix2d& sqrt_information) {
    return new ceres::AutoDiffCostFunction<RsReprojectionCost, 2, 6, 6, 6, 6, 1>(
        new RsReprojectionCost(basis, cam, frame_time_minus_span_start_s, uv_measured, point_w,
                               sqrt_information));
  }

 private:
  spline::SpanPowerBasis basis_;
  SpanCamera cam_;
  double frame_offset_s_;
  WeightedMeasurement measurement_;
};

}  // namespace rscalib::rs
