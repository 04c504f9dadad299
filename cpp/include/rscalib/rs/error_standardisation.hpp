#pragma once
// Error standardisation (Oth et al. 2013 §3.5, eq. 15-21; docs/formulation.md §4).
// Noise n ~ N(0, R) on the measurement y = (u, v) also moves the observation time through
// v, so the error is
//   e ~ e_bar + A n,   A = I - d [[0, u_dot], [0, v_dot]],
// (u_dot, v_dot) = d/dt pi(T_cw(t) P) at t = t_i + v d. Cov(e) = A R A^T; its inverse
// square root weights the residual. det A = 1 - d v_dot -> 0 when the point moves down
// the image as fast as the shutter scans: clamp that gain.
#include <Eigen/Core>

namespace rscalib::rs {

// A for line delay d (s/row) and image velocity (u_dot, v_dot) in px/s.
Eigen::Matrix2d ErrorNoiseMap(double line_delay_s, const Eigen::Vector2d& image_velocity_px_s);

struct StandardisationWeight {
  Eigen::Matrix2d sqrt_information;  // W with W^T W = (A R A^T)^{-1}, R = sigma^2 I
  bool clamped = false;              // d * v_dot was limited to max_rs_gain
};

// max_rs_gain < 1 bounds d * v_dot (so det A >= 1 - max_rs_gain).
StandardisationWeight ComputeStandardisationWeight(double line_delay_s,
                                                   const Eigen::Vector2d& image_velocity_px_s,
                                                   double pixel_sigma, double max_rs_gain);

}  // namespace rscalib::rs
