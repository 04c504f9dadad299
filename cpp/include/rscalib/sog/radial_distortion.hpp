#pragma once
// civera-radial distortion (camera/civera_radial.hpp) of an offset from the principal point,
// with the analytic Jacobians the SOG EKF needs (docs/formulation.md §10).
#include <Eigen/Core>

namespace rscalib::sog {

// Pure distortion of an undistorted offset from the principal point, uv_d - C = D(uv_u - C):
// returns false when not invertible. d_offset_d_offset (2x2) and d_offset_d_k (2x2, k1 k2) by
// the implicit function theorem on the closed-form undistortion.
bool DistortOffset(const Eigen::Vector2d& offset_u, double k1, double k2,
                   const Eigen::Vector2d& pixel_size_mm, Eigen::Vector2d* offset_d,
                   Eigen::Matrix2d* d_offset_d_offset = nullptr,
                   Eigen::Matrix2d* d_offset_d_k = nullptr);

// Jacobians of the closed-form undistortion U(delta_d) = delta_d (1 + k1 rd^2 + k2 rd^4)
// w.r.t. the distorted offset (2x2) and (k1, k2) (2x2).
void UndistortOffsetJacobians(const Eigen::Vector2d& offset_d, double k1, double k2,
                              const Eigen::Vector2d& pixel_size_mm, Eigen::Matrix2d* d_u_d_offset,
                              Eigen::Matrix2d* d_u_d_k);

}  // namespace rscalib::sog
