#pragma once
// Wald's sequential probability ratio test for pruning Gaussians (docs/sog.md §7; paper
// eq. 14-18, after Stevenson/Montiel's SOG+SPRT): for Gaussian i,
//   L_t(H0) = N(nu_i; 0, S_i),  L_t(H1) = sum_{j != i} w_j N(nu_j; 0, S_j) / sum_{j != i} w_j,
// accept H0 ("keep for good") when prod L(H0)/L(H1) > A = (1 - beta)/alpha, reject it
// (prune) when < B = beta/(1 - alpha). Everything in logs.
#include <cmath>
#include <limits>

#include <Eigen/Core>

namespace rscalib::sog {

struct WaldBoundaries {
  double log_accept;  // log A
  double log_reject;  // log B
};

inline WaldBoundaries MakeWaldBoundaries(double alpha, double beta) {
  return {std::log((1.0 - beta) / alpha), std::log(beta / (1.0 - alpha))};
}

// log L_t(H0)/L_t(H1) for every Gaussian, from the weights before this step (log, any
// normalisation) and this step's log-likelihoods. O(N^2), N is at most a few hundred.
// A single Gaussian has no alternative: its ratio is 0.
inline Eigen::VectorXd SprtLogRatios(const Eigen::VectorXd& log_weights,
                                     const Eigen::VectorXd& log_likelihoods) {
  const Eigen::Index n = log_weights.size();
  Eigen::VectorXd out = Eigen::VectorXd::Zero(n);
  if (n < 2) return out;
  const Eigen::VectorXd joint = log_weights + log_likelihoods;
  const double inf = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < n; ++i) {
    double m_joint = -inf, m_weight = -inf;
    for (Eigen::Index j = 0; j < n; ++j) {
      if (j == i) continue;
      m_joint = std::max(m_joint, joint[j]);
      m_weight = std::max(m_weight, log_weights[j]);
    }
    if (!std::isfinite(m_weight)) continue;  // all alternatives have zero weight
    double s_joint = 0.0, s_weight = 0.0;
    for (Eigen::Index j = 0; j < n; ++j) {
      if (j == i) continue;
      if (std::isfinite(m_joint)) s_joint += std::exp(joint[j] - m_joint);
      s_weight += std::exp(log_weights[j] - m_weight);
    }
    const double log_h1 = (std::isfinite(m_joint) ? m_joint + std::log(s_joint) : -inf) -
                          (m_weight + std::log(s_weight));
    out[i] = log_likelihoods[i] - log_h1;
    if (std::isnan(out[i])) out[i] = -inf;
  }
  return out;
}

}  // namespace rscalib::sog
