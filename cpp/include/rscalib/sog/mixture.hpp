#pragma once
// Sum-of-Gaussians arithmetic (docs/sog.md §6; paper eq. 1, 2, 5), in log space: the
// stacked innovations have hundreds of dimensions, so N(nu; 0, S) and det S over- or
// underflow a double long before their ratios do.
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

namespace rscalib::sog {

// log N(nu; 0, S) from the Cholesky factor of S; false if S is not positive definite.
template <typename Vector, typename Matrix>
bool LogGaussianDensity(const Vector& nu, const Matrix& s, double* log_density) {
  const Eigen::Index n = nu.size();
  if (n == 0) {
    *log_density = 0.0;
    return true;
  }
  Eigen::LLT<Eigen::MatrixXd> llt(s);
  if (llt.info() != Eigen::Success) return false;
  const Eigen::VectorXd white = llt.matrixL().solve(Eigen::VectorXd(nu));
  const double log_det = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
  *log_density = -0.5 * (white.squaredNorm() + log_det + double(n) * std::log(2.0 * M_PI));
  return std::isfinite(*log_density);
}

// log(sum exp(a)); -inf for an empty or all -inf input.
inline double LogSumExp(const Eigen::VectorXd& a) {
  if (a.size() == 0) return -std::numeric_limits<double>::infinity();
  const double m = a.maxCoeff();
  if (!std::isfinite(m)) return m;
  return m + std::log((a.array() - m).exp().sum());
}

// Paper eq. 2 in logs: log w_i + log N_i, normalised so that sum exp = 1.
inline Eigen::VectorXd UpdateLogWeights(const Eigen::VectorXd& log_weights,
                                        const Eigen::VectorXd& log_likelihoods) {
  Eigen::VectorXd out = log_weights + log_likelihoods;
  for (Eigen::Index i = 0; i < out.size(); ++i)
    if (std::isnan(out[i])) out[i] = -std::numeric_limits<double>::infinity();
  return out.array() - LogSumExp(out);
}

// Moment matching (paper eq. 5): mean = sum w_i m_i, cov = sum w_i (P_i + (m_i - mean)(.)^T).
// Weights need not be normalised; zero total weight gives NaN.
template <int Dim>
void MergeGaussians(const std::vector<double>& weights,
                    const std::vector<Eigen::Matrix<double, Dim, 1>>& means,
                    const std::vector<Eigen::Matrix<double, Dim, Dim>>& covariances,
                    Eigen::Matrix<double, Dim, 1>* mean,
                    Eigen::Matrix<double, Dim, Dim>* covariance) {
  const Eigen::Index dim = means.empty() ? 0 : means[0].size();
  double total = 0.0;
  mean->setZero(dim);
  for (size_t i = 0; i < means.size(); ++i) {
    total += weights[i];
    *mean += weights[i] * means[i];
  }
  *mean /= total;
  covariance->setZero(dim, dim);
  for (size_t i = 0; i < means.size(); ++i) {
    const Eigen::Matrix<double, Dim, 1> d = means[i] - *mean;
    *covariance += weights[i] * (covariances[i] + d * d.transpose());
  }
  *covariance /= total;
}

}  // namespace rscalib::sog
