// Inverse-depth points with analytic Jacobians (docs/sog.md §4; Civera et al. 2008).
#include "rscalib/sog/inverse_depth.hpp"

#include <cmath>
#include <limits>

#include "rscalib/sog/quaternion.hpp"
#include "rscalib/sog/radial_distortion.hpp"

namespace rscalib::sog {

Eigen::Vector3d InverseDepthToXyz(const InverseDepthPoint& y,
                                  Eigen::Matrix<double, 3, 6>* d_xyz_d_y) {
  const double theta = y[3], phi = y[4], rho = y[5];
  const Eigen::Vector3d m = DirectionFromAngles(theta, phi);
  if (d_xyz_d_y != nullptr) {
    d_xyz_d_y->leftCols<3>().setIdentity();
    d_xyz_d_y->col(3) = DirectionDTheta(theta, phi) / rho;
    d_xyz_d_y->col(4) = DirectionDPhi(theta, phi) / rho;
    d_xyz_d_y->col(5) = -m / (rho * rho);
  }
  return y.head<3>() + m / rho;
}

double LinearityIndex(const InverseDepthPoint& y, double rho_variance,
                      const Eigen::Vector3d& camera_position) {
  const double rho = y[5];
  if (!(rho > 0.0) || !(rho_variance >= 0.0)) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d m = DirectionFromAngles(y[3], y[4]);
  const Eigen::Vector3d to_point = y.head<3>() + m / rho - camera_position;
  const double d = to_point.norm();
  if (!(d > 0.0)) return std::numeric_limits<double>::infinity();
  const double sigma_d = std::sqrt(rho_variance) / (rho * rho);
  const double cos_alpha = m.dot(to_point) / d;
  return 4.0 * sigma_d * std::abs(cos_alpha) / d;
}

InverseDepthPoint InitialiseInverseDepth(const Eigen::Matrix<double, 12, 1>& camera,
                                         const Eigen::Vector2d& pixel_size_mm,
                                         const Eigen::Vector2d& uv_distorted, double rho0,
                                         Eigen::Matrix<double, 6, 12>* d_y_d_camera,
                                         Eigen::Matrix<double, 6, 2>* d_y_d_uv) {
  const double f = camera[0];
  const Eigen::Vector2d c(camera[1], camera[2]);
  const double k1 = camera[3], k2 = camera[4];
  const Eigen::Vector4d q = camera.segment<4>(8);
  const Eigen::Vector2d offset_d = uv_distorted - c;
  const Eigen::Vector2d scaled = pixel_size_mm.cwiseProduct(offset_d);
  const double rd2 = scaled.squaredNorm();
  const Eigen::Vector2d offset_u = offset_d * (1.0 + rd2 * (k1 + k2 * rd2));
  const Eigen::Vector3d ray_c(offset_u[0] / f, offset_u[1] / f, 1.0);
  const Eigen::Vector3d h = QuaternionToRotation<double>(q) * ray_c;
  const double xz2 = h[0] * h[0] + h[2] * h[2];
  const double xz = std::sqrt(xz2);
  InverseDepthPoint y;
  y.head<3>() = camera.segment<3>(5);
  y[3] = std::atan2(h[0], h[2]);
  y[4] = std::atan2(-h[1], xz);
  y[5] = rho0;
  if (d_y_d_camera == nullptr && d_y_d_uv == nullptr) return y;

  const double h2 = xz2 + h[1] * h[1];
  Eigen::Matrix<double, 2, 3> d_angles_d_h;
  // clang-format off
  d_angles_d_h << h[2] / xz2, 0.0, -h[0] / xz2,
                  h[0] * h[1] / (xz * h2), -xz / h2, h[2] * h[1] / (xz * h2);
  // clang-format on
  const Eigen::Matrix<double, 2, 3> d_angles_d_ray = d_angles_d_h * QuaternionToRotation<double>(q);
  // ray = ((U(uv_d - C) ) / f, 1): only its first two entries vary.
  Eigen::Matrix2d d_u_d_offset, d_u_d_k;
  UndistortOffsetJacobians(offset_d, k1, k2, pixel_size_mm, &d_u_d_offset, &d_u_d_k);
  const Eigen::Matrix2d d_angles_d_n = d_angles_d_ray.leftCols<2>();
  if (d_y_d_camera != nullptr) {
    auto& j = *d_y_d_camera;
    j.setZero();
    j.block<3, 3>(0, 5).setIdentity();
    j.block<2, 1>(3, 0) = d_angles_d_n * (-offset_u / (f * f));
    j.block<2, 2>(3, 1) = d_angles_d_n * (-d_u_d_offset / f);
    j.block<2, 2>(3, 3) = d_angles_d_n * (d_u_d_k / f);
    j.block<2, 4>(3, 8) = d_angles_d_h * DRotatedDQuaternion(q, ray_c, /*transpose=*/false);
  }
  if (d_y_d_uv != nullptr) {
    d_y_d_uv->setZero();
    d_y_d_uv->block<2, 2>(3, 0) = d_angles_d_n * (d_u_d_offset / f);
  }
  return y;
}

}  // namespace rscalib::sog
