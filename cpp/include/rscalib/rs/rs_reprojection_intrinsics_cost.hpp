#pragma once
// Rolling-shutter reprojection error (paper eq. 9) with the camera intrinsics as unknowns
// (`rscalib linedelay --refine-intrinsics`, docs/formulation.md §14):
//   r = W (y - pi_theta(T_cw(t_i + v d) P))
// with W the standardisation weight of rs_reprojection_cost.hpp (computed at the current
// estimate, intrinsics included) and pi_theta the camera model with parameters theta.
//
// Parameter blocks:
//   c0, c1, c2, c3 : 6 each, control points span-3 .. span of the pose spline, [p; phi]
//   line_delay     : 1, d in seconds per row
//   intrinsics     : kIntrinsicsBlockSize (9), theta in the model's layout, zero-padded
//                    (intrinsics_prior_cost.hpp; px for f and c)
//
// Like RsReprojectionCost, the residual keeps the span it was attached to.
#include <ceres/autodiff_cost_function.h>

#include "rscalib/rs/intrinsics_prior_cost.hpp"
#include "rscalib/rs/rs_projection.hpp"

namespace rscalib::rs {

// x_c = T_cw(t) P with t = span start + t_minus_span_start, the pose from the span's 4
// control points (each [p; phi]).
template <typename T>
void TransformAtSpanTime(const spline::SpanPowerBasis& basis, const double* point_w,
                         const T* const control_points[4], const T& t_minus_span_start,
                         T* point_c) {
  T weights[3][4];
  spline::SpanPowerBasis local = basis;  // zero start: full precision for large timestamps
  local.span_start = 0.0;
  spline::EvaluateSpanBasis(local, t_minus_span_start, 0, weights);
  T state[geometry::kPoseStateDim];
  spline::CombineControlPoints(weights[0], control_points, geometry::kPoseStateDim, state);
  geometry::TransformWorldToCamera(state, point_w, point_c);
}

// The fixed part of a camera whose parameters are unknowns: its model and pixel size.
struct CameraModelOf {
  camera::CameraModelType model;
  double pixel_size_mm[2];  // civera-radial only

  explicit CameraModelOf(const camera::CameraModel& camera)
      : model(camera.type()), pixel_size_mm{camera.pixel_size_mm()[0], camera.pixel_size_mm()[1]} {}

  template <typename T>
  bool Project(const T* intrinsics, const T* point_c, T* uv) const {
    return camera::ProjectPoint(model, intrinsics, pixel_size_mm, point_c, uv);
  }
};

struct RsReprojectionIntrinsicsCost {
  RsReprojectionIntrinsicsCost(const spline::SpanPowerBasis& basis, const CameraModelOf& camera,
                               double frame_time_minus_span_start_s, const double* uv_measured,
                               const double* point_w, const Eigen::Matrix2d& sqrt_information)
      : basis_(basis),
        camera_(camera),
        frame_offset_s_(frame_time_minus_span_start_s),
        measurement_(uv_measured, point_w, sqrt_information) {}

  template <typename T>
  bool operator()(const T* c0, const T* c1, const T* c2, const T* c3, const T* line_delay,
                  const T* intrinsics, T* residual) const {
    const T* control_points[4] = {c0, c1, c2, c3};
    const T u = T(frame_offset_s_) + T(measurement_.uv[1]) * line_delay[0];
    T point_c[3];
    TransformAtSpanTime(basis_, measurement_.point_w, control_points, u, point_c);
    T uv[2];
    if (!camera_.Project(intrinsics, point_c, uv)) return false;
    measurement_.Residual(uv, residual);
    return true;
  }

  static ceres::CostFunction* Create(const spline::SpanPowerBasis& basis,
                                     const CameraModelOf& camera,
                                     double frame_time_minus_span_start_s,
                                     const double* uv_measured, const double* point_w,
                                     const Eigen::Matrix2d& sqrt_information) {
    return new ceres::AutoDiffCostFunction<RsReprojectionIntrinsicsCost, 2, 6, 6, 6, 6, 1,
                                           kIntrinsicsBlockSize>(new RsReprojectionIntrinsicsCost(
        basis, camera, frame_time_minus_span_start_s, uv_measured, point_w, sqrt_information));
  }

 private:
  spline::SpanPowerBasis basis_;
  CameraModelOf camera_;
  double frame_offset_s_;
  WeightedMeasurement measurement_;
};

}  // namespace rscalib::rs
