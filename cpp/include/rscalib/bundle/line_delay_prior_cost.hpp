#pragma once
// A Gaussian prior on the line delay (e.g. a `rscalib linedelay` result, mean and sigma), in the
// units of the pixel residuals (docs/sog.md §23): the negative log-likelihood
//   1/(2 s^2) sum |r_px|^2 + 1/2 ((d - mean) / sigma)^2
// times s^2 (s: the pixel noise, px) is 1/2 sum |r_px|^2 + 1/2 r^2 with
//   r = s (d - mean) / sigma.
//
// Parameter block: line_delay : 1, d in microseconds per row (as reprojection_cost.hpp).
#include <ceres/autodiff_cost_function.h>

namespace rscalib::bundle {

struct LineDelayPriorCost {
  LineDelayPriorCost(double mean_us, double sigma_us, double pixel_sigma_px)
      : mean_us_(mean_us), weight_(pixel_sigma_px / sigma_us) {}

  template <typename T>
  bool operator()(const T* line_delay_us, T* residual) const {
    residual[0] = weight_ * (line_delay_us[0] - mean_us_);
    return true;
  }

  // d r / d d (px per µs/row).
  double weight() const { return weight_; }

  static ceres::CostFunction* Create(double mean_us, double sigma_us, double pixel_sigma_px) {
    return new ceres::AutoDiffCostFunction<LineDelayPriorCost, 1, 1>(
        new LineDelayPriorCost(mean_us, sigma_us, pixel_sigma_px));
  }

 private:
  double mean_us_;
  double weight_;
};

}  // namespace rscalib::bundle
