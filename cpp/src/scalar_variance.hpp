// Private to the solvers (not installed): the marginal variance of one scalar parameter.
#pragma once

#include <optional>

namespace ceres {
class Problem;
}

namespace rscalib::detail {

// Variance of the 1-D parameter block `parameter` of `problem` at its current value (Ceres'
// Covariance, sparse QR: it copes with the gauge freedoms of a trajectory). nullopt when Ceres
// cannot compute it or the result is not a finite non-negative number.
std::optional<double> ScalarVariance(ceres::Problem* problem, const double* parameter, int num_threads);

}  // namespace rscalib::detail
