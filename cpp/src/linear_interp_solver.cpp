// The linear-interpolation baseline (Hedborg et al. 2012). All Ceres autodiff
// instantiations of LinearInterpCost live in this translation unit (compile time).
#include "rscalib/rs/linear_interp_solver.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>

#include <ceres/ceres.h>

#include "rscalib/core/error.hpp"
#include "rscalib/rs/error_standardisation.hpp"
#include "rscalib/rs/linear_interp_cost.hpp"
#include "scalar_variance.hpp"
#include "solver_setup.hpp"

namespace rscalib::rs {

Eigen::Matrix<double, 6, 1> LinearInterpPoseState(const Eigen::Matrix<double, 6, 1>& pose_a,
                                                  const Eigen::Matrix<double, 6, 1>& pose_b,
                                                  double s) {
  Eigen::Matrix<double, 6, 1> state;
  InterpolatePoseStateLinear(pose_a.data(), pose_b.data(), s, state.data());
  return state;
}

namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

struct Pairing {
  int first = -1;            // frame a of the pair (a, a + 1); -1: dropped
  bool extrapolated = false;
  bool ok = false;           // projectable at the current estimate
  bool clamped = false;
  Eigen::Matrix2d sqrt_information = Eigen::Matrix2d::Identity();
  Eigen::Vector2d residual_px = Eigen::Vector2d::Zero();
  double time_s = 0.0;
};

double AutoInterval(const Eigen::VectorXd& frame_time_s) {
  if (frame_time_s.size() < 2) return 0.0;
  std::vector<double> intervals(frame_time_s.size() - 1);
  for (Eigen::Index i = 0; i + 1 < frame_time_s.size(); ++i)
    intervals[i] = frame_time_s[i + 1] - frame_time_s[i];
  std::nth_element(intervals.begin(), intervals.begin() + intervals.size() / 2, intervals.end());
  return 1.5 * intervals[intervals.size() / 2];
}

// Pair, weight and raw error of every observation at the current estimate.
std::vector<Pairing> Pair(const LinearInterpObservations& obs, const Eigen::VectorXd& frame_time_s,
                          const std::vector<bool>& linked_to_next, const SpanCamera& cam,
                          const FramePoseMatrix& poses, double line_delay_s,
                          const LinearInterpOptions& options) {
  using Jet = ceres::Jet<double, 1>;
  const int num_frames = static_cast<int>(frame_time_s.size());
  std::vector<Pairing> out(obs.uv.rows());
  for (Eigen::Index m = 0; m < obs.uv.rows(); ++m) {
    Pairing& p = out[m];
    const int k = obs.frame_index[m];
    const double offset_s = obs.uv(m, 1) * line_delay_s;
    p.time_s = frame_time_s[k] + offset_s;
    const bool has_next = k + 1 < num_frames && linked_to_next[k];
    const bool has_prev = k > 0 && linked_to_next[k - 1];
    if (offset_s >= 0.0) {
      p.first = has_next ? k : (has_prev ? k - 1 : -1);
      p.extrapolated = !has_next && has_prev;
    } else {
      p.first = has_prev ? k - 1 : (has_next ? k : -1);
      p.extrapolated = !has_prev && has_next;
    }
    if (p.first < 0) continue;
    const int a = p.first;
    const double interval_s = frame_time_s[a + 1] - frame_time_s[a];
    // s as a Jet in time: its derivative gives the image velocity for A.
    const Jet s((p.time_s - frame_time_s[a]) / interval_s, 0);
    Jet pose_a[6], pose_b[6];
    for (int i = 0; i < 6; ++i) {
      pose_a[i] = Jet(poses(a, i));
      pose_b[i] = Jet(poses(a + 1, i));
    }
    const double point_w[3] = {obs.point_w(m, 0), obs.point_w(m, 1), obs.point_w(m, 2)};
    Jet uv[2];
    p.ok = ProjectLinearInterp(cam, point_w, pose_a, pose_b, s, uv) && std::isfinite(uv[0].a) &&
           std::isfinite(uv[1].a);
    if (!p.ok) continue;
    p.residual_px = Eigen::Vector2d(obs.uv(m, 0) - uv[0].a, obs.uv(m, 1) - uv[1].a);
    if (options.standardise_errors) {
      const Eigen::Vector2d velocity_px_s(uv[0].v[0] / interval_s, uv[1].v[0] / interval_s);
      const StandardisationWeight w = ComputeStandardisationWeight(
          line_delay_s, velocity_px_s, options.pixel_sigma, options.max_rs_gain);
      p.sqrt_information = w.sqrt_information;
      p.clamped = w.clamped;
    } else {
      p.sqrt_information = Eigen::Matrix2d::Identity() / options.pixel_sigma;
    }
  }
  return out;
}

void Validate(const LinearInterpObservations& obs, const Eigen::VectorXd& frame_time_s,
              const FramePoseMatrix& poses, const LinearInterpOptions& options) {
  const Eigen::Index m = obs.uv.rows();
  if (obs.frame_index.size() != m || obs.point_w.rows() != m)
    throw InputError("observations: frame_index, uv and point_w must have the same length");
  if (m == 0) throw InputError("no observations");
  if (frame_time_s.size() < 2) throw InputError("the linear model needs at least 2 frames");
  if (poses.rows() != frame_time_s.size())
    throw InputError("frame_poses must have one row per frame time");
  for (Eigen::Index i = 0; i + 1 < frame_time_s.size(); ++i)
    if (!(frame_time_s[i + 1] > frame_time_s[i]))
      throw InputError("frame times must be strictly increasing");
  if (obs.frame_index.size() &&
      (obs.frame_index.minCoeff() < 0 || obs.frame_index.maxCoeff() >= frame_time_s.size()))
    throw InputError("observations: frame_index out of range");
  if (!(options.pixel_sigma > 0.0)) throw InputError("pixel_sigma must be positive");
  if (!(options.max_rs_gain > 0.0 && options.max_rs_gain < 1.0))
    throw InputError("max_rs_gain must be in (0, 1)");
  if (!(options.max_frame_interval_s >= 0.0))
    throw InputError("max_frame_interval_s must be >= 0 (0: automatic)");
  if (options.robust_loss != "none" && options.robust_loss != "huber" &&
      options.robust_loss != "cauchy")
    throw InputError("robust_loss must be none, huber or cauchy");
  if (!obs.uv.allFinite() || !obs.point_w.allFinite() || !frame_time_s.allFinite() ||
      !poses.allFinite())
    throw InputError("observations, frame times or poses contain NaN or infinity");
}

void FillStatistics(const std::vector<Pairing>& pairs, LinearInterpSummary* summary) {
  const Eigen::Index m = static_cast<Eigen::Index>(pairs.size());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  summary->pair_first.resize(m);
  summary->residual_px.resize(m, 2);
  summary->standardised_sq.resize(m);
  summary->observation_time_s.resize(m);
  summary->measurement_cost = 0.0;
  summary->num_error_terms = summary->isolated = summary->extrapolated = 0;
  summary->unprojectable = summary->clamped_weights = 0;
  double sum_sq_px = 0.0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const Pairing& p = pairs[i];
    summary->observation_time_s[i] = p.time_s;
    summary->pair_first[i] = p.ok ? p.first : -1;
    summary->isolated += p.first < 0;
    summary->unprojectable += p.first >= 0 && !p.ok;
    if (!p.ok) {
      summary->residual_px.row(i).setConstant(nan);
      summary->standardised_sq[i] = nan;
      continue;
    }
    summary->extrapolated += p.extrapolated;
    summary->clamped_weights += p.clamped;
    const double sq = (p.sqrt_information * p.residual_px).squaredNorm();
    summary->residual_px.row(i) = p.residual_px.transpose();
    summary->standardised_sq[i] = sq;
    summary->measurement_cost += sq;
    summary->num_error_terms += 1;
    sum_sq_px += p.residual_px.squaredNorm();
  }
  summary->rms_px =
      summary->num_error_terms ? std::sqrt(sum_sq_px / (2.0 * summary->num_error_terms)) : 0.0;
}

}  // namespace

LinearInterpSummary SolveLineDelayLinear(const LinearInterpObservations& observations,
                                         const Eigen::VectorXd& frame_time_s,
                                         const camera::CameraModel& camera,
                                         FramePoseMatrix* frame_poses, double* line_delay_s,
                                         const LinearInterpOptions& options) {
  Validate(observations, frame_time_s, *frame_poses, options);
  const auto started = Clock::now();
  LinearInterpSummary summary;
  const SpanCamera cam{camera.type(), camera.params().data(),
                       static_cast<int>(camera.params().size()), camera.pixel_size_mm().data()};
  const int num_frames = static_cast<int>(frame_time_s.size());
  summary.max_frame_interval_s =
      options.max_frame_interval_s > 0.0 ? options.max_frame_interval_s : AutoInterval(frame_time_s);
  std::vector<bool> linked_to_next(num_frames, false);
  for (int k = 0; k + 1 < num_frames; ++k) {
    linked_to_next[k] = frame_time_s[k + 1] - frame_time_s[k] <= summary.max_frame_interval_s;
    summary.num_chains += linked_to_next[k] && (k == 0 || !linked_to_next[k - 1]);
  }

  std::unique_ptr<ceres::LossFunction> loss = detail::MakeRobustLoss(options.robust_loss, options.robust_loss_scale);
  const ceres::Solver::Options solver_options = detail::MakeSolverOptions(options);

  double* poses = frame_poses->data();
  std::unique_ptr<ceres::Problem> problem;
  std::vector<Pairing> pairs;
  std::vector<int> previous_first;
  double d_at_pair = std::numeric_limits<double>::quiet_NaN();
  for (int outer = 0; outer < std::max(1, options.max_outer_iterations); ++outer) {
    pairs = Pair(observations, frame_time_s, linked_to_next, cam, *frame_poses, *line_delay_s,
                 options);
    bool changed = previous_first.empty();
    for (size_t i = 0; i < previous_first.size(); ++i) changed |= pairs[i].first != previous_first[i];
    // The standardisation weights depend on d: with them, also wait for d to settle.
    const bool d_settled = !options.standardise_errors ||
        std::abs(*line_delay_s - d_at_pair) <= 1e-3 * std::max(std::abs(*line_delay_s), 1e-9);
    if (outer > 0 && !changed && d_settled) break;
    d_at_pair = *line_delay_s;
    previous_first.resize(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) previous_first[i] = pairs[i].first;

    ceres::Problem::Options problem_options;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(problem_options);
    problem->AddParameterBlock(line_delay_s, 1);
    for (Eigen::Index m = 0; m < observations.uv.rows(); ++m) {
      const Pairing& p = pairs[m];
      if (!p.ok) continue;
      const int a = p.first;
      const double uv[2] = {observations.uv(m, 0), observations.uv(m, 1)};
      const double point_w[3] = {observations.point_w(m, 0), observations.point_w(m, 1),
                                 observations.point_w(m, 2)};
      problem->AddResidualBlock(
          LinearInterpCost::Create(cam, frame_time_s[observations.frame_index[m]] - frame_time_s[a],
                                   frame_time_s[a + 1] - frame_time_s[a], uv, point_w,
                                   p.sqrt_information),
          loss.get(), poses + 6 * a, poses + 6 * (a + 1), line_delay_s);
    }
    if (!options.estimate_line_delay) problem->SetParameterBlockConstant(line_delay_s);
    if (options.max_iterations <= 0) {
      summary.converged = true;
      summary.message = "not solved (max_iterations = 0)";
      summary.outer_iterations = outer + 1;
      break;
    }
    ceres::Solver::Summary ceres_summary;
    ceres::Solve(solver_options, problem.get(), &ceres_summary);
    summary.iterations += static_cast<int>(ceres_summary.iterations.size());
    summary.outer_iterations = outer + 1;
    summary.converged = ceres_summary.termination_type == ceres::CONVERGENCE;
    summary.message = ceres_summary.message;
    if (ceres_summary.termination_type == ceres::FAILURE)
      throw InputError("the linear-interpolation solve failed: " + ceres_summary.message);
  }
  summary.solve_time_s = Seconds(started);
  summary.line_delay_s = *line_delay_s;

  pairs = Pair(observations, frame_time_s, linked_to_next, cam, *frame_poses, *line_delay_s, options);
  FillStatistics(pairs, &summary);

  summary.line_delay_std_s = std::numeric_limits<double>::infinity();
  if (options.compute_covariance && options.estimate_line_delay && problem) {
    const auto covariance_started = Clock::now();
    if (const auto variance = detail::ScalarVariance(problem.get(), line_delay_s, options.num_threads)) {
      summary.line_delay_std_s = std::sqrt(*variance);
      summary.covariance_ok = true;
    }
    summary.covariance_time_s = Seconds(covariance_started);
  } else if (!options.estimate_line_delay) {
    summary.line_delay_std_s = 0.0;
  }
  return summary;
}

}  // namespace rscalib::rs
