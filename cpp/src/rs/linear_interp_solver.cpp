// The linear-interpolation baseline (Hedborg et al. 2012). All Ceres autodiff
// instantiations of LinearInterpCost live in this translation unit (compile time).
#include "rscalib/rs/linear_interp_solver.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <ceres/ceres.h>

#include "rscalib/core/error.hpp"
#include "rscalib/rs/linear_interp_cost.hpp"
#include "solver_common.hpp"

namespace rscalib::rs {

Eigen::Matrix<double, 6, 1> LinearInterpPoseState(const Eigen::Matrix<double, 6, 1>& pose_a,
                                                  const Eigen::Matrix<double, 6, 1>& pose_b,
                                                  double s) {
  Eigen::Matrix<double, 6, 1> state;
  InterpolatePoseStateLinear(pose_a.data(), pose_b.data(), s, state.data());
  return state;
}

namespace {

// The pair of frames an observation is interpolated between, and its weighted error there.
struct Pairing {
  int first = -1;  // frame a of the pair (a, a + 1); -1: dropped
  bool extrapolated = false;
  detail::WeightedError error;
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
    detail::WeightedError& e = p.error;
    const int k = obs.frame_index[m];
    const double offset_s = obs.uv(m, 1) * line_delay_s;
    e.time_s = frame_time_s[k] + offset_s;
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
    const Jet s((e.time_s - frame_time_s[a]) / interval_s, 0);
    Jet pose_a[6], pose_b[6];
    for (int i = 0; i < 6; ++i) {
      pose_a[i] = Jet(poses(a, i));
      pose_b[i] = Jet(poses(a + 1, i));
    }
    const double point_w[3] = {obs.point_w(m, 0), obs.point_w(m, 1), obs.point_w(m, 2)};
    Jet uv[2];
    if (!ProjectLinearInterp(cam, point_w, pose_a, pose_b, s, uv)) continue;
    detail::SetWeightedError(obs.uv.row(m).transpose(), Eigen::Vector2d(uv[0].a, uv[1].a),
                             Eigen::Vector2d(uv[0].v[0] / interval_s, uv[1].v[0] / interval_s),
                             line_delay_s, options.standardise_errors, options.pixel_sigma,
                             options.max_rs_gain, &e);
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
  detail::ValidateNoiseOptions(options.pixel_sigma, options.max_rs_gain);
  if (!(options.max_frame_interval_s >= 0.0))
    throw InputError("max_frame_interval_s must be >= 0 (0: automatic)");
  detail::ValidateRobustLoss(options.robust_loss);
  if (!obs.uv.allFinite() || !obs.point_w.allFinite() || !frame_time_s.allFinite() ||
      !poses.allFinite())
    throw InputError("observations, frame times or poses contain NaN or infinity");
}

void FillStatistics(const std::vector<Pairing>& pairs, LinearInterpSummary* summary) {
  std::vector<const detail::WeightedError*> errors;
  for (const Pairing& p : pairs) errors.push_back(&p.error);
  detail::FillErrorStatistics(errors, summary);
  summary->pair_first.resize(static_cast<Eigen::Index>(pairs.size()));
  summary->isolated = summary->extrapolated = summary->unprojectable = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const Pairing& p = pairs[i];
    summary->pair_first[i] = p.error.ok ? p.first : -1;
    summary->isolated += p.first < 0;
    summary->unprojectable += p.first >= 0 && !p.error.ok;
    if (p.error.ok) summary->extrapolated += p.extrapolated;
  }
}

}  // namespace

LinearInterpSummary SolveLineDelayLinear(const LinearInterpObservations& observations,
                                         const Eigen::VectorXd& frame_time_s,
                                         const camera::CameraModel& camera,
                                         FramePoseMatrix* frame_poses, double* line_delay_s,
                                         const LinearInterpOptions& options) {
  Validate(observations, frame_time_s, *frame_poses, options);
  const auto started = std::chrono::steady_clock::now();
  LinearInterpSummary summary;
  const SpanCamera cam = MakeSpanCamera(camera);
  const int num_frames = static_cast<int>(frame_time_s.size());
  summary.max_frame_interval_s = options.max_frame_interval_s > 0.0 ? options.max_frame_interval_s
                                                                    : AutoInterval(frame_time_s);
  std::vector<bool> linked_to_next(num_frames, false);
  for (int k = 0; k + 1 < num_frames; ++k) {
    linked_to_next[k] = frame_time_s[k + 1] - frame_time_s[k] <= summary.max_frame_interval_s;
    summary.num_chains += linked_to_next[k] && (k == 0 || !linked_to_next[k - 1]);
  }

  double* poses = frame_poses->data();
  std::vector<Pairing> pairs;
  std::vector<int> previous_first;
  // Re-choose every observation's pair (it depends on the sign of d).
  const auto repair = [&]() {
    pairs =
        Pair(observations, frame_time_s, linked_to_next, cam, *frame_poses, *line_delay_s, options);
    bool changed = previous_first.empty();
    for (size_t i = 0; i < previous_first.size(); ++i)
      changed |= pairs[i].first != previous_first[i];
    previous_first.resize(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) previous_first[i] = pairs[i].first;
    return changed;
  };
  const auto add_residuals = [&](ceres::Problem* problem, ceres::LossFunction* loss) {
    for (Eigen::Index m = 0; m < observations.uv.rows(); ++m) {
      const Pairing& p = pairs[m];
      if (!p.error.ok) continue;
      const int a = p.first;
      const double uv[2] = {observations.uv(m, 0), observations.uv(m, 1)};
      const double point_w[3] = {observations.point_w(m, 0), observations.point_w(m, 1),
                                 observations.point_w(m, 2)};
      problem->AddResidualBlock(
          LinearInterpCost::Create(cam, frame_time_s[observations.frame_index[m]] - frame_time_s[a],
                                   frame_time_s[a + 1] - frame_time_s[a], uv, point_w,
                                   p.error.sqrt_information),
          loss, poses + 6 * a, poses + 6 * (a + 1), line_delay_s);
    }
  };
  // The standardisation weights depend on d: with them, also wait for d to settle.
  const detail::SolveSettings settings = detail::MakeSolveSettings(
      options, options.standardise_errors, "the linear-interpolation solve failed: ");
  const detail::SolveResult result =
      detail::SolveWithCovariance(settings, line_delay_s, started, repair, add_residuals);
  result.CopyTo(&summary);

  pairs =
      Pair(observations, frame_time_s, linked_to_next, cam, *frame_poses, *line_delay_s, options);
  FillStatistics(pairs, &summary);
  return summary;
}

}  // namespace rscalib::rs
