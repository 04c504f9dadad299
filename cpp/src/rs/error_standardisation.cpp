#include "rscalib/rs/error_standardisation.hpp"

namespace rscalib::rs {

Eigen::Matrix2d ErrorNoiseMap(double line_delay_s, const Eigen::Vector2d& image_velocity_px_s) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Identity();
  a(0, 1) = -line_delay_s * image_velocity_px_s[0];
  a(1, 1) = 1.0 - line_delay_s * image_velocity_px_s[1];
  return a;
}

StandardisationWeight ComputeStandardisationWeight(double line_delay_s,
                                                   const Eigen::Vector2d& image_velocity_px_s,
                                                   double pixel_sigma, double max_rs_gain) {
  StandardisationWeight out;
  double gain = line_delay_s * image_velocity_px_s[1];  // d * v_dot
  if (gain > max_rs_gain) {
    gain = max_rs_gain;
    out.clamped = true;
  }
  // W = A^{-1} / sigma, A = [[1, -d u_dot], [0, 1 - d v_dot]].
  const double det = 1.0 - gain;
  out.sqrt_information << 1.0, line_delay_s * image_velocity_px_s[0] / det, 0.0, 1.0 / det;
  out.sqrt_information /= pixel_sigma;
  return out;
}

}  // namespace rscalib::rs
