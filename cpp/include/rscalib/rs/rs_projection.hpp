#pragma once
// Rolling-shutter projection of a target point at an explicit time, through the pose
// spline restricted to one span (4 control points). Shared by the cost functor and by
// the error standardisation (which needs the image velocity d/dt pi(T(t) P)).
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
  T params[camera::CameraModel::kMaxParams];
  for (int i = 0; i < cam.num_params; ++i) params[i] = T(cam.params[i]);
  return camera::ProjectPoint(cam.model, params, cam.pixel_size_mm, point_c, uv);
}

}  // namespace rscalib::rs
