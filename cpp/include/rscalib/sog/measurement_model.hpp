#pragma once
// Measurement of a map feature (docs/sog.md §5; paper eq. 9-12): the feature in the camera
// frame, h = R(q)^T (m(theta, phi) + rho ((x0, y0, z0) - r)) for inverse depth (a positive
// multiple of the point) or h = R(q)^T (X - r) for XYZ, projected with civera-radial.
// "camera" is the 12-vector [f, Cx, Cy, k1, k2, r, q] (state_layout.hpp, columns 0..11).
#include <Eigen/Core>

#include "rscalib/camera/civera_radial.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/quaternion.hpp"
#include "rscalib/sog/radial_distortion.hpp"
#include "rscalib/sog/state_layout.hpp"

namespace rscalib::sog {

using MeasuredCamera = Eigen::Matrix<double, kMeasuredCameraDim, 1>;

template <typename T>
Eigen::Matrix<T, 3, 1> FeatureInCamera(const T* camera, FeatureKind kind, const T* feature) {
  const Eigen::Matrix<T, 3, 1> r(camera[5], camera[6], camera[7]);
  const Quaternion<T> q(camera[8], camera[9], camera[10], camera[11]);
  Eigen::Matrix<T, 3, 1> a;
  if (kind == FeatureKind::kInverseDepth) {
    const Eigen::Matrix<T, 3, 1> origin(feature[0], feature[1], feature[2]);
    a = DirectionFromAngles(feature[3], feature[4]) + feature[5] * (origin - r);
  } else {
    a = Eigen::Matrix<T, 3, 1>(feature[0], feature[1], feature[2]) - r;
  }
  return QuaternionToRotation(q).transpose() * a;
}

// Distorted pixel of a feature; false if it is behind the camera or not invertible.
// The reference implementation (double or ceres::Jet) the analytic Jacobians are tested against.
template <typename T>
bool ProjectFeature(const T* camera, const double* pixel_size_mm, FeatureKind kind,
                    const T* feature, T* uv) {
  const Eigen::Matrix<T, 3, 1> h = FeatureInCamera(camera, kind, feature);
  return camera::CiveraRadial::Project(camera, pixel_size_mm, h.data(), uv);
}

// Analytic version with Jacobians: d_uv_d_camera (2x12), d_uv_d_feature (2x6; only the first
// FeatureDim(kind) columns are meaningful).
bool ProjectFeatureWithJacobians(const MeasuredCamera& camera, const Eigen::Vector2d& pixel_size_mm,
                                 FeatureKind kind, const double* feature, Eigen::Vector2d* uv,
                                 Eigen::Matrix<double, 2, kMeasuredCameraDim>* d_uv_d_camera,
                                 Eigen::Matrix<double, 2, 6>* d_uv_d_feature);

}  // namespace rscalib::sog
