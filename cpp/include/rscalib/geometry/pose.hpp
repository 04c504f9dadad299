#pragma once
// Camera pose T_cw = (R, p): x_c = R x_w + p (world = target frame). The trajectory
// state is x = [p; phi] in R^6 (translation first, then rotation vector), docs/conventions.md
// "Frames and poses". A pose at a time of a pose spline: spline/pose_spline.hpp.
#include <Eigen/Core>
#include <ceres/rotation.h>

namespace rscalib::geometry {

constexpr int kPoseStateDim = 6;

struct Pose {
  Eigen::Matrix3d rotation_cw = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation_cw = Eigen::Vector3d::Zero();
};

// x_c = R(phi) x_w + p for a 6-D state [p; phi]. T: double or ceres::Jet.
template <typename T, typename P>
void TransformWorldToCamera(const T* state, const P* point_w, T* point_c) {
  const T point_w_t[3] = {T(point_w[0]), T(point_w[1]), T(point_w[2])};
  ceres::AngleAxisRotatePoint(state + 3, point_w_t, point_c);
  point_c[0] += state[0];
  point_c[1] += state[1];
  point_c[2] += state[2];
}

Pose PoseFromState(const Eigen::Matrix<double, 6, 1>& state);

}  // namespace rscalib::geometry
