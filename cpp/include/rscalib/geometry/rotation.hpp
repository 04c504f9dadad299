#pragma once
// Rotation-vector helpers. A rotation vector phi = angle * axis (radians).
#include <Eigen/Core>
#include <ceres/rotation.h>

namespace rscalib::geometry {

// R = exp([phi]x), safe at phi -> 0 for double and ceres::Jet (Ceres' Rodrigues).
template <typename T>
Eigen::Matrix<T, 3, 3> RotationVectorToMatrix(const T* phi) {
  Eigen::Matrix<T, 3, 3> rotation;
  ceres::AngleAxisToRotationMatrix(phi, ceres::ColumnMajorAdapter3x3(rotation.data()));
  return rotation;
}

// Inverse of RotationVectorToMatrix for double (angle in [0, pi]).
Eigen::Vector3d RotationMatrixToVector(const Eigen::Matrix3d& rotation);

// Paper eq. 22: rotation vectors are defined modulo 2*pi along their axis. Replace each
// sample k > 0 by v * (theta + 2*pi*m) / theta with the integer m that puts it nearest
// to the (already unwrapped) sample k-1, so a spline through them has no jumps.
// rotation_vectors: count x 3, rows are samples in time order.
Eigen::MatrixX3d UnwrapRotationVectors(const Eigen::MatrixX3d& rotation_vectors);

}  // namespace rscalib::geometry
