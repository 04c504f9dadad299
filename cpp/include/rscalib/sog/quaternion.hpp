#pragma once
// Hamilton quaternions q = (w, x, y, z), scalar first, as 4-vectors (the EKF keeps them
// unconstrained and renormalises after each update). Templated for double and ceres::Jet.
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace rscalib::sog {

template <typename T>
using Quaternion = Eigen::Matrix<T, 4, 1>;

// p ⊗ q.
template <typename T>
Quaternion<T> QuaternionProduct(const Quaternion<T>& p, const Quaternion<T>& q) {
  Quaternion<T> out;
  out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3];
  out[1] = p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2];
  out[2] = p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1];
  out[3] = p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0];
  return out;
}

// p ⊗ q = QuaternionLeftMatrix(p) q = QuaternionRightMatrix(q) p.
inline Eigen::Matrix4d QuaternionLeftMatrix(const Eigen::Vector4d& p) {
  Eigen::Matrix4d m;
  // clang-format off
  m << p[0], -p[1], -p[2], -p[3],
       p[1], p[0], -p[3], p[2],
       p[2], p[3], p[0], -p[1],
       p[3], -p[2], p[1], p[0];
  // clang-format on
  return m;
}
inline Eigen::Matrix4d QuaternionRightMatrix(const Eigen::Vector4d& q) {
  Eigen::Matrix4d m;
  // clang-format off
  m << q[0], -q[1], -q[2], -q[3],
       q[1], q[0], q[3], -q[2],
       q[2], -q[3], q[0], q[1],
       q[3], q[2], -q[1], q[0];
  // clang-format on
  return m;
}

// R(q) for any q (not normalised: the quadratic form, = |q|^2 x rotation), so that its
// derivative below is the derivative of what the filter evaluates.
template <typename T>
Eigen::Matrix<T, 3, 3> QuaternionToRotation(const Quaternion<T>& q) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix<T, 3, 3> r;
  // clang-format off
  r << w * w + x * x - y * y - z * z, T(2) * (x * y - w * z), T(2) * (x * z + w * y),
       T(2) * (x * y + w * z), w * w - x * x + y * y - z * z, T(2) * (y * z - w * x),
       T(2) * (x * z - w * y), T(2) * (y * z + w * x), w * w - x * x - y * y + z * z;
  // clang-format on
  return r;
}

// d(R(q) a)/dq (transpose = false) or d(R(q)^T a)/dq (transpose = true), 3x4. From
// R(q) a = (w^2 - v.v) a + 2 (v.a) v + 2 w (v x a), v = (x, y, z); R^T flips the last sign.
inline Eigen::Matrix<double, 3, 4> DRotatedDQuaternion(const Eigen::Vector4d& q,
                                                       const Eigen::Vector3d& a, bool transpose) {
  const double w = q[0];
  const Eigen::Vector3d v = q.tail<3>();
  const double s = transpose ? -1.0 : 1.0;
  Eigen::Matrix3d a_cross;
  a_cross << 0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0;
  Eigen::Matrix<double, 3, 4> d;
  d.col(0) = 2.0 * w * a + 2.0 * s * v.cross(a);
  d.rightCols<3>() = -2.0 * a * v.transpose() + 2.0 * v.dot(a) * Eigen::Matrix3d::Identity() +
                     2.0 * v * a.transpose() - 2.0 * s * w * a_cross;
  return d;
}

// Rotation by the vector a (angle |a|) as a unit quaternion, and its derivative d_q_d_a (4x3).
// Series near |a| = 0 keep both smooth.
inline Eigen::Vector4d RotationVectorToQuaternion(const Eigen::Vector3d& a,
                                                  Eigen::Matrix<double, 4, 3>* d_q_d_a = nullptr) {
  const double theta = a.norm();
  // q = (cos(theta/2), s a) with s = sin(theta/2)/theta; ds/dtheta / theta = c3.
  double c, s, s_prime_over_theta;
  if (theta < 1e-4) {
    const double t2 = theta * theta;
    c = 1.0 - t2 / 8.0;
    s = 0.5 - t2 / 48.0;
    s_prime_over_theta = -1.0 / 24.0 + t2 / 960.0;
  } else {
    c = std::cos(0.5 * theta);
    s = std::sin(0.5 * theta) / theta;
    s_prime_over_theta = (0.5 * theta * c - std::sin(0.5 * theta)) / (theta * theta * theta);
  }
  if (d_q_d_a != nullptr) {
    d_q_d_a->row(0) = -0.5 * s * a.transpose();  // d cos(theta/2) = -sin(theta/2)/2 dtheta
    d_q_d_a->bottomRows<3>() =
        s * Eigen::Matrix3d::Identity() + s_prime_over_theta * a * a.transpose();
  }
  return Eigen::Vector4d(c, s * a[0], s * a[1], s * a[2]);
}

}  // namespace rscalib::sog
