#pragma once
// A point in inverse depth anchored in a keyframe (docs/sog.md §23): three unknowns (a, b, rho),
// the point in the anchor camera's frame being (a, b, 1) / rho. Seen from a keyframe j, the
// projection is computed from h = rho x_cj, never dividing by rho:
//   h = R_j R_a^T ((a, b, 1) - rho p_a) + rho p_j
// (poses T_cw = [p; phi], x_c = R(phi) x_w + p; geometry/pose.hpp). Every camera model
// projects h and x_cj = h / rho alike for rho > 0, and h stays finite and smooth through
// rho = 0 (a point at infinity: its direction R_j R_a^T (a, b, 1)), so far points keep a
// well-conditioned Jacobian. In its anchor keyframe h = (a, b, 1): the point's own ray.
#include <Eigen/Core>
#include <ceres/rotation.h>

#include "rscalib/geometry/pose.hpp"

namespace rscalib::bundle {

constexpr int kAnchoredPointDim = 3;  // (a, b, rho): rho in 1/m, a and b unitless

// h = rho x_c of `point` (a, b, rho) anchored in the camera at `anchor_pose`, in the camera at
// `observer_pose` (both [p; phi] T_cw). T: double or ceres::Jet.
template <typename T>
void AnchoredPointInCamera(const T* anchor_pose, const T* observer_pose, const T* point, T* h) {
  const T& rho = point[2];
  const T ray_minus_anchor[3] = {point[0] - rho * anchor_pose[0], point[1] - rho * anchor_pose[1],
                                 T(1.0) - rho * anchor_pose[2]};
  const T world_from_anchor[3] = {-anchor_pose[3], -anchor_pose[4], -anchor_pose[5]};
  T in_world[3];  // rho (x_w - 0): R_a^T ((a, b, 1) - rho p_a)
  ceres::AngleAxisRotatePoint(world_from_anchor, ray_minus_anchor, in_world);
  ceres::AngleAxisRotatePoint(observer_pose + 3, in_world, h);
  h[0] += rho * observer_pose[0];
  h[1] += rho * observer_pose[1];
  h[2] += rho * observer_pose[2];
}

// h in the anchor camera itself: (a, b, 1), whatever rho.
template <typename T>
void AnchoredPointInAnchor(const T* point, T* h) {
  h[0] = point[0];
  h[1] = point[1];
  h[2] = T(1.0);
}

// (a, b, rho) of the world point x_w anchored in the camera at `anchor_pose`; false when the
// point is not in front of that camera (z <= 0).
inline bool AnchoredPointFromWorld(const double* anchor_pose, const Eigen::Vector3d& point_w,
                                   Eigen::Vector3d* point) {
  Eigen::Vector3d point_c;
  geometry::TransformWorldToCamera(anchor_pose, point_w.data(), point_c.data());
  if (!(point_c[2] > 0.0)) return false;
  *point << point_c[0] / point_c[2], point_c[1] / point_c[2], 1.0 / point_c[2];
  return true;
}

// The world point of `point` (a, b, rho) anchored at `anchor_pose`; rho must be non-zero.
inline Eigen::Vector3d WorldPointFromAnchored(const double* anchor_pose,
                                              const Eigen::Vector3d& point) {
  const Eigen::Vector3d point_c = Eigen::Vector3d(point[0], point[1], 1.0) / point[2];
  const double minus_phi[3] = {-anchor_pose[3], -anchor_pose[4], -anchor_pose[5]};
  const Eigen::Vector3d shifted =
      point_c - Eigen::Vector3d(anchor_pose[0], anchor_pose[1], anchor_pose[2]);
  Eigen::Vector3d point_w;
  ceres::AngleAxisRotatePoint(minus_phi, shifted.data(), point_w.data());
  return point_w;
}

}  // namespace rscalib::bundle
