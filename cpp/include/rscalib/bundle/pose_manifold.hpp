#pragma once
// The manifold of a keyframe pose [p; phi] (T_cw, geometry/pose.hpp) in the bundle adjustment:
// the translation moves additively and the rotation on the left, R' = exp([dphi]x) R, stored
// back as the rotation vector of R' with |phi'| <= pi (Ceres' quaternion helpers). A step never
// meets the rotation vector's singularity at |phi| = 2 pi, however far a keyframe turns.
//
// Ambient layout (6): [p (m); phi (rad)]; tangent layout (6): [dp (m); dphi (rad)].
#include <ceres/autodiff_manifold.h>
#include <ceres/rotation.h>

namespace rscalib::bundle {

// phi' = log(exp(delta) exp(phi)) as a rotation vector. T: double or ceres::Jet.
template <typename T>
void RotateOnTheLeft(const T* phi, const T* delta, T* phi_out) {
  T q_phi[4], q_delta[4], q_out[4];
  ceres::AngleAxisToQuaternion(phi, q_phi);
  ceres::AngleAxisToQuaternion(delta, q_delta);
  ceres::QuaternionProduct(q_delta, q_phi, q_out);
  ceres::QuaternionToAngleAxis(q_out, phi_out);
}

// log(exp(phi_y) exp(phi_x)^-1) as a rotation vector.
template <typename T>
void RotationDifference(const T* phi_y, const T* phi_x, T* delta) {
  T q_y[4], q_x[4], q_out[4];
  ceres::AngleAxisToQuaternion(phi_y, q_y);
  ceres::AngleAxisToQuaternion(phi_x, q_x);
  const T q_x_inverse[4] = {q_x[0], -q_x[1], -q_x[2], -q_x[3]};
  ceres::QuaternionProduct(q_y, q_x_inverse, q_out);
  ceres::QuaternionToAngleAxis(q_out, delta);
}

struct PoseManifoldFunctor {
  template <typename T>
  bool Plus(const T* x, const T* delta, T* x_plus_delta) const {
    for (int i = 0; i < 3; ++i) x_plus_delta[i] = x[i] + delta[i];
    RotateOnTheLeft(x + 3, delta + 3, x_plus_delta + 3);
    return true;
  }

  template <typename T>
  bool Minus(const T* y, const T* x, T* y_minus_x) const {
    for (int i = 0; i < 3; ++i) y_minus_x[i] = y[i] - x[i];
    RotationDifference(y + 3, x + 3, y_minus_x + 3);
    return true;
  }
};

using PoseManifold = ceres::AutoDiffManifold<PoseManifoldFunctor, 6, 6>;

}  // namespace rscalib::bundle
