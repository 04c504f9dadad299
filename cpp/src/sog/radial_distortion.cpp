// civera-radial distortion of an offset from the principal point, with analytic Jacobians
// (docs/formulation.md §10).
#include "rscalib/sog/radial_distortion.hpp"

#include <Eigen/Dense>

#include "rscalib/camera/civera_radial.hpp"

namespace rscalib::sog {

void UndistortOffsetJacobians(const Eigen::Vector2d& offset_d, double k1, double k2,
                              const Eigen::Vector2d& pixel_size_mm, Eigen::Matrix2d* d_u_d_offset,
                              Eigen::Matrix2d* d_u_d_k) {
  const Eigen::Vector2d scaled = pixel_size_mm.cwiseProduct(offset_d);
  const double rd2 = scaled.squaredNorm();
  const double g = 1.0 + rd2 * (k1 + k2 * rd2);
  const double dg_drd2 = k1 + 2.0 * k2 * rd2;
  if (d_u_d_offset != nullptr) {
    // U = delta g(rd^2), d rd^2 / d delta = 2 (dx^2 delta_u, dy^2 delta_v).
    const Eigen::Vector2d d_rd2 = 2.0 * pixel_size_mm.cwiseProduct(scaled);
    *d_u_d_offset = g * Eigen::Matrix2d::Identity() + dg_drd2 * offset_d * d_rd2.transpose();
  }
  if (d_u_d_k != nullptr) {
    d_u_d_k->col(0) = offset_d * rd2;
    d_u_d_k->col(1) = offset_d * rd2 * rd2;
  }
}

bool DistortOffset(const Eigen::Vector2d& offset_u, double k1, double k2,
                   const Eigen::Vector2d& pixel_size_mm, Eigen::Vector2d* offset_d,
                   Eigen::Matrix2d* d_offset_d_offset, Eigen::Matrix2d* d_offset_d_k) {
  const double ru = pixel_size_mm.cwiseProduct(offset_u).norm();
  if (ru < 1e-300) {
    *offset_d = offset_u;
  } else {
    double rd = 0.0;
    if (!camera::CiveraRadial::SolveDistortedRadius(k1, k2, ru, &rd)) return false;
    *offset_d = offset_u * (rd / ru);
  }
  if (d_offset_d_offset == nullptr && d_offset_d_k == nullptr) return true;
  // Implicit function theorem on U(offset_d, k) = offset_u.
  Eigen::Matrix2d d_u_d_offset, d_u_d_k;
  UndistortOffsetJacobians(*offset_d, k1, k2, pixel_size_mm, &d_u_d_offset, &d_u_d_k);
  const Eigen::Matrix2d inverse = d_u_d_offset.inverse();
  if (d_offset_d_offset != nullptr) *d_offset_d_offset = inverse;
  if (d_offset_d_k != nullptr) *d_offset_d_k = -inverse * d_u_d_k;
  return true;
}

}  // namespace rscalib::sog
