// Constant-velocity motion model with analytic Jacobians (docs/sog.md §3).
#include "rscalib/sog/motion_model.hpp"

#include "rscalib/sog/quaternion.hpp"

namespace rscalib::sog {

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

}  // namespace rscalib::sog
