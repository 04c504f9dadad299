// Measurement of a map feature with analytic Jacobians (docs/sog.md §5).
#include "rscalib/sog/measurement_model.hpp"

#include <Eigen/Dense>

namespace rscalib::sog {

bool ProjectFeatureWithJacobians(const MeasuredCamera& camera, const Eigen::Vector2d& pixel_size_mm,
                                 FeatureKind kind, const double* feature, Eigen::Vector2d* uv,
                                 Eigen::Matrix<double, 2, kMeasuredCameraDim>* d_uv_d_camera,
                                 Eigen::Matrix<double, 2, 6>* d_uv_d_feature) {
  const double f = camera[0];
  const Eigen::Vector2d c(camera[1], camera[2]);
  const double k1 = camera[3], k2 = camera[4];
  const Eigen::Vector3d r = camera.segment<3>(5);
  const Eigen::Vector4d q = camera.segment<4>(8);
  const Eigen::Matrix3d rotation_cw = QuaternionToRotation<double>(q).transpose();

  Eigen::Vector3d a;  // h = R^T a
  double rho = 1.0;
  if (kind == FeatureKind::kInverseDepth) {
    rho = feature[5];
    a = DirectionFromAngles(feature[3], feature[4]) +
        rho * (Eigen::Map<const Eigen::Vector3d>(feature) - r);
  } else {
    a = Eigen::Map<const Eigen::Vector3d>(feature) - r;
  }
  const Eigen::Vector3d h = rotation_cw * a;
  if (!(h[2] > 0.0)) return false;
  const Eigen::Vector2d n(h[0] / h[2], h[1] / h[2]);
  Eigen::Vector2d offset_d;
  Eigen::Matrix2d d_od_d_ou, d_od_d_k;
  const bool want = d_uv_d_camera != nullptr || d_uv_d_feature != nullptr;
  if (!DistortOffset(f * n, k1, k2, pixel_size_mm, &offset_d, want ? &d_od_d_ou : nullptr,
                     want ? &d_od_d_k : nullptr))
    return false;
  *uv = c + offset_d;
  if (!want) return true;

  // uv = C + D(f n(h)): dC -> I, df -> D' n, dk -> D_k, dh -> D' f dn/dh.
  Eigen::Matrix<double, 2, 3> d_n_d_h;
  d_n_d_h << 1.0 / h[2], 0.0, -n[0] / h[2], 0.0, 1.0 / h[2], -n[1] / h[2];
  const Eigen::Matrix<double, 2, 3> d_uv_d_h = f * d_od_d_ou * d_n_d_h;
  if (d_uv_d_camera != nullptr) {
    auto& j = *d_uv_d_camera;
    j.col(0) = d_od_d_ou * n;
    j.block<2, 2>(0, 1).setIdentity();
    j.block<2, 2>(0, 3) = d_od_d_k;
    j.block<2, 3>(0, 5) = -rho * d_uv_d_h * rotation_cw;
    j.block<2, 4>(0, 8) = d_uv_d_h * DRotatedDQuaternion(q, a, /*transpose=*/true);
  }
  if (d_uv_d_feature != nullptr) {
    auto& j = *d_uv_d_feature;
    j.setZero();
    const Eigen::Matrix<double, 2, 3> d_uv_d_a = d_uv_d_h * rotation_cw;
    if (kind == FeatureKind::kInverseDepth) {
      const double theta = feature[3], phi = feature[4];
      j.leftCols<3>() = rho * d_uv_d_a;
      j.col(3) = d_uv_d_a * DirectionDTheta(theta, phi);
      j.col(4) = d_uv_d_a * DirectionDPhi(theta, phi);
      j.col(5) = d_uv_d_a * (Eigen::Map<const Eigen::Vector3d>(feature) - r);
    } else {
      j.leftCols<3>() = d_uv_d_a;
    }
  }
  return true;
}

}  // namespace rscalib::sog
