// Private to the two line-delay solvers (not installed): what the spline solver
// (line_delay_solver.cpp) and the linear baseline (linear_interp_solver.cpp) share.
//   - input checks of the options both have,
//   - the weighted error of one observation at the current estimate (docs/formulation.md §4),
//   - the statistics of those errors in a summary,
//   - the outer loop: re-linearise, rebuild the Ceres problem, solve, until nothing changes
//     (docs/formulation.md §3, §6), then the marginal standard deviation of d.
// The Ceres cost functors are not instantiated here (each solver's own translation unit).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <ceres/ceres.h>

#include "rscalib/core/solver_settings.hpp"

namespace rscalib::rs::detail {

// ------------------------------------------------------------------------------ options

// Throws InputError unless pixel_sigma > 0 and max_rs_gain is in (0, 1).
void ValidateNoiseOptions(double pixel_sigma, double max_rs_gain);
// Throws InputError unless the name is none, huber or cauchy.
void ValidateRobustLoss(const std::string& robust_loss);

// The options of the outer loop and of each Ceres solve.
struct SolveSettings {
  ceres::Solver::Options solver;  // max_num_iterations <= 0: build + covariance only
  std::string robust_loss;        // none | huber | cauchy, of the measurement errors
  double robust_loss_scale;       // in standardised units (sigmas)
  int max_outer_iterations;
  int num_threads;  // also of the covariance
  bool estimate_line_delay;
  bool compute_covariance;
  // Stop only once d has settled too (when the weights or the attachment depend on d).
  bool wait_for_line_delay;
  // Start of the InputError thrown when Ceres reports a failure.
  std::string failure_message;
  // Optional: further parameter blocks (pointer, ambient size) whose covariance with d is
  // wanted (SolveResult::joint_covariance). Empty: only the variance of d (the default path).
  std::vector<std::pair<const double*, int>> joint_covariance_blocks;
  // The variance of d from the Schur complement of the normal equations (no robust loss, no
  // joint blocks), Ceres' covariance when that is not possible. false: Ceres' covariance.
  bool schur_variance = false;
  // Optional, with schur_variance: which observations (rows 2k, 2k + 1 of the block's residual
  // are observation k of the list) each measurement block holds, filled by AddResiduals; then
  // SolveResult::line_delay_score holds each observation's score for d (SchurVariance).
  const std::unordered_map<ceres::ResidualBlockId, std::vector<int>>* block_observations = nullptr;
  int num_observations = 0;
};

// From the options both solvers have (RsSolverOptions, LinearInterpOptions): DOGLEG on
// sparse normal equations (CHOLMOD when SuiteSparse is there), their tolerances.
template <typename Options>
SolveSettings MakeSolveSettings(const Options& options, bool wait_for_line_delay,
                                const std::string& failure_message) {
  SolveSettings s;
  s.solver.trust_region_strategy_type = ceres::DOGLEG;
  s.solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  s.solver.sparse_linear_algebra_library_type = SparseLibrary();
  SetStopAndLogging(options, &s.solver);
  s.robust_loss = options.robust_loss;
  s.robust_loss_scale = options.robust_loss_scale;
  s.max_outer_iterations = options.max_outer_iterations;
  s.num_threads = options.num_threads;
  s.estimate_line_delay = options.estimate_line_delay;
  s.compute_covariance = options.compute_covariance;
  s.wait_for_line_delay = wait_for_line_delay;
  s.failure_message = failure_message;
  return s;
}

// --------------------------------------------------------------------- weighted errors

// One observation's error e = y - pi(...) at the current estimate and its weight W.
struct WeightedError {
  bool ok = false;  // projectable at the current estimate
  bool clamped = false;
  Eigen::Matrix2d sqrt_information = Eigen::Matrix2d::Identity();
  Eigen::Vector2d residual_px = Eigen::Vector2d::Zero();
  Eigen::Vector2d image_velocity_px_s = Eigen::Vector2d::Zero();  // d(uv)/dt, for A and the report
  double time_s = 0.0;
};

// Sets ok (uv finite), the raw error and W: A^{-1} / sigma with A from the image velocity
// (px/s) when standardising, else I / sigma. `error` keeps ok = false when uv is not finite.
void SetWeightedError(const Eigen::Vector2d& measured_uv, const Eigen::Vector2d& predicted_uv,
                      const Eigen::Vector2d& image_velocity_px_s, double line_delay_s,
                      bool standardise_errors, double pixel_sigma, double max_rs_gain,
                      WeightedError* error);

// Per-observation outputs and totals both summaries have. `Summary` has residual_px,
// image_velocity_px_s, standardised_sq, observation_time_s, measurement_cost, num_error_terms,
// clamped_weights and rms_px. Rows of errors that are not ok are NaN and not counted.
template <typename Summary>
void FillErrorStatistics(const std::vector<const WeightedError*>& errors, Summary* summary) {
  const Eigen::Index m = static_cast<Eigen::Index>(errors.size());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  summary->residual_px.resize(m, 2);
  summary->image_velocity_px_s.resize(m, 2);
  summary->standardised_sq.resize(m);
  summary->observation_time_s.resize(m);
  summary->measurement_cost = 0.0;
  summary->num_error_terms = 0;
  summary->clamped_weights = 0;
  double sum_sq_px = 0.0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const WeightedError& e = *errors[i];
    summary->observation_time_s[i] = e.time_s;
    if (!e.ok) {
      summary->residual_px.row(i).setConstant(nan);
      summary->image_velocity_px_s.row(i).setConstant(nan);
      summary->standardised_sq[i] = nan;
      continue;
    }
    summary->clamped_weights += e.clamped;
    const double sq = (e.sqrt_information * e.residual_px).squaredNorm();
    summary->residual_px.row(i) = e.residual_px.transpose();
    summary->image_velocity_px_s.row(i) = e.image_velocity_px_s.transpose();
    summary->standardised_sq[i] = sq;
    summary->measurement_cost += sq;
    summary->num_error_terms += 1;
    sum_sq_px += e.residual_px.squaredNorm();
  }
  summary->rms_px =
      summary->num_error_terms ? std::sqrt(sum_sq_px / (2.0 * summary->num_error_terms)) : 0.0;
}

// ------------------------------------------------------------------ solve and covariance

// What the outer loop reports; CopyTo() writes it into a solver summary.
struct SolveResult {
  bool converged = false;
  std::string message;
  int iterations = 0;  // Ceres iterations over all outer loops
  int outer_iterations = 0;
  double line_delay_s = 0.0;
  double solve_time_s = 0.0;
  double line_delay_std_s = std::numeric_limits<double>::infinity();
  bool covariance_ok = false;
  double covariance_time_s = 0.0;
  // With SolveSettings::joint_covariance_blocks: the covariance of [d, those blocks] (ambient
  // sizes, in order); empty when not asked for or not computable.
  Eigen::MatrixXd joint_covariance;
  // With SolveSettings::block_observations: (num_observations, 2) scores of d; empty otherwise.
  Eigen::MatrixX2d line_delay_score;

  template <typename Summary>
  void CopyTo(Summary* summary) const {
    summary->converged = converged;
    summary->message = message;
    summary->iterations = iterations;
    summary->outer_iterations = outer_iterations;
    summary->line_delay_s = line_delay_s;
    summary->solve_time_s = solve_time_s;
    summary->line_delay_std_s = line_delay_std_s;
    summary->covariance_ok = covariance_ok;
    summary->covariance_time_s = covariance_time_s;
  }
};

// Variance of the 1-D parameter block `line_delay` from the normal equations H = J^T J of the
// plain least-squares problem `problem` (no loss functions, no manifolds): 1 / (h_dd - h_dc
// H_cc^{-1} h_cd), with H_cc the rest (sparse LDLT after Jacobi scaling). nullopt when H_cc is
// not positive definite; +inf when d is not determined (Schur complement <= 1e-14 h_dd).
//
// With `block_observations` (see SolveSettings) also fills `score` (num_observations x 2): the
// linearised contribution of each observation's u and v error to the estimate of d, s_i =
// (J_i g) r_i with g = H^{-1} e_d (whitened J, r), so that d_hat - d = -sum_i s_i to first order
// and the variance of 1 / schur is sum_i E[s_i^2] for independent errors. Sums over groups of
// observations (frames, time windows) give a cluster-robust variance of d (docs/formulation.md).
std::optional<double> SchurVariance(
    ceres::Problem* problem, double* line_delay, int num_threads,
    const std::unordered_map<ceres::ResidualBlockId, std::vector<int>>* block_observations =
        nullptr,
    int num_observations = 0, Eigen::MatrixX2d* score = nullptr);

// Called at the start of every outer iteration: re-linearise at the current estimate
// (attach / pair every observation, recompute the weights) and return whether any
// observation changed its attachment since the previous call.
using Relinearise = std::function<bool()>;
// Adds the residual blocks of the current attachment (the parameter block line_delay_s is
// already in the problem; `loss` is the robust loss of the measurement errors, may be null).
using AddResiduals = std::function<void(ceres::Problem* problem, ceres::LossFunction* loss)>;

// Outer loop: relinearise(); stop (after the first round) when nothing changed and, with
// wait_for_line_delay, d moved by less than 0.1 %; else rebuild the problem and solve it
// (DOGLEG, sparse normal Cholesky). Then, with estimate_line_delay and compute_covariance,
// the standard deviation of d from Ceres' covariance (sparse QR; +inf if rank deficient);
// 0 when d is not estimated. solve_time_s counts from `started`. Throws InputError when
// Ceres fails.
SolveResult SolveWithCovariance(const SolveSettings& settings, double* line_delay_s,
                                std::chrono::steady_clock::time_point started,
                                const Relinearise& relinearise, const AddResiduals& add_residuals);

}  // namespace rscalib::rs::detail
