#pragma once
// Inverse-depth points (Civera, Davison, Montiel 2008; docs/sog.md §4):
//   y = (x0, y0, z0, theta, phi, rho),  X = (x0, y0, z0) + m(theta, phi) / rho,
//   m = (cos(phi) sin(theta), -sin(phi), cos(phi) cos(theta))  (world frame).
// theta is the azimuth about the world y axis, phi the elevation (up is -y).
#include <cmath>

#include <Eigen/Core>

namespace rscalib::sog {

using InverseDepthPoint = Eigen::Matrix<double, 6, 1>;

template <typename T>
Eigen::Matrix<T, 3, 1> DirectionFromAngles(const T& theta, const T& phi) {
  using std::cos;
  using std::sin;
  return Eigen::Matrix<T, 3, 1>(cos(phi) * sin(theta), -sin(phi), cos(phi) * cos(theta));
}

// dm/dtheta and dm/dphi.
inline Eigen::Vector3d DirectionDTheta(double theta, double phi) {
  return {std::cos(phi) * std::cos(theta), 0.0, -std::cos(phi) * std::sin(theta)};
}
inline Eigen::Vector3d DirectionDPhi(double theta, double phi) {
  return {-std::sin(phi) * std::sin(theta), -std::cos(phi), -std::sin(phi) * std::cos(theta)};
}

// X and d_xyz_d_inverse_depth (3x6).
Eigen::Vector3d InverseDepthToXyz(const InverseDepthPoint& y,
                                  Eigen::Matrix<double, 3, 6>* d_xyz_d_y = nullptr);

// Linearity index L = 4 sigma_d |cos(alpha)| / d (Civera et al. 2008, §VI):
// sigma_d = sigma_rho / rho^2, d = |X - r|, alpha the angle between m and X - r.
// Infinite for rho <= 0 (never linear enough to convert).
double LinearityIndex(const InverseDepthPoint& y, double rho_variance,
                      const Eigen::Vector3d& camera_position);

// A new inverse-depth point from a distorted pixel seen by the camera with calibration
// (f, Cx, Cy, k1, k2), centre r and orientation q_wc, at inverse depth rho0:
// the ray through the undistorted pixel, rotated to the world, as (theta, phi).
// d_y_d_camera (6x12) is w.r.t. [calibration, r, q]; d_y_d_uv (6x2); d y / d rho0 = e_6.
InverseDepthPoint InitialiseInverseDepth(const Eigen::Matrix<double, 12, 1>& camera,
                                         const Eigen::Vector2d& pixel_size_mm,
                                         const Eigen::Vector2d& uv_distorted, double rho0,
                                         Eigen::Matrix<double, 6, 12>* d_y_d_camera = nullptr,
                                         Eigen::Matrix<double, 6, 2>* d_y_d_uv = nullptr);

}  // namespace rscalib::sog
