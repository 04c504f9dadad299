#pragma once
// The scale gauge of the bundle adjustment (docs/sog.md §23): one keyframe's pose moves on the
// manifold that keeps its camera centre c = -R^T p at a fixed distance from a fixed point c0
// (the first keyframe's centre, whose pose is held). With the first pose held, the only freedom
// of the data left is a scaling about c0; it changes that distance, which is held here, so the
// gauge is fixed without holding anything a point or another pose needs.
//
// Ambient layout (6): [p (m); phi (rad)] (T_cw). Tangent layout (5): [s0, s1 (m), dphi (rad)]:
// the centre moves by the arc s0 e0 + s1 e1 on the sphere about c0 (e0, e1 orthonormal, normal
// to the current direction c - c0), the rotation on the left, R' = exp([dphi]x) R (as
// pose_manifold.hpp); then p' = -R' c'.
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ceres/autodiff_manifold.h>
#include <ceres/rotation.h>

#include "rscalib/bundle/pose_manifold.hpp"
#include "rscalib/core/scalar.hpp"

namespace rscalib::bundle {

struct BaselineManifoldFunctor {
  explicit BaselineManifoldFunctor(const Eigen::Vector3d& centre) : centre_(centre) {}

  template <typename T>
  bool Plus(const T* x, const T* delta, T* x_plus_delta) const {
    using std::cos;
    using std::sin;
    using std::sqrt;
    T direction[3], radius;
    CameraCentreDirection(x, direction, &radius);
    Eigen::Vector3d e0, e1;
    TangentBasis(direction, &e0, &e1);
    T arc[3];
    for (int i = 0; i < 3; ++i) arc[i] = delta[0] * e0[i] + delta[1] * e1[i];
    const T angle_sq = (arc[0] * arc[0] + arc[1] * arc[1] + arc[2] * arc[2]) / (radius * radius);
    T moved[3];                           // the new unit direction from c0
    if (ScalarValue(angle_sq) < 1e-20) {  // first order, exact derivatives at delta = 0
      for (int i = 0; i < 3; ++i) moved[i] = direction[i] + arc[i] / radius;
    } else {
      const T angle = sqrt(angle_sq);
      const T along = sin(angle) / angle / radius;
      for (int i = 0; i < 3; ++i) moved[i] = cos(angle) * direction[i] + along * arc[i];
    }
    RotateOnTheLeft(x + 3, delta + 2, x_plus_delta + 3);
    T centre_new[3];
    for (int i = 0; i < 3; ++i) centre_new[i] = T(centre_[i]) + radius * moved[i];
    ceres::AngleAxisRotatePoint(x_plus_delta + 3, centre_new, x_plus_delta);
    for (int i = 0; i < 3; ++i) x_plus_delta[i] = -x_plus_delta[i];
    return true;
  }

  template <typename T>
  bool Minus(const T* y, const T* x, T* y_minus_x) const {
    using std::atan2;
    using std::sqrt;
    T direction_x[3], direction_y[3], radius_x, radius_y;
    CameraCentreDirection(x, direction_x, &radius_x);
    CameraCentreDirection(y, direction_y, &radius_y);
    Eigen::Vector3d e0, e1;
    TangentBasis(direction_x, &e0, &e1);
    const T cosine = direction_x[0] * direction_y[0] + direction_x[1] * direction_y[1] +
                     direction_x[2] * direction_y[2];
    T normal[3];  // the part of direction_y normal to direction_x
    for (int i = 0; i < 3; ++i) normal[i] = direction_y[i] - cosine * direction_x[i];
    const T sine_sq = normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2];
    T scale = radius_x;  // arc length per unit of `normal`: r theta / sin(theta)
    if (ScalarValue(sine_sq) > 1e-20) {
      const T sine = sqrt(sine_sq);
      scale = radius_x * atan2(sine, cosine) / sine;
    }
    y_minus_x[0] = scale * (normal[0] * e0[0] + normal[1] * e0[1] + normal[2] * e0[2]);
    y_minus_x[1] = scale * (normal[0] * e1[0] + normal[1] * e1[1] + normal[2] * e1[2]);
    RotationDifference(y + 3, x + 3, y_minus_x + 2);
    return true;
  }

  const Eigen::Vector3d& centre() const { return centre_; }

 private:
  // Unit direction from c0 to the camera centre of pose x, and the distance.
  template <typename T>
  void CameraCentreDirection(const T* x, T* direction, T* radius) const {
    using std::sqrt;
    const T minus_phi[3] = {-x[3], -x[4], -x[5]};
    T rotated[3];  // R^T p
    ceres::AngleAxisRotatePoint(minus_phi, x, rotated);
    T offset[3];
    for (int i = 0; i < 3; ++i) offset[i] = -rotated[i] - T(centre_[i]);
    *radius = sqrt(offset[0] * offset[0] + offset[1] * offset[1] + offset[2] * offset[2]);
    for (int i = 0; i < 3; ++i) direction[i] = offset[i] / *radius;
  }

  // Two unit vectors normal to `direction` and to each other (from its value: a fixed basis
  // of the tangent plane at the current point).
  template <typename T>
  static void TangentBasis(const T* direction, Eigen::Vector3d* e0, Eigen::Vector3d* e1) {
    const Eigen::Vector3d n(ScalarValue(direction[0]), ScalarValue(direction[1]),
                            ScalarValue(direction[2]));
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();
    int least = 0;  // the axis least aligned with n
    n.cwiseAbs().minCoeff(&least);
    axis[least] = 1.0;
    *e0 = n.cross(axis).normalized();
    *e1 = n.cross(*e0);
  }

  Eigen::Vector3d centre_;
};

// The manifold of the scale keyframe's pose; make it with
// `new BaselineManifold(new BaselineManifoldFunctor(c0))`, c0 in the world frame.
using BaselineManifold = ceres::AutoDiffManifold<BaselineManifoldFunctor, 6, 5>;

}  // namespace rscalib::bundle
