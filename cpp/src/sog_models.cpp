// Models of the SOG self-calibration EKF with analytic Jacobians: constant-velocity motion,
// inverse-depth points, civera-radial projection of map features (docs/sog.md §3-5).
#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "rscalib/camera/civera_radial.hpp"
#include "rscalib/sog/inverse_depth.hpp"
#include "rscalib/sog/measurement_model.hpp"
#include "rscalib/sog/motion_model.hpp"
#include "rscalib/sog/quaternion.hpp"

namespace rscalib::sog {

// ------------------------------------------------------------------------------ motion model

MotionState PredictMotion(const MotionState& state, double dt_s, MotionJacobian* d_out_d_state,
                          Eigen::Matrix<double, 13, 6>* d_out_d_impulse) {
  const Eigen::Vector3d r = state.segment<3>(0);
  const Eigen::Vector4d q = state.segment<4>(3);
  const Eigen::Vector3d v = state.segment<3>(7);
  const Eigen::Vector3d w = state.segment<3>(10);
  Eigen::Matrix<double, 4, 3> d_dq_d_a;
  const Eigen::Vector4d dq = RotationVectorToQuaternion(w * dt_s, &d_dq_d_a);
  MotionState out;
  out.segment<3>(0) = r + v * dt_s;
  out.segment<4>(3) = QuaternionProduct<double>(q, dq);
  out.segment<3>(7) = v;
  out.segment<3>(10) = w;
  // q' depends on w (and the impulse W) through a = (w + W) dt.
  const Eigen::Matrix<double, 4, 3> d_q_d_w = QuaternionLeftMatrix(q) * d_dq_d_a * dt_s;
  if (d_out_d_state != nullptr) {
    MotionJacobian& f = *d_out_d_state;
    f.setIdentity();
    f.block<3, 3>(0, 7) = dt_s * Eigen::Matrix3d::Identity();
    f.block<4, 4>(3, 3) = QuaternionRightMatrix(dq);
    f.block<4, 3>(3, 10) = d_q_d_w;
  }
  if (d_out_d_impulse != nullptr) {
    Eigen::Matrix<double, 13, 6>& g = *d_out_d_impulse;
    g.setZero();
    g.block<3, 3>(0, 0) = dt_s * Eigen::Matrix3d::Identity();
    g.block<4, 3>(3, 3) = d_q_d_w;
    g.block<3, 3>(7, 0).setIdentity();
    g.block<3, 3>(10, 3).setIdentity();
  }
  return out;
}

Eigen::Matrix<double, 13, 13> MotionProcessNoise(const MotionState& state, double dt_s,
                                                 double accel_sigma, double angular_accel_sigma) {
  Eigen::Matrix<double, 13, 6> g;
  PredictMotion(state, dt_s, nullptr, &g);
  Eigen::Matrix<double, 6, 1> impulse_variance;
  impulse_variance << Eigen::Vector3d::Constant(accel_sigma * accel_sigma * dt_s * dt_s),
      Eigen::Vector3d::Constant(angular_accel_sigma * angular_accel_sigma * dt_s * dt_s);
  return g * impulse_variance.asDiagonal() * g.transpose();
}

// ---------------------------------------------------------------------------- inverse depth

namespace {

Eigen::Vector3d DDirectionDTheta(double theta, double phi) {
  return {std::cos(phi) * std::cos(theta), 0.0, -std::cos(phi) * std::sin(theta)};
}
Eigen::Vector3d DDirectionDPhi(double theta, double phi) {
  return {-std::sin(phi) * std::sin(theta), -std::cos(phi), -std::sin(phi) * std::cos(theta)};
}

}  // namespace

Eigen::Vector3d InverseDepthToXyz(const InverseDepthPoint& y, Eigen::Matrix<double, 3, 6>* d_xyz_d_y) {
  const double theta = y[3], phi = y[4], rho = y[5];
  const Eigen::Vector3d m = DirectionFromAngles(theta, phi);
  if (d_xyz_d_y != nullptr) {
    d_xyz_d_y->leftCols<3>().setIdentity();
    d_xyz_d_y->col(3) = DDirectionDTheta(theta, phi) / rho;
    d_xyz_d_y->col(4) = DDirectionDPhi(theta, phi) / rho;
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

// ------------------------------------------------------------------------------ distortion

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

// ----------------------------------------------------------------------------- measurement

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
      j.col(3) = d_uv_d_a * DDirectionDTheta(theta, phi);
      j.col(4) = d_uv_d_a * DDirectionDPhi(theta, phi);
      j.col(5) = d_uv_d_a * (Eigen::Map<const Eigen::Vector3d>(feature) - r);
    } else {
      j.leftCols<3>() = d_uv_d_a;
    }
  }
  return true;
}

// ---------------------------------------------------------------- inverse-depth initialisation

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
  d_angles_d_h << h[2] / xz2, 0.0, -h[0] / xz2,
                  h[0] * h[1] / (xz * h2), -xz / h2, h[2] * h[1] / (xz * h2);
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
