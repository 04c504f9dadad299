#pragma once
// Constant-velocity camera motion (docs/sog.md §3; Davison's MonoSLAM model used by Civera):
//   r' = r + (v + V) dt,  q' = q ⊗ q((w + W) dt),  v' = v + V,  w' = w + W,
// with the velocity impulses V = a dt, W = alpha dt from accelerations a ~ N(0, sa^2 I),
// alpha ~ N(0, salpha^2 I) held over the step. Operates on the 13-vector [r, q, v, w].
#include <Eigen/Core>

namespace rscalib::sog {

using MotionState = Eigen::Matrix<double, 13, 1>;
using MotionJacobian = Eigen::Matrix<double, 13, 13>;

// x' = f(x, dt), with d_out_d_state (13x13) and d_out_d_impulse (13x6, impulses (V, W)).
MotionState PredictMotion(const MotionState& state, double dt_s,
                          MotionJacobian* d_out_d_state = nullptr,
                          Eigen::Matrix<double, 13, 6>* d_out_d_impulse = nullptr);

// Process noise G diag(sa^2 dt^2 I, salpha^2 dt^2 I) G^T of one step.
Eigen::Matrix<double, 13, 13> MotionProcessNoise(const MotionState& state, double dt_s,
                                                 double accel_sigma, double angular_accel_sigma);

}  // namespace rscalib::sog
