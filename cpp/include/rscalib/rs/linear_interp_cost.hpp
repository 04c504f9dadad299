#pragma once
// Baseline rolling-shutter trajectory (Hedborg et al. 2012): one pose per frame, and
// between the poses of two consecutive frames a, b the camera centre moves linearly and
// the rotation along the geodesic (SLERP):
//   s    = (t - t_a) / (t_b - t_a),           t = t_k + v d (k: the observation's frame)
//   R(s) = R_a Exp(s Log(R_a^T R_b)),         c(s) = (1 - s) c_a + s c_b,  c = -R^T p
//   x_c  = R(s) (x_w - c(s))                  (T_cw as everywhere: x_c = R x_w + p)
// Interpolating the centre, not p, makes the model independent of where the world origin
// is. s may leave [0, 1] slightly (chain ends, or d moving across 0): the same formulas
// extrapolate smoothly. Rotations go through unit quaternions, whose Log
// (ceres::QuaternionToAngleAxis) is Jet-safe at the identity and takes the short way.
//
// Residual: r = W (y - pi(T_cw(t) P)), W = I / sigma for the plain baseline (or the
// A R A^T standardisation of the spline model, error_standardisation.hpp).
//
// Parameter blocks:
//   pose_a     : 6, T_cw of frame a at its row-0 time t_a, [p; phi]
//   pose_b     : 6, T_cw of frame b = a + 1 (next frame of the same chain), [p; phi]
//   line_delay : 1, d in seconds per row
#include <Eigen/Core>
#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "rscalib/rs/rs_projection.hpp"

namespace rscalib::rs {

// Rotation (unit quaternion [w, x, y, z], camera-from-world) and camera centre (world) at
// interpolation parameter s between two [p; phi] poses.
template <typename T>
void InterpolatePoseLinear(const T* pose_a, const T* pose_b, const T& s, T* quaternion_cw,
                           T* centre_w) {
  T q_a[4], q_b[4];
  ceres::AngleAxisToQuaternion(pose_a + 3, q_a);
  ceres::AngleAxisToQuaternion(pose_b + 3, q_b);
  // Centres c = -R^T p (R^T p: p rotated by the conjugate quaternion).
  const T q_a_conj[4] = {q_a[0], -q_a[1], -q_a[2], -q_a[3]};
  const T q_b_conj[4] = {q_b[0], -q_b[1], -q_b[2], -q_b[3]};
  T rt_p_a[3], rt_p_b[3];
  ceres::UnitQuaternionRotatePoint(q_a_conj, pose_a, rt_p_a);
  ceres::UnitQuaternionRotatePoint(q_b_conj, pose_b, rt_p_b);
  for (int i = 0; i < 3; ++i) centre_w[i] = -((T(1.0) - s) * rt_p_a[i] + s * rt_p_b[i]);
  // q_rel ~ R_a^T R_b; its rotation vector is the shortest one (angle in [-pi, pi]).
  T q_rel[4], omega[3];
  ceres::QuaternionProduct(q_a_conj, q_b, q_rel);
  ceres::QuaternionToAngleAxis(q_rel, omega);
  const T s_omega[3] = {s * omega[0], s * omega[1], s * omega[2]};
  T q_s[4];
  ceres::AngleAxisToQuaternion(s_omega, q_s);
  ceres::QuaternionProduct(q_a, q_s, quaternion_cw);
}

// The interpolated pose as a [p; phi] state (|phi| <= pi).
template <typename T>
void InterpolatePoseStateLinear(const T* pose_a, const T* pose_b, const T& s, T* state) {
  T q[4], centre[3];
  InterpolatePoseLinear(pose_a, pose_b, s, q, centre);
  ceres::UnitQuaternionRotatePoint(q, centre, state);
  for (int i = 0; i < 3; ++i) state[i] = -state[i];
  ceres::QuaternionToAngleAxis(q, state + 3);
}

// uv = pi(T_cw(s) P). False if the point cannot be projected.
template <typename T>
bool ProjectLinearInterp(const SpanCamera& cam, const double* point_w, const T* pose_a,
                         const T* pose_b, const T& s, T* uv) {
  T q[4], centre[3];
  InterpolatePoseLinear(pose_a, pose_b, s, q, centre);
  const T relative[3] = {T(point_w[0]) - centre[0], T(point_w[1]) - centre[1],
                         T(point_w[2]) - centre[2]};
  T point_c[3];
  ceres::UnitQuaternionRotatePoint(q, relative, point_c);
  return cam.Project(point_c, uv);
}

struct LinearInterpCost {
  // frame_offset_s = t_k - t_a (0 when the observation's frame is a, t_b - t_a when it is b);
  // interval_s = t_b - t_a > 0.
  LinearInterpCost(const SpanCamera& cam, double frame_offset_s, double interval_s,
                   const double* uv_measured, const double* point_w,
                   const Eigen::Matrix2d& sqrt_information)
      : cam_(cam),
        frame_offset_s_(frame_offset_s),
        inverse_interval_per_s_(1.0 / interval_s),
        measurement_(uv_measured, point_w, sqrt_information) {}

  template <typename T>
  bool operator()(const T* pose_a, const T* pose_b, const T* line_delay, T* residual) const {
    const T s =
        (T(frame_offset_s_) + T(measurement_.uv[1]) * line_delay[0]) * inverse_interval_per_s_;
    T uv[2];
    if (!ProjectLinearInterp(cam_, measurement_.point_w, pose_a, pose_b, s, uv)) return false;
    measurement_.Residual(uv, residual);
    return true;
  }

  static ceres::CostFunction* Create(const SpanCamera& cam, double frame_offset_s,
                                     double interval_s, const double* uv_measured,
                                     const double* point_w,
                                     const Eigen::Matrix2d& sqrt_information) {
    return new ceres::AutoDiffCostFunction<LinearInterpCost, 2, 6, 6, 1>(new LinearInterpCost(
        cam, frame_offset_s, interval_s, uv_measured, point_w, sqrt_information));
  }

 private:
  SpanCamera cam_;
  double frame_offset_s_;
  double inverse_interval_per_s_;
  WeightedMeasurement measurement_;
};

}  // namespace rscalib::rs
