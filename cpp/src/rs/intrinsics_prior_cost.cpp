#include "rscalib/rs/intrinsics_prior_cost.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "rscalib/core/error.hpp"

namespace rscalib::rs {

IntrinsicsMatrix IntrinsicsPriorSqrtInformation(const Eigen::MatrixXd& covariance,
                                                const std::vector<int>& fixed) {
  const int n = static_cast<int>(covariance.rows());
  if (covariance.cols() != n || n < 1 || n > kIntrinsicsBlockSize)
    throw InputError(
        "the intrinsics prior covariance must be square, one row per camera parameter");
  if (!covariance.allFinite()) throw InputError("the intrinsics prior covariance is not finite");
  std::vector<bool> is_free(n, true);
  for (int index : fixed) {
    if (index < 0 || index >= n) throw InputError("a fixed intrinsics index is out of range");
    is_free[index] = false;
  }
  std::vector<int> free;
  for (int i = 0; i < n; ++i)
    if (is_free[i]) free.push_back(i);
  IntrinsicsMatrix sqrt_information = IntrinsicsMatrix::Zero();
  if (free.empty()) return sqrt_information;
  const int k = static_cast<int>(free.size());
  Eigen::MatrixXd sub(k, k);
  for (int r = 0; r < k; ++r)
    for (int c = 0; c < k; ++c) sub(r, c) = covariance(free[r], free[c]);
  if ((sub - sub.transpose()).cwiseAbs().maxCoeff() > 1e-9 * sub.cwiseAbs().maxCoeff())
    throw InputError("the intrinsics prior covariance is not symmetric");
  const Eigen::LLT<Eigen::MatrixXd> llt(sub);
  if (llt.info() != Eigen::Success)
    throw InputError("the intrinsics prior covariance is not positive definite");
  const Eigen::MatrixXd lower = llt.matrixL();
  const Eigen::MatrixXd inverse =
      lower.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(k, k));
  for (int r = 0; r < k; ++r)
    for (int c = 0; c < k; ++c) sqrt_information(free[r], free[c]) = inverse(r, c);
  return sqrt_information;
}

}  // namespace rscalib::rs
