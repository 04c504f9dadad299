#include "scalar_variance.hpp"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <ceres/ceres.h>

namespace rscalib::detail {

std::optional<double> ScalarVariance(ceres::Problem* problem, const double* parameter, int num_threads) {
  ceres::Covariance::Options covariance_options;
  covariance_options.num_threads = std::max(1, num_threads);
  covariance_options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(covariance_options);
  const std::vector<std::pair<const double*, const double*>> blocks = {{parameter, parameter}};
  if (!covariance.Compute(blocks, problem)) return std::nullopt;
  double variance = 0.0;
  covariance.GetCovarianceBlock(parameter, parameter, &variance);
  if (!(variance >= 0.0) || !std::isfinite(variance)) return std::nullopt;
  return variance;
}

}  // namespace rscalib::detail
