#pragma once
// Rolling-shutter projection of a target point at an explicit time, through the pose
// spline restricted to one span (4 control points), and the weighted measurement of a
// reprojection cost. Shared by the cost functors and by the solvers (the error
// standardisation needs the image velocity d/dt pi(T(t) P)).
#include "rscalib/camera/camera_model.hpp"
#include "rscalib/geometry/pose.hpp"
#include "rscalib/spline/bspline_basis.hpp"

namespace rscalib::rs {

// Fixed inputs of one observation's projection. Intrinsics are constants here.
struct SpanCamera {
  camera::CameraModelType model;
  const double* params;  // camera::CameraModel::params().data()
  int num_params;
  const double* pixel_size_mm;  // civera-radial only

  // uv = pi(point_c). False if the point cannot be projected. T: double or ceres::Jet.
  template <typename T>
  bool Project(const T* point_c, T* uv) const {
    T params_t[camera::CameraModel::kMaxParams];
    for (int i = 0; i < num_params; ++i) params_t[i] = T(params[i]);
    return camera::ProjectPoint(model, params_t, pixel_size_mm, point_c, uv);
  }
};

// The SpanCamera of `camera` (which must outlive it).
inline SpanCamera MakeSpanCamera(const camera::CameraModel& camera) {
  return SpanCamera{camera.type(), camera.params().data(), static_cast<int>(camera.params().size()),
                    camera.pixel_size_mm().data()};
}

// uv = pi(T_cw(t) P) with t = span_start + u and the pose from the span's 4 control
// points c[0..3] (each [p; phi]). Returns false if the point cannot be projected.
template <typename T>
bool ProjectAtSpanTime(const spline::SpanPowerBasis& basis, const SpanCamera& cam,
                       const double* point_w, const T* const control_points[4],
                       const T& t_minus_span_start, T* uv) {
  T weights[3][4];
  // EvaluateSpanBasis takes absolute time; pass u directly with a zero-start copy to
  // keep full precision for large absolute timestamps.
  spline::SpanPowerBasis local = basis;
  local.span_start = 0.0;
  spline::EvaluateSpanBasis(local, t_minus_span_start, 0, weights);
  T state[geometry::kPoseStateDim];
  spline::CombineControlPoints(weights[0], control_points, geometry::kPoseStateDim, state);
  T point_c[3];
  geometry::TransformWorldToCamera(state, point_w, point_c);
  return cam.Project(point_c, uv);
}

// One measured pixel y of a target point and the weight W of its error (the fixed data of
// a reprojection cost): r = W (y - uv).
struct WeightedMeasurement {
  WeightedMeasurement(const double* uv_measured, const double* point_w_in,
                      const Eigen::Matrix2d& sqrt_information_in)
      : uv{uv_measured[0], uv_measured[1]},
        point_w{point_w_in[0], point_w_in[1], point_w_in[2]},
        sqrt_information(sqrt_information_in) {}

  template <typename T>
  void Residual(const T* uv_predicted, T* residual) const {
    const T e0 = T(uv[0]) - uv_predicted[0];
    const T e1 = T(uv[1]) - uv_predicted[1];
    residual[0] = sqrt_information(0, 0) * e0 + sqrt_information(0, 1) * e1;
    residual[1] = sqrt_information(1, 0) * e0 + sqrt_information(1, 1) * e1;
  }

  double uv[2];
  double point_w[3];
  Eigen::Matrix2d sqrt_information;
};

}  // namespace rscalib::rs
