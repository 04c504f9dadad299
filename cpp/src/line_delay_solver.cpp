// The rolling-shutter batch problem. All Ceres autodiff instantiations of the RS
// functors live in this one translation unit (compile time).
#include "rscalib/rs/line_delay_solver.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <memory>

#include <ceres/ceres.h>

#include "rscalib/core/error.hpp"
#include "rscalib/rs/error_standardisation.hpp"
#include "rscalib/rs/motion_prior_cost.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"
#include "scalar_variance.hpp"
#include "solver_setup.hpp"

namespace rscalib::rs {

Eigen::Matrix2d ErrorNoiseMap(double line_delay_s, const Eigen::Vector2d& image_velocity_px_s) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Identity();
  a(0, 1) = -line_delay_s * image_velocity_px_s[0];
  a(1, 1) = 1.0 - line_delay_s * image_velocity_px_s[1];
  return a;
}

StandardisationWeight ComputeStandardisationWeight(double line_delay_s,
                                                   const Eigen::Vector2d& image_velocity_px_s,
                                                   double pixel_sigma, double max_rs_gain) {
  StandardisationWeight out;
  double gain = line_delay_s * image_velocity_px_s[1];  // d * v_dot
  if (gain > max_rs_gain) {
    gain = max_rs_gain;
    out.clamped = true;
  }
  // W = A^{-1} / sigma, A = [[1, -d u_dot], [0, 1 - d v_dot]].
  const double det = 1.0 - gain;
  out.sqrt_information << 1.0, line_delay_s * image_velocity_px_s[0] / det, 0.0, 1.0 / det;
  out.sqrt_information /= pixel_sigma;
  return out;
}

namespace {

using Clock = std::chrono::steady_clock;
using spline::CubicBSpline;
using spline::SpanPowerBasis;

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

SpanCamera MakeSpanCamera(const camera::CameraModel& camera) {
  return SpanCamera{camera.type(), camera.params().data(),
                    static_cast<int>(camera.params().size()), camera.pixel_size_mm().data()};
}

struct Attachment {
  int span = -1;
  bool ok = false;       // projectable at the current estimate
  bool clamped = false;
  Eigen::Matrix2d sqrt_information = Eigen::Matrix2d::Identity();
  Eigen::Vector2d residual_px = Eigen::Vector2d::Zero();
  double time_s = 0.0;
};

// Span, image velocity and weight of every observation at the current estimate.
std::vector<Attachment> Attach(const RsObservations& obs, const camera::CameraModel& camera,
                               const CubicBSpline& trajectory,
                               const std::vector<SpanPowerBasis>& bases, double line_delay_s,
                               const RsSolverOptions& options) {
  using Jet = ceres::Jet<double, 1>;
  const SpanCamera cam = MakeSpanCamera(camera);
  const auto& control = trajectory.control_points();
  const int n = trajectory.num_control_points();
  std::vector<Attachment> out(obs.uv.rows());
  for (Eigen::Index m = 0; m < obs.uv.rows(); ++m) {
    Attachment& a = out[m];
    a.time_s = obs.frame_time_s[m] + obs.uv(m, 1) * line_delay_s;
    a.span = spline::FindSpan(trajectory.knots().data(), n, a.time_s);
    const SpanPowerBasis& basis = bases[a.span - spline::kSplineDegree];
    Jet c_storage[4][6];
    const Jet* c[4];
    for (int j = 0; j < 4; ++j) {
      for (int d = 0; d < 6; ++d) c_storage[j][d] = Jet(control(a.span - 3 + j, d));
      c[j] = c_storage[j];
    }
    const double point_w[3] = {obs.point_w(m, 0), obs.point_w(m, 1), obs.point_w(m, 2)};
    Jet uv[2];
    a.ok = ProjectAtSpanTime(basis, cam, point_w, c, Jet(a.time_s - basis.span_start, 0), uv);
    if (!a.ok || !std::isfinite(uv[0].a) || !std::isfinite(uv[1].a)) {
      a.ok = false;
      continue;
    }
    a.residual_px = Eigen::Vector2d(obs.uv(m, 0) - uv[0].a, obs.uv(m, 1) - uv[1].a);
    if (options.standardise_errors) {
      const StandardisationWeight w = ComputeStandardisationWeight(
          line_delay_s, Eigen::Vector2d(uv[0].v[0], uv[1].v[0]), options.pixel_sigma,
          options.max_rs_gain);
      a.sqrt_information = w.sqrt_information;
      a.clamped = w.clamped;
    } else {
      a.sqrt_information = Eigen::Matrix2d::Identity() / options.pixel_sigma;
    }
  }
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
  if (!(options.pixel_sigma > 0.0)) throw InputError("pixel_sigma must be positive");
  if (!(options.max_rs_gain > 0.0 && options.max_rs_gain < 1.0))
    throw InputError("max_rs_gain must be in (0, 1)");
  if ((options.motion_prior_q.array() <= 0.0).any())
    throw InputError("motion prior Q must be positive");
  if (options.robust_loss != "none" && options.robust_loss != "huber" &&
      options.robust_loss != "cauchy")
    throw InputError("robust_loss must be none, huber or cauchy");
  if (!obs.uv.allFinite() || !obs.frame_time_s.allFinite() || !obs.point_w.allFinite())
    throw InputError("observations contain NaN or infinity");
  (void)camera;
}

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

void FillStatistics(const RsObservations& obs, const CubicBSpline& trajectory,
                    const std::vector<Attachment>& attached, const RsSolverOptions& options,
                    RsSolveSummary* summary) {
  const Eigen::Index m = obs.uv.rows();
  summary->segment_cost.assign(trajectory.num_segments(), 0.0);
  summary->segment_count.assign(trajectory.num_segments(), 0);
  summary->residual_px.resize(m, 2);
  summary->standardised_sq.resize(m);
  summary->observation_time_s.resize(m);
  summary->measurement_cost = 0.0;
  summary->num_error_terms = 0;
  summary->unprojectable = 0;
  summary->clamped_weights = 0;
  double sum_sq_px = 0.0;
  for (Eigen::Index i = 0; i < m; ++i) {
    const Attachment& a = attached[i];
    summary->observation_time_s[i] = a.time_s;
    if (!a.ok) {
      ++summary->unprojectable;
      summary->residual_px.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
      summary->standardised_sq[i] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    summary->clamped_weights += a.clamped;
    const double sq = (a.sqrt_information * a.residual_px).squaredNorm();
    summary->residual_px.row(i) = a.residual_px.transpose();
    summary->standardised_sq[i] = sq;
    summary->measurement_cost += sq;
    summary->num_error_terms += 1;
    sum_sq_px += a.residual_px.squaredNorm();
    const int segment = a.span - spline::kSplineDegree;
    summary->segment_cost[segment] += sq;
    summary->segment_count[segment] += 1;
  }
  summary->rms_px =
      summary->num_error_terms ? std::sqrt(sum_sq_px / (2.0 * summary->num_error_terms)) : 0.0;
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
  FillStatistics(observations, trajectory, attached, options, &summary);
  summary.line_delay_s = line_delay_s;
  return summary;
}

RsSolveSummary SolveLineDelay(const RsObservations& observations,
                              const camera::CameraModel& camera, spline::CubicBSpline* trajectory,
                              double* line_delay_s, const RsSolverOptions& options) {
  Validate(observations, camera, *trajectory, options);
  const auto started = Clock::now();
  RsSolveSummary summary;
  const SpanCamera cam = MakeSpanCamera(camera);
  const auto bases = AllSpanBases(*trajectory);
  double* control = trajectory->mutable_control_points().data();
  const double* knots = trajectory->knots().data();

  std::unique_ptr<ceres::LossFunction> loss = detail::MakeRobustLoss(options.robust_loss, options.robust_loss_scale);
  const ceres::Solver::Options solver_options = detail::MakeSolverOptions(options);

  std::unique_ptr<ceres::Problem> problem;
  std::vector<Attachment> attached;
  std::vector<int> previous_span;
  double d_at_attach = std::numeric_limits<double>::quiet_NaN();
  ceres::Solver::Summary ceres_summary;
  for (int outer = 0; outer < std::max(1, options.max_outer_iterations); ++outer) {
    attached = Attach(observations, camera, *trajectory, bases, *line_delay_s, options);
    int reattached = 0;
    for (size_t i = 0; i < previous_span.size(); ++i)
      reattached += attached[i].span != previous_span[i];
    summary.reattached = reattached;
    const bool d_settled =
        std::abs(*line_delay_s - d_at_attach) <= 1e-3 * std::max(std::abs(*line_delay_s), 1e-9);
    if (outer > 0 && reattached == 0 && d_settled) break;
    previous_span.resize(attached.size());
    for (size_t i = 0; i < attached.size(); ++i) previous_span[i] = attached[i].span;
    d_at_attach = *line_delay_s;

    ceres::Problem::Options problem_options;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(problem_options);
    problem->AddParameterBlock(line_delay_s, 1);
    for (Eigen::Index m = 0; m < observations.uv.rows(); ++m) {
      const Attachment& a = attached[m];
      if (!a.ok) continue;
      const SpanPowerBasis& basis = bases[a.span - spline::kSplineDegree];
      const double uv[2] = {observations.uv(m, 0), observations.uv(m, 1)};
      const double point_w[3] = {observations.point_w(m, 0), observations.point_w(m, 1),
                                 observations.point_w(m, 2)};
      double* c0 = control + 6 * (a.span - 3);
      problem->AddResidualBlock(
          RsReprojectionCost::Create(basis, cam, observations.frame_time_s[m] - basis.span_start,
                                     uv, point_w, a.sqrt_information),
          loss.get(), c0, c0 + 6, c0 + 12, c0 + 18, line_delay_s);
    }
    if (options.use_motion_prior) {
      for (int span = spline::kSplineDegree; span < trajectory->num_control_points(); ++span) {
        if (knots[span + 1] <= knots[span]) continue;
        double* c0 = control + 6 * (span - 3);
        problem->AddResidualBlock(MotionPriorCost::Create(knots, span, options.motion_prior_q),
                                  nullptr, c0, c0 + 6, c0 + 12, c0 + 18);
      }
    }
    if (!options.estimate_line_delay) problem->SetParameterBlockConstant(line_delay_s);

    if (options.max_iterations <= 0) {  // evaluation / covariance only
      summary.converged = true;
      summary.message = "not solved (max_iterations = 0)";
      summary.outer_iterations = outer + 1;
      break;
    }
    ceres::Solve(solver_options, problem.get(), &ceres_summary);
    summary.iterations += static_cast<int>(ceres_summary.iterations.size());
    summary.outer_iterations = outer + 1;
    summary.converged = ceres_summary.termination_type == ceres::CONVERGENCE;
    summary.message = ceres_summary.message;
    if (ceres_summary.termination_type == ceres::FAILURE) {
      throw InputError("the line-delay solve failed: " + ceres_summary.message);
    }
  }
  summary.solve_time_s = Seconds(started);
  summary.line_delay_s = *line_delay_s;

  attached = Attach(observations, camera, *trajectory, bases, *line_delay_s, options);
  FillStatistics(observations, *trajectory, attached, options, &summary);

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
