// The rolling-shutter batch problem. All Ceres autodiff instantiations of the RS
// functors live in this one translation unit (compile time).
#include "rscalib/rs/line_delay_solver.hpp"

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

#include <ceres/ceres.h>

#include "rscalib/core/error.hpp"
#include "rscalib/core/parallel_ranges.hpp"
#include "rscalib/rs/intrinsics_prior_cost.hpp"
#include "rscalib/rs/motion_prior_cost.hpp"
#include "rscalib/rs/rs_reprojection_analytic_cost.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"
#include "rscalib/rs/rs_reprojection_intrinsics_cost.hpp"
#include "solver_common.hpp"

namespace rscalib::rs {

namespace {

using spline::CubicBSpline;
using spline::SpanPowerBasis;

// The span an observation is attached to, and its weighted error there.
struct Attachment {
  int span = -1;
  detail::WeightedError error;
};

// Span, image velocity and weight of observations [begin, end) at the current estimate.
void AttachRange(const RsObservations& obs, const camera::CameraModel& camera,
                 const CubicBSpline& trajectory, const std::vector<SpanPowerBasis>& bases,
                 double line_delay_s, const RsSolverOptions& options, Eigen::Index begin,
                 Eigen::Index end, std::vector<Attachment>* attached) {
  using Jet = ceres::Jet<double, 1>;
  const SpanCamera cam = MakeSpanCamera(camera);
  const auto& control = trajectory.control_points();
  const int n = trajectory.num_control_points();
  std::vector<Attachment>& out = *attached;
  for (Eigen::Index m = begin; m < end; ++m) {
    Attachment& a = out[m];
    detail::WeightedError& e = a.error;
    e.time_s = obs.frame_time_s[m] + obs.uv(m, 1) * line_delay_s;
    a.span = spline::FindSpan(trajectory.knots().data(), n, e.time_s);
    const SpanPowerBasis& basis = bases[a.span - spline::kSplineDegree];
    Jet c_storage[4][6];
    const Jet* c[4];
    for (int j = 0; j < 4; ++j) {
      for (int d = 0; d < 6; ++d) c_storage[j][d] = Jet(control(a.span - 3 + j, d));
      c[j] = c_storage[j];
    }
    const double point_w[3] = {obs.point_w(m, 0), obs.point_w(m, 1), obs.point_w(m, 2)};
    // t as a Jet: the derivative of uv is the image velocity for A.
    Jet uv[2];
    if (!ProjectAtSpanTime(basis, cam, point_w, c, Jet(e.time_s - basis.span_start, 0), uv))
      continue;
    detail::SetWeightedError(
        obs.uv.row(m).transpose(), Eigen::Vector2d(uv[0].a, uv[1].a),
        Eigen::Vector2d(uv[0].v[0], uv[1].v[0]), line_delay_s, options.standardise_errors,
        options.observation_sigma.size() > 0 ? options.observation_sigma[m] : options.pixel_sigma,
        options.max_rs_gain, &e);
  }
}

// Span, image velocity and weight of every observation at the current estimate. Each
// observation is on its own: options.num_threads threads share them, the same result.
std::vector<Attachment> Attach(const RsObservations& obs, const camera::CameraModel& camera,
                               const CubicBSpline& trajectory,
                               const std::vector<SpanPowerBasis>& bases, double line_delay_s,
                               const RsSolverOptions& options) {
  std::vector<Attachment> out(obs.uv.rows());
  ParallelRanges(out.size(), options.num_threads, 4096, [&](std::size_t begin, std::size_t end) {
    AttachRange(obs, camera, trajectory, bases, line_delay_s, options,
                static_cast<Eigen::Index>(begin), static_cast<Eigen::Index>(end), &out);
  });
  return out;
}

std::vector<SpanPowerBasis> AllSpanBases(const CubicBSpline& trajectory) {
  std::vector<SpanPowerBasis> bases;
  for (int span = spline::kSplineDegree; span < trajectory.num_control_points(); ++span)
    bases.push_back(trajectory.PowerBasis(span));
  return bases;
}

void Validate(const RsObservations& obs, const camera::CameraModel& camera,
              const CubicBSpline& trajectory, const RsSolverOptions& options) {
  const Eigen::Index m = obs.uv.rows();
  if (obs.frame_time_s.size() != m || obs.point_w.rows() != m)
    throw InputError("observations: frame_time_s, uv and point_w must have the same length");
  if (m == 0) throw InputError("no observations");
  if (trajectory.dimension() != geometry::kPoseStateDim)
    throw InputError("the trajectory must be a 6-D pose spline [p; phi]");
  detail::ValidateNoiseOptions(options.pixel_sigma, options.max_rs_gain);
  if (options.observation_sigma.size() > 0) {
    if (options.observation_sigma.size() != m)
      throw InputError("observation_sigma must have one value per observation (or none)");
    if (!(options.observation_sigma.array() > 0.0).all() || !options.observation_sigma.allFinite())
      throw InputError("observation_sigma must be positive and finite");
  }
  if ((options.motion_prior_q.array() <= 0.0).any())
    throw InputError("motion prior Q must be positive");
  detail::ValidateRobustLoss(options.robust_loss);
  if (!obs.uv.allFinite() || !obs.frame_time_s.allFinite() || !obs.point_w.allFinite())
    throw InputError("observations contain NaN or infinity");
  if (options.refine_intrinsics) {
    const Eigen::Index n = camera.params().size();
    if (options.intrinsics_prior_mean.size() != n || !options.intrinsics_prior_mean.allFinite())
      throw InputError("intrinsics_prior_mean must have one finite value per camera parameter");
    if (options.intrinsics_prior_covariance.rows() != n ||
        options.intrinsics_prior_covariance.cols() != n)
      throw InputError("intrinsics_prior_covariance must be n x n for the camera's n parameters");
  }
}

// --refine-intrinsics (docs/formulation.md §14): the intrinsics parameter block (zero-padded
// to kIntrinsicsBlockSize), its prior and the entries held constant (fixed ones, padding).
struct IntrinsicsBlock {
  IntrinsicsBlock(const camera::CameraModel& camera, const RsSolverOptions& options)
      : start(camera), n(static_cast<int>(camera.params().size())) {
    value.setZero();
    value.head(n) = camera.params();
    prior_mean.setZero();
    prior_mean.head(n) = options.intrinsics_prior_mean;
    sqrt_information = IntrinsicsPriorSqrtInformation(options.intrinsics_prior_covariance,
                                                      options.fixed_intrinsics);
    std::vector<bool> fixed(kIntrinsicsBlockSize, false);
    for (int i : options.fixed_intrinsics) fixed[i] = true;
    for (int i = n; i < kIntrinsicsBlockSize; ++i) fixed[i] = true;
    for (int i = 0; i < kIntrinsicsBlockSize; ++i)
      if (fixed[i]) constant.push_back(i);
  }

  // The camera with the current parameters.
  camera::CameraModel Current() const {
    return camera::CameraModel(start.name(), value.head(n), start.width(), start.height(),
                               start.pixel_size_mm());
  }

  // Adds the block (with the constant entries held) and its prior to `problem`.
  void AddTo(ceres::Problem* problem) {
    if (static_cast<int>(constant.size()) == kIntrinsicsBlockSize) {
      problem->AddParameterBlock(value.data(), kIntrinsicsBlockSize);
      problem->SetParameterBlockConstant(value.data());
    } else {
      problem->AddParameterBlock(value.data(), kIntrinsicsBlockSize,
                                 new ceres::SubsetManifold(kIntrinsicsBlockSize, constant));
    }
    problem->AddResidualBlock(IntrinsicsPriorCost::Create(prior_mean, sqrt_information), nullptr,
                              value.data());
  }

  double PriorCost() const {
    const Eigen::Matrix<double, kIntrinsicsBlockSize, 1> r =
        sqrt_information * (value - prior_mean);
    return r.squaredNorm();
  }

  const camera::CameraModel& start;
  int n;
  IntrinsicsVector value;
  IntrinsicsVector prior_mean;
  IntrinsicsMatrix sqrt_information;
  std::vector<int> constant;
};

double PriorCost(const CubicBSpline& trajectory, const RsSolverOptions& options) {
  if (!options.use_motion_prior) return 0.0;
  double cost = 0.0;
  const auto& control = trajectory.control_points();
  for (int span = spline::kSplineDegree; span < trajectory.num_control_points(); ++span) {
    if (trajectory.knots()[span + 1] <= trajectory.knots()[span]) continue;
    std::unique_ptr<ceres::CostFunction> f(
        MotionPriorCost::Create(trajectory.knots().data(), span, options.motion_prior_q));
    const double* blocks[4];
    for (int j = 0; j < 4; ++j) blocks[j] = control.data() + 6 * (span - 3 + j);
    double r[12];
    f->Evaluate(blocks, r, nullptr);
    for (double x : r) cost += x * x;
  }
  return cost;
}

void FillStatistics(const CubicBSpline& trajectory, const std::vector<Attachment>& attached,
                    const RsSolverOptions& options, RsSolveSummary* summary) {
  std::vector<const detail::WeightedError*> errors;
  for (const Attachment& a : attached) errors.push_back(&a.error);
  detail::FillErrorStatistics(errors, summary);
  summary->segment_cost.assign(trajectory.num_segments(), 0.0);
  summary->segment_count.assign(trajectory.num_segments(), 0);
  summary->unprojectable = 0;
  for (size_t i = 0; i < attached.size(); ++i) {
    if (!attached[i].error.ok) {
      ++summary->unprojectable;
      continue;
    }
    const int segment = attached[i].span - spline::kSplineDegree;
    summary->segment_cost[segment] += summary->standardised_sq[i];
    summary->segment_count[segment] += 1;
  }
  summary->prior_cost = PriorCost(trajectory, options);
}

}  // namespace

RsSolveSummary EvaluateLineDelay(const RsObservations& observations,
                                 const camera::CameraModel& camera,
                                 const spline::CubicBSpline& trajectory, double line_delay_s,
                                 const RsSolverOptions& options) {
  Validate(observations, camera, trajectory, options);
  RsSolveSummary summary;
  const auto bases = AllSpanBases(trajectory);
  const auto attached = Attach(observations, camera, trajectory, bases, line_delay_s, options);
  FillStatistics(trajectory, attached, options, &summary);
  summary.line_delay_s = line_delay_s;
  return summary;
}

RsSolveSummary SolveLineDelay(const RsObservations& observations, const camera::CameraModel& camera,
                              spline::CubicBSpline* trajectory, double* line_delay_s,
                              const RsSolverOptions& options) {
  Validate(observations, camera, *trajectory, options);
  const auto started = std::chrono::steady_clock::now();
  RsSolveSummary summary;
  const SpanCamera cam = MakeSpanCamera(camera);
  const auto bases = AllSpanBases(*trajectory);
  double* control = trajectory->mutable_control_points().data();
  const double* knots = trajectory->knots().data();
  // With refine_intrinsics the weights are computed with the current intrinsics.
  std::optional<IntrinsicsBlock> intrinsics;
  if (options.refine_intrinsics) intrinsics.emplace(camera, options);
  const CameraModelOf camera_model(camera);

  std::vector<Attachment> attached;
  std::vector<int> previous_span;
  // Re-attach every observation to the span of its current time t_i + v d.
  const auto reattach = [&]() {
    if (intrinsics) {
      attached =
          Attach(observations, intrinsics->Current(), *trajectory, bases, *line_delay_s, options);
    } else {
      attached = Attach(observations, camera, *trajectory, bases, *line_delay_s, options);
    }
    int reattached = 0;
    for (size_t i = 0; i < previous_span.size(); ++i)
      reattached += attached[i].span != previous_span[i];
    summary.reattached = reattached;
    previous_span.resize(attached.size());
    for (size_t i = 0; i < attached.size(); ++i) previous_span[i] = attached[i].span;
    return reattached != 0;
  };
  // Which observations each measurement block holds: the per-observation scores of d.
  std::unordered_map<ceres::ResidualBlockId, std::vector<int>> block_observations;
  const auto add_residuals = [&](ceres::Problem* problem, ceres::LossFunction* loss) {
    block_observations.clear();
    if (intrinsics) intrinsics->AddTo(problem);
    // Plain least squares with the analytic Jacobian: one residual block per run of observations
    // on the same span, consecutive frames included (RsReprojectionGroupCost, with the intrinsics
    // RsReprojectionIntrinsicsGroupCost), the same sum of squares. Under a robust loss each
    // observation is its own block (the loss applies to a whole block).
    const bool analytic = options.analytic_jacobian;
    const bool group = analytic && !loss;
    std::vector<AnalyticReprojectionTerm> members;
    std::vector<AnalyticIntrinsicsTerm> intrinsics_members;
    std::vector<int> member_observations;
    const auto flush_group = [&](int span) {
      if (members.empty() && intrinsics_members.empty()) return;
      double* c0 = control + 6 * (span - 3);
      const ceres::ResidualBlockId id =
          intrinsics
              ? problem->AddResidualBlock(
                    new RsReprojectionIntrinsicsGroupCost(std::move(intrinsics_members)), loss, c0,
                    c0 + 6, c0 + 12, c0 + 18, line_delay_s, intrinsics->value.data())
              : problem->AddResidualBlock(new RsReprojectionGroupCost(std::move(members)), loss, c0,
                                          c0 + 6, c0 + 12, c0 + 18, line_delay_s);
      if (options.line_delay_score) block_observations[id] = std::move(member_observations);
      members.clear();
      intrinsics_members.clear();
      member_observations.clear();
    };
    int group_span = -1;
    for (Eigen::Index m = 0; m < observations.uv.rows(); ++m) {
      const Attachment& a = attached[m];
      if (!a.error.ok) continue;
      const SpanPowerBasis& basis = bases[a.span - spline::kSplineDegree];
      const double uv[2] = {observations.uv(m, 0), observations.uv(m, 1)};
      const double point_w[3] = {observations.point_w(m, 0), observations.point_w(m, 1),
                                 observations.point_w(m, 2)};
      double* c0 = control + 6 * (a.span - 3);
      const double frame_offset_s = observations.frame_time_s[m] - basis.span_start;
      if (intrinsics && analytic) {
        if (!group || a.span != group_span) {
          flush_group(group_span);
          group_span = a.span;
        }
        intrinsics_members.emplace_back(basis, camera_model, frame_offset_s, uv, point_w,
                                        a.error.sqrt_information);
        if (options.line_delay_score) member_observations.push_back(static_cast<int>(m));
        continue;
      }
      if (group && !intrinsics) {
        if (a.span != group_span) {
          flush_group(group_span);
          group_span = a.span;
        }
        members.emplace_back(basis, cam, frame_offset_s, uv, point_w, a.error.sqrt_information);
        if (options.line_delay_score) member_observations.push_back(static_cast<int>(m));
        continue;
      }
      if (intrinsics) {
        problem->AddResidualBlock(
            RsReprojectionIntrinsicsCost::Create(basis, camera_model, frame_offset_s, uv, point_w,
                                                 a.error.sqrt_information),
            loss, c0, c0 + 6, c0 + 12, c0 + 18, line_delay_s, intrinsics->value.data());
        continue;
      }
      ceres::CostFunction* cost =
          options.analytic_jacobian
              ? new RsReprojectionAnalyticCost(basis, cam, frame_offset_s, uv, point_w,
                                               a.error.sqrt_information)
              : RsReprojectionCost::Create(basis, cam, frame_offset_s, uv, point_w,
                                           a.error.sqrt_information);
      const ceres::ResidualBlockId id =
          problem->AddResidualBlock(cost, loss, c0, c0 + 6, c0 + 12, c0 + 18, line_delay_s);
      if (options.line_delay_score) block_observations[id] = {static_cast<int>(m)};
    }
    flush_group(group_span);
    if (options.use_motion_prior) {
      for (int span = spline::kSplineDegree; span < trajectory->num_control_points(); ++span) {
        if (knots[span + 1] <= knots[span]) continue;
        double* c0 = control + 6 * (span - 3);
        problem->AddResidualBlock(MotionPriorCost::Create(knots, span, options.motion_prior_q),
                                  nullptr, c0, c0 + 6, c0 + 12, c0 + 18);
      }
    }
  };
  detail::SolveSettings settings =
      detail::MakeSolveSettings(options, true, "the line-delay solve failed: ");
  if (intrinsics)
    settings.joint_covariance_blocks = {{intrinsics->value.data(), kIntrinsicsBlockSize}};
  settings.schur_variance = options.schur_variance && !intrinsics;
  if (options.line_delay_score) {
    settings.block_observations = &block_observations;
    settings.num_observations = static_cast<int>(observations.uv.rows());
  }
  const detail::SolveResult result =
      detail::SolveWithCovariance(settings, line_delay_s, started, reattach, add_residuals);
  result.CopyTo(&summary);
  summary.line_delay_score = result.line_delay_score;

  if (intrinsics) {
    const camera::CameraModel refined = intrinsics->Current();
    attached = Attach(observations, refined, *trajectory, bases, *line_delay_s, options);
    summary.intrinsics = refined.params();
    const int n = intrinsics->n;
    if (result.joint_covariance.rows() >= 1 + n)
      summary.line_delay_intrinsics_covariance =
          result.joint_covariance.topLeftCorner(1 + n, 1 + n);
    summary.intrinsics_prior_cost = intrinsics->PriorCost();
  } else {
    attached = Attach(observations, camera, *trajectory, bases, *line_delay_s, options);
  }
  FillStatistics(*trajectory, attached, options, &summary);
  return summary;
}

}  // namespace rscalib::rs
