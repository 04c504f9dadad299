#include "rscalib/bundle/bundle_problem.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <ceres/ceres.h>

#include "rscalib/bundle/baseline_manifold.hpp"
#include "rscalib/bundle/global_covariance.hpp"
#include "rscalib/bundle/line_delay_prior_cost.hpp"
#include "rscalib/bundle/pose_manifold.hpp"
#include "rscalib/bundle/reprojection_cost.hpp"
#include "rscalib/core/error.hpp"
#include "rscalib/core/memory_limit.hpp"
#include "rscalib/core/solver_settings.hpp"

namespace rscalib::bundle {

namespace {

constexpr double kMaxJacobianEntries = 2 * (kMaxGlobals + 6 + 6 + 3);
// Rounds of the free solve, each dropping the points that left their range, before a bounded solve.
constexpr int kMaxDropRounds = 3;

std::string Index(const char* what, Eigen::Index i) {
  return std::string(what) + "[" + std::to_string(i) + "]";
}

void CheckFinite(const Eigen::Ref<const Eigen::MatrixXd>& values, const char* what) {
  for (Eigen::Index r = 0; r < values.rows(); ++r)
    for (Eigen::Index c = 0; c < values.cols(); ++c)
      if (!std::isfinite(values(r, c)))
        throw InputError(std::string("bundle adjustment: ") + what +
                         " has a NaN or infinite value" + " in row " + std::to_string(r) +
                         " (every value must be finite)");
}

void CheckOptions(const BundleOptions& options) {
  const auto& loss = options.robust_loss;
  if (loss != "none" && loss != "huber" && loss != "cauchy" && loss != "soft_l1")
    throw InputError(
        "bundle adjustment: robust_loss must be none, huber, cauchy or soft_l1, got '" + loss +
        "'");
  if (!(options.robust_loss_scale_px > 0.0) || !std::isfinite(options.robust_loss_scale_px))
    throw InputError("bundle adjustment: robust_loss_scale_px must be positive and finite");
  if (options.max_iterations < 0 || options.max_iterations > 100000)
    throw InputError("bundle adjustment: max_iterations must be 0..100000, got " +
                     std::to_string(options.max_iterations));
  for (double tolerance :
       {options.function_tolerance, options.gradient_tolerance, options.parameter_tolerance})
    if (!(tolerance >= 0.0) || !std::isfinite(tolerance))
      throw InputError("bundle adjustment: tolerances must be finite and >= 0");
  if (options.num_threads < 1 || options.num_threads > 1024)
    throw InputError("bundle adjustment: num_threads must be 1..1024, got " +
                     std::to_string(options.num_threads));
  const auto& solver = options.linear_solver;
  if (solver != "sparse_schur" && solver != "dense_schur" && solver != "iterative_schur")
    throw InputError(
        "bundle adjustment: linear_solver must be sparse_schur, dense_schur or iterative_schur, "
        "got '" +
        solver + "'");
  if (!std::isfinite(options.near_limit) || !std::isfinite(options.beyond_infinity_limit))
    throw InputError("bundle adjustment: near_limit and beyond_infinity_limit must be finite");
  if (!(options.max_out_of_range_share >= 0.0 && options.max_out_of_range_share <= 1.0))
    throw InputError("bundle adjustment: max_out_of_range_share must be in [0, 1]");
  if (!(options.prior_pixel_sigma_px > 0.0) || !std::isfinite(options.prior_pixel_sigma_px))
    throw InputError("bundle adjustment: prior_pixel_sigma_px must be positive and finite");
}

void CheckData(const camera::CameraModel& camera, const BundleData& data) {
  const Eigen::Index n_cam = camera.params().size();
  const Eigen::Index num_keyframes = data.keyframe_poses.rows();
  const Eigen::Index num_points = data.points.rows();
  const auto& obs = data.observations;
  const Eigen::Index n = obs.keyframe.size();
  if (data.free_intrinsics.size() != 0 && data.free_intrinsics.size() != n_cam)
    throw InputError("bundle adjustment: free_intrinsics has " +
                     std::to_string(data.free_intrinsics.size()) + " entries, the " +
                     camera.name() + " camera " + std::to_string(n_cam) + " parameters");
  if (num_keyframes < 2)
    throw InputError("bundle adjustment: needs at least 2 keyframes, got " +
                     std::to_string(num_keyframes));
  if (num_points < 1) throw InputError("bundle adjustment: no points");
  if (obs.point.size() != n || obs.uv_px.rows() != n || obs.image_velocity_px_s.rows() != n)
    throw InputError("bundle adjustment: the observations' keyframe (" + std::to_string(n) +
                     "), point (" + std::to_string(obs.point.size()) + "), uv_px (" +
                     std::to_string(obs.uv_px.rows()) + ") and image_velocity_px_s (" +
                     std::to_string(obs.image_velocity_px_s.rows()) +
                     ") must have one row per observation");
  if (data.point_anchor.size() != num_points)
    throw InputError("bundle adjustment: point_anchor has " +
                     std::to_string(data.point_anchor.size()) + " entries for " +
                     std::to_string(num_points) + " points");
  CheckFinite(data.keyframe_poses, "keyframe_poses");
  CheckFinite(data.points, "points");
  CheckFinite(obs.uv_px, "uv_px");
  CheckFinite(obs.image_velocity_px_s,
              "image_velocity_px_s (give 0 for a track whose velocity is unknown)");
  for (Eigen::Index i = 0; i < n; ++i) {
    if (obs.keyframe[i] < 0 || obs.keyframe[i] >= num_keyframes)
      throw InputError("bundle adjustment: " + Index("observation keyframe", i) + " = " +
                       std::to_string(obs.keyframe[i]) + " is outside 0.." +
                       std::to_string(num_keyframes - 1));
    if (obs.point[i] < 0 || obs.point[i] >= num_points)
      throw InputError("bundle adjustment: " + Index("observation point", i) + " = " +
                       std::to_string(obs.point[i]) + " is outside 0.." +
                       std::to_string(num_points - 1));
  }
  for (Eigen::Index i = 0; i < num_points; ++i)
    if (data.point_anchor[i] < 0 || data.point_anchor[i] >= num_keyframes)
      throw InputError("bundle adjustment: " + Index("point_anchor", i) + " = " +
                       std::to_string(data.point_anchor[i]) + " is outside 0.." +
                       std::to_string(num_keyframes - 1));
  const auto& ld = data.line_delay;
  if (!std::isfinite(ld.value_s) || !std::isfinite(data.reference_row))
    throw InputError("bundle adjustment: the line delay and the reference row must be finite");
  if (ld.mode == LineDelayMode::kPrior &&
      (!std::isfinite(ld.prior_mean_s) || !(ld.prior_sigma_s > 0.0) ||
       !std::isfinite(ld.prior_sigma_s)))
    throw InputError(
        "bundle adjustment: the line delay's prior needs a finite mean and a positive, finite "
        "sigma");
}

std::unique_ptr<ceres::LossFunction> MakeLoss(const std::string& name, double scale) {
  if (name == "huber") return std::make_unique<ceres::HuberLoss>(scale);
  if (name == "cauchy") return std::make_unique<ceres::CauchyLoss>(scale);
  if (name == "soft_l1") return std::make_unique<ceres::SoftLOneLoss>(scale);
  return nullptr;
}

Eigen::Vector3d CameraCentre(const double* pose) {
  const double minus_phi[3] = {-pose[3], -pose[4], -pose[5]};
  Eigen::Vector3d rotated;
  ceres::AngleAxisRotatePoint(minus_phi, pose, rotated.data());
  return -rotated;
}

// The parameter pointers of an observation's residual block, in its cost's order.
struct ObservationBlocks {
  std::vector<double*> blocks;
  bool in_anchor = false;
};

}  // namespace

BundleResult SolveBundle(const camera::CameraModel& camera, const BundleData& data,
                         const BundleOptions& options) {
  CheckOptions(options);
  CheckData(camera, data);
  const int n_cam = static_cast<int>(camera.params().size());
  const int num_keyframes = static_cast<int>(data.keyframe_poses.rows());
  const int num_points = static_cast<int>(data.points.rows());
  const auto& obs = data.observations;
  const int n = static_cast<int>(obs.keyframe.size());

  std::vector<bool> free_param(n_cam, true);
  for (int i = 0; i < data.free_intrinsics.size(); ++i) free_param[i] = data.free_intrinsics[i];
  const int n_free_cam = static_cast<int>(std::count(free_param.begin(), free_param.end(), true));
  const bool estimate_delay = data.line_delay.mode != LineDelayMode::kFixed;
  if (n_free_cam + (estimate_delay ? 1 : 0) == 0)
    throw InputError(
        "bundle adjustment: nothing global to estimate: free_intrinsics frees none of the "
        "camera's parameters and the line delay is fixed");
  if (estimate_delay && !(obs.image_velocity_px_s.array() != 0.0).any())
    throw InputError(
        "bundle adjustment: the line delay cannot be estimated: every image velocity is zero");

  // Memory: Ceres' and the covariance's storage per observation, and the reduced camera matrix
  // (6 x 6 blocks between keyframes that share a point), before anything large is allocated.
  {
    std::vector<std::vector<int>> keyframes_of(num_points);
    for (int i = 0; i < n; ++i) keyframes_of[obs.point[i]].push_back(obs.keyframe[i]);
    double pose_pairs = 0.0;
    for (auto& list : keyframes_of) {
      std::sort(list.begin(), list.end());
      const double m = static_cast<double>(std::unique(list.begin(), list.end()) - list.begin());
      pose_pairs += (m + 1) * (m + 1);
    }
    CheckMemory(n * (1024.0 + 16.0 * kMaxJacobianEntries) + 2.0 * 288.0 * pose_pairs +
                    1024.0 * num_points + 64.0 * 36.0 * num_keyframes,
                "the bundle adjustment of " + std::to_string(num_keyframes) + " keyframes, " +
                    std::to_string(num_points) + " points and " + std::to_string(n) +
                    " observations");
  }

  BundleResult result;
  // The camera, the line delay and the poses in one buffer, in this order: Ceres orders the blocks
  // of an elimination group by address, and separate allocations put the camera at another place
  // among the poses from call to call (the solution then differed in its last bits).
  std::vector<double> globals(n_cam + 1 + 6 * static_cast<size_t>(num_keyframes));
  Eigen::Map<Eigen::VectorXd> intrinsics(globals.data(), n_cam);
  intrinsics = camera.params();
  double& line_delay_us = globals[n_cam];
  line_delay_us = data.line_delay.value_s / kMicroseconds;
  Eigen::Map<KeyframePoseMatrix> poses(globals.data() + n_cam + 1, num_keyframes, 6);
  poses = data.keyframe_poses;
  AnchoredPointMatrix points = data.points;
  const double pixel_size[2] = {camera.pixel_size_mm()[0], camera.pixel_size_mm()[1]};

  // Inverse-depth bounds, relative to the median start depth (the gauge's units): without parallax
  // (a camera only turning) a point's rho is not observed and would wander, onto its anchor's
  // centre (rho -> +-inf) or far beyond infinity; the bounds keep it in a physical range.
  std::vector<double> start_rho;
  for (int j = 0; j < num_points; ++j)
    if (points(j, 2) > 0.0) start_rho.push_back(points(j, 2));
  double rho_low = -std::numeric_limits<double>::infinity();
  double rho_high = std::numeric_limits<double>::infinity();
  if (!start_rho.empty()) {
    std::nth_element(start_rho.begin(), start_rho.begin() + start_rho.size() / 2, start_rho.end());
    const double median_rho = start_rho[start_rho.size() / 2];
    if (options.near_limit > 0.0) rho_high = median_rho / options.near_limit;
    if (options.beyond_infinity_limit >= 0.0) rho_low = -options.beyond_infinity_limit * median_rho;
  }
  for (int j = 0; j < num_points; ++j) points(j, 2) = std::clamp(points(j, 2), rho_low, rho_high);

  // The cost of every observation (kept: they give the residuals and Jacobians afterwards).
  std::vector<std::unique_ptr<ceres::CostFunction>> costs(n);
  std::vector<ObservationBlocks> blocks(n);
  for (int i = 0; i < n; ++i) {
    const int k = obs.keyframe[i], j = obs.point[i], a = data.point_anchor[j];
    const Eigen::Vector2d uv = obs.uv_px.row(i).transpose();
    const Eigen::Vector2d velocity = obs.image_velocity_px_s.row(i).transpose();
    blocks[i].in_anchor = k == a;
    costs[i].reset(ReprojectionCost::Create(camera.type(), pixel_size, uv.data(), velocity.data(),
                                            data.reference_row, k == a));
    if (k == a) {
      blocks[i].blocks = {intrinsics.data(), points.row(j).data(), &line_delay_us};
    } else {
      blocks[i].blocks = {intrinsics.data(), poses.row(a).data(), poses.row(k).data(),
                          points.row(j).data(), &line_delay_us};
    }
  }
  const auto evaluate = [&](int i, double* residual, double** jacobians) {
    return costs[i]->Evaluate(blocks[i].blocks.data(), residual, jacobians) &&
           std::isfinite(residual[0]) && std::isfinite(residual[1]);
  };

  // Observations that cannot be projected at the start are dropped, then points seen < 2 times.
  result.used = Eigen::Matrix<bool, Eigen::Dynamic, 1>::Constant(n, true);
  std::vector<int> seen(num_points, 0);
  for (int i = 0; i < n; ++i) {
    double residual[2];
    result.used[i] = evaluate(i, residual, nullptr);
    if (result.used[i]) ++seen[obs.point[i]];
  }
  std::vector<bool> point_used(num_points);
  for (int j = 0; j < num_points; ++j) point_used[j] = seen[j] >= 2;
  for (int i = 0; i < n; ++i) result.used[i] = result.used[i] && point_used[obs.point[i]];
  result.dropped_observations = static_cast<int>(n - result.used.count());
  for (int j = 0; j < num_points; ++j) result.dropped_points += point_used[j] ? 0 : 1;

  // Keyframes the used observations involve (as observer, or as the anchor of a point seen
  // from another keyframe); the others are held.
  std::vector<bool> involved(num_keyframes, false);
  for (int i = 0; i < n; ++i) {
    if (!result.used[i]) continue;
    involved[obs.keyframe[i]] = true;
    if (!blocks[i].in_anchor) involved[data.point_anchor[obs.point[i]]] = true;
  }
  // Too few observations for the unknowns.
  int num_used_points = 0, num_involved = 0;
  for (int j = 0; j < num_points; ++j) num_used_points += point_used[j] ? 1 : 0;
  for (int k = 1; k < num_keyframes; ++k) num_involved += involved[k] ? 1 : 0;
  const int num_unknowns =
      n_free_cam + (estimate_delay ? 1 : 0) + 6 * num_involved - 1 + 3 * num_used_points;
  const int num_used = static_cast<int>(result.used.count());
  if (2 * num_used <= num_unknowns)
    throw InputError("bundle adjustment: too few observations: " + std::to_string(num_used) +
                     " usable (" + std::to_string(result.dropped_observations) +
                     " dropped: not projectable at the start or on points seen once) give " +
                     std::to_string(2 * num_used) + " residuals for " +
                     std::to_string(num_unknowns) + " unknowns");

  const Eigen::Vector3d first_centre = CameraCentre(poses.row(0).data());
  int scale_keyframe = options.scale_keyframe;
  if (scale_keyframe >= 0) {
    if (scale_keyframe == 0 || scale_keyframe >= num_keyframes || !involved[scale_keyframe])
      throw InputError("bundle adjustment: scale_keyframe " + std::to_string(scale_keyframe) +
                       " must be an observed keyframe other than the first (1.." +
                       std::to_string(num_keyframes - 1) + ")");
  } else {
    double farthest = -1.0;
    for (int k = 1; k < num_keyframes; ++k) {
      if (!involved[k]) continue;
      const double distance = (CameraCentre(poses.row(k).data()) - first_centre).norm();
      if (distance > farthest) farthest = distance, scale_keyframe = k;
    }
  }
  if (scale_keyframe < 0)
    throw InputError("bundle adjustment: no observed keyframe besides the first");
  const double baseline = (CameraCentre(poses.row(scale_keyframe).data()) - first_centre).norm();
  if (!(baseline > 1e-9 * std::max(1.0, first_centre.norm())))
    throw InputError(
        "bundle adjustment: the scale keyframe's camera centre coincides with the first's at the "
        "start (baseline " +
        std::to_string(baseline) +
        " m): the scale is not defined; start from poses with a baseline");
  result.scale_keyframe = scale_keyframe;

  // The problem. Costs, the loss and the manifolds stay ours.
  const std::unique_ptr<ceres::LossFunction> loss =
      MakeLoss(options.robust_loss, options.robust_loss_scale_px);
  PoseManifold pose_manifold;
  BaselineManifold baseline_manifold(new BaselineManifoldFunctor(first_centre));
  std::unique_ptr<ceres::Manifold> intrinsics_manifold;
  if (n_free_cam > 0 && n_free_cam < n_cam) {
    std::vector<int> held;
    for (int i = 0; i < n_cam; ++i)
      if (!free_param[i]) held.push_back(i);
    intrinsics_manifold = std::make_unique<ceres::SubsetManifold>(n_cam, held);
  }
  std::unique_ptr<ceres::CostFunction> prior_cost;
  double prior_weight = 0.0;  // d r / d d of the prior (px per µs/row)
  if (data.line_delay.mode == LineDelayMode::kPrior) {
    prior_weight = options.prior_pixel_sigma_px / (data.line_delay.prior_sigma_s / kMicroseconds);
    prior_cost.reset(LineDelayPriorCost::Create(data.line_delay.prior_mean_s / kMicroseconds,
                                                data.line_delay.prior_sigma_s / kMicroseconds,
                                                options.prior_pixel_sigma_px));
  }
  const auto out_of_range = [&](int j) {
    return point_used[j] && (points(j, 2) < rho_low || points(j, 2) > rho_high);
  };
  // One Ceres solve over the used observations from the current values; bounded: the points'
  // inverse depths held in [rho_low, rho_high]; stop: ends a free solve early.
  const auto solve_once = [&](bool bounded, ceres::IterationCallback* stop) {
    ceres::Problem::Options problem_options;
    problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(problem_options);
    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    problem.AddParameterBlock(intrinsics.data(), n_cam);
    ordering->AddElementToGroup(intrinsics.data(), 1);
    if (n_free_cam == 0) problem.SetParameterBlockConstant(intrinsics.data());
    else if (intrinsics_manifold) problem.SetManifold(intrinsics.data(), intrinsics_manifold.get());
    problem.AddParameterBlock(&line_delay_us, 1);
    ordering->AddElementToGroup(&line_delay_us, 1);
    if (!estimate_delay) problem.SetParameterBlockConstant(&line_delay_us);
    for (int k = 0; k < num_keyframes; ++k) {
      if (!involved[k] && k != 0) continue;
      problem.AddParameterBlock(poses.row(k).data(), 6);
      ordering->AddElementToGroup(poses.row(k).data(), 1);
      if (k == 0) problem.SetParameterBlockConstant(poses.row(k).data());
      else if (k == scale_keyframe) problem.SetManifold(poses.row(k).data(), &baseline_manifold);
      else problem.SetManifold(poses.row(k).data(), &pose_manifold);
    }
    for (int j = 0; j < num_points; ++j) {
      if (!point_used[j]) continue;
      double* point = points.row(j).data();
      problem.AddParameterBlock(point, 3);
      ordering->AddElementToGroup(point, 0);
      if (!bounded) continue;
      if (std::isfinite(rho_low)) problem.SetParameterLowerBound(point, 2, rho_low);
      if (std::isfinite(rho_high)) problem.SetParameterUpperBound(point, 2, rho_high);
    }
    for (int i = 0; i < n; ++i)
      if (result.used[i]) problem.AddResidualBlock(costs[i].get(), loss.get(), blocks[i].blocks);
    if (prior_cost) problem.AddResidualBlock(prior_cost.get(), nullptr, &line_delay_us);

    ceres::Solver::Options solver_options;
    solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    if (options.linear_solver == "dense_schur") {
      solver_options.linear_solver_type = ceres::DENSE_SCHUR;
    } else if (options.linear_solver == "iterative_schur") {
      solver_options.linear_solver_type = ceres::ITERATIVE_SCHUR;
      solver_options.preconditioner_type = ceres::SCHUR_JACOBI;
    } else {
      solver_options.linear_solver_type = ceres::SPARSE_SCHUR;
      solver_options.sparse_linear_algebra_library_type = SparseLibrary();
    }
    solver_options.linear_solver_ordering = ordering;
    SetStopAndLogging(options, &solver_options);
    if (!bounded && options.max_free_iterations > 0)
      solver_options.max_num_iterations =
          std::min(solver_options.max_num_iterations, options.max_free_iterations);
    if (stop != nullptr) {
      solver_options.callbacks.push_back(stop);
      solver_options.update_state_every_iteration = true;  // the callback reads the points
    }
    std::string why;
    if (!solver_options.IsValid(&why)) throw InputError("bundle adjustment: " + why);
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options, &problem, &summary);
    if (options.verbose) std::cout << summary.FullReport() << std::endl;
    return summary;
  };

  // The covariance of the globals at the current values, and their remaining Gauss-Newton step
  // (result.step_sigma).
  const int num_globals_full = n_cam + 1;
  const auto covariance = [&]() {
    result.step_sigma = 0.0;
    result.covariance_ok = false;
    result.covariance_model = Eigen::MatrixXd::Zero(num_globals_full, num_globals_full);
    result.covariance_tracks = result.covariance_model;
    result.covariance_two_way = result.covariance_model;
    result.remaining_step = Eigen::VectorXd::Zero(num_globals_full);

    // The covariance of the globals (global_covariance.hpp) from each observation's Jacobians in
    // the tangent spaces of its blocks.
    const auto covariance_start = std::chrono::steady_clock::now();
    std::vector<int> global_of;  // index in the full (n + 1) layout of each free global
    for (int i = 0; i < n_cam; ++i)
      if (free_param[i]) global_of.push_back(i);
    if (estimate_delay) global_of.push_back(n_cam);
    const int ng = static_cast<int>(global_of.size());
    UnknownLayout layout;
    layout.num_globals = ng;
    layout.num_points = num_points;
    layout.pose_size.assign(num_keyframes, 0);
    std::vector<Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> plus_jacobian(num_keyframes);
    for (int k = 1; k < num_keyframes; ++k) {
      if (!involved[k]) continue;
      plus_jacobian[k].setZero();
      if (k == scale_keyframe) {
        layout.pose_size[k] = 5;
        Eigen::Matrix<double, 6, 5, Eigen::RowMajor> jacobian;
        baseline_manifold.PlusJacobian(poses.row(k).data(), jacobian.data());
        plus_jacobian[k].leftCols(5) = jacobian;
      } else {
        layout.pose_size[k] = 6;
        pose_manifold.PlusJacobian(poses.row(k).data(), plus_jacobian[k].data());
      }
    }
    std::vector<int> used_index;
    for (int i = 0; i < n; ++i)
      if (result.used[i]) used_index.push_back(i);
    std::vector<ObservationLinearisation> linearised(used_index.size());
    std::vector<char> failed(used_index.size(), 0);
    const auto linearise = [&](size_t first, size_t last) {
      Eigen::Matrix<double, 2, 6, Eigen::RowMajor> d_anchor, d_observer;
      Eigen::Matrix<double, 2, 3, Eigen::RowMajor> d_point;
      Eigen::Vector2d d_delay;
      for (size_t u = first; u < last; ++u) {
        const int i = used_index[u];
        auto& out = linearised[u];
        const int k = obs.keyframe[i], j = obs.point[i], a = data.point_anchor[j];
        double residual[2];
        Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor> d_cam(2, n_cam);
        std::vector<double*> jacobians;
        if (blocks[i].in_anchor) jacobians = {d_cam.data(), d_point.data(), d_delay.data()};
        else
          jacobians = {d_cam.data(), d_anchor.data(), d_observer.data(), d_point.data(),
                       d_delay.data()};
        if (!costs[i]->Evaluate(blocks[i].blocks.data(), residual, jacobians.data())) {
          failed[u] = 1;
          continue;
        }
        out.point = j;
        out.keyframe = k;
        out.residual << residual[0], residual[1];
        out.weight = 1.0;
        if (loss != nullptr) {
          double rho[3];
          loss->Evaluate(out.residual.squaredNorm(), rho);
          out.weight = rho[1];
        }
        out.d_r_d_globals.resize(2, ng);
        for (int g = 0; g < ng; ++g)
          out.d_r_d_globals.col(g) = global_of[g] < n_cam ? d_cam.col(global_of[g]) : d_delay;
        out.d_r_d_point = d_point;
        if (blocks[i].in_anchor) continue;
        const int pose_keyframe[2] = {a, k};
        const Eigen::Matrix<double, 2, 6, Eigen::RowMajor>* ambient[2] = {&d_anchor, &d_observer};
        for (int s = 0; s < 2; ++s) {
          if (layout.pose_size[pose_keyframe[s]] == 0) continue;
          out.pose[s] = pose_keyframe[s];
          out.d_r_d_pose[s] = *ambient[s] * plus_jacobian[pose_keyframe[s]];
        }
      }
    };
    {
      const size_t total = used_index.size();
      const int workers = static_cast<int>(std::min<size_t>(options.num_threads, total / 256 + 1));
      std::vector<std::thread> threads;
      for (int w = 1; w < workers; ++w)
        threads.emplace_back(linearise, total * w / workers, total * (w + 1) / workers);
      linearise(0, total / workers);
      for (auto& thread : threads) thread.join();
    }
    if (std::any_of(failed.begin(), failed.end(), [](char f) { return f != 0; })) {
      result.message += "; the covariance was not computed: a residual could not be evaluated";
      return;
    }
    std::vector<GlobalPrior> priors;
    if (data.line_delay.mode == LineDelayMode::kPrior) {
      const double information = prior_weight * prior_weight;
      priors.push_back({ng - 1, information,
                        information * options.prior_pixel_sigma_px * options.prior_pixel_sigma_px});
    }
    const auto linearised_at = std::chrono::steady_clock::now();
    const GlobalCovariances cov = ComputeGlobalCovariances(layout, linearised, priors);
    if (options.verbose)
      std::cout
          << "covariance: linearisation "
          << std::chrono::duration<double>(linearised_at - covariance_start).count()
          << " s, Schur complements and clusters "
          << std::chrono::duration<double>(std::chrono::steady_clock::now() - linearised_at).count()
          << " s" << std::endl;
    // Back to the full layout, the line delay in s/row.
    Eigen::VectorXd unit = Eigen::VectorXd::Ones(ng);
    if (estimate_delay) unit[ng - 1] = kMicroseconds;
    const auto expand = [&](const Eigen::MatrixXd& small) {
      Eigen::MatrixXd full = Eigen::MatrixXd::Zero(num_globals_full, num_globals_full);
      for (int r = 0; r < ng; ++r)
        for (int c = 0; c < ng; ++c)
          full(global_of[r], global_of[c]) = small(r, c) * unit[r] * unit[c];
      return full;
    };
    result.covariance_model = expand(cov.model);
    result.covariance_tracks = expand(cov.by_track);
    result.covariance_two_way = expand(cov.two_way);
    for (int g = 0; g < ng; ++g) {
      result.remaining_step[global_of[g]] = cov.step[g] * unit[g];
      const double sigma = std::sqrt(std::max(cov.model(g, g), 0.0));
      result.step_sigma =
          std::max(result.step_sigma, sigma > 0.0 ? std::abs(cov.step[g]) / sigma
                                                  : std::numeric_limits<double>::infinity());
    }
    result.sigma_px = cov.sigma_px;
    result.dof = cov.dof;
    result.covariance_ok = cov.full_rank && result.covariance_model.allFinite() &&
                           result.covariance_two_way.allFinite();
    result.covariance_time_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - covariance_start).count();
  };

  double solve_time_s = 0.0;
  int iterations = 0;
  double first_cost = std::numeric_limits<double>::quiet_NaN();
  const auto account = [&](const ceres::Solver::Summary& s) {
    if (std::isnan(first_cost)) first_cost = s.initial_cost;
    solve_time_s += s.total_time_in_seconds;
    iterations += static_cast<int>(s.iterations.size()) - 1;
  };
  const auto solve = [&](bool bounded, ceres::IterationCallback* stop) {
    const ceres::Solver::Summary summary = solve_once(bounded, stop);
    account(summary);
    return summary;
  };

  // The points free first (docs/sog.md §23): Ceres' bounds cost a projected line search, with a
  // Jacobian evaluation, in every iteration, and one point held at a bound made a 30 s walk's solve
  // crawl (4x slower). Points that end outside the range are outliers and are dropped, the solve
  // going on from there, while they are few (max_out_of_range_share); more, or a failed solve:
  // again from the start with Ceres' bounds (a camera only turning: depths not observed).
  const bool has_bounds = std::isfinite(rho_low) || std::isfinite(rho_high);
  int points_in_solve = 0;
  for (int j = 0; j < num_points; ++j) points_in_solve += point_used[j] ? 1 : 0;
  const int max_out_of_range =
      static_cast<int>(std::floor(options.max_out_of_range_share * points_in_solve));
  struct TooManyOutOfRange : ceres::IterationCallback {
    std::function<int()> count;
    int limit = 0;
    ceres::CallbackReturnType operator()(const ceres::IterationSummary&) override {
      return count() > limit ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
    }
  };
  ceres::Solver::Summary summary;
  bool solved_free = false;
  if (has_bounds && options.free_points_first) {
    const std::vector<double> start_globals = globals;
    const AnchoredPointMatrix start_points = points;
    const auto start_used = result.used;
    const std::vector<bool> start_point_used = point_used;
    TooManyOutOfRange stop;
    int dropped = 0;
    bool capped = false;
    stop.count = [&] {
      int c = 0;
      for (int j = 0; j < num_points; ++j) c += out_of_range(j) ? 1 : 0;
      return c;
    };
    for (int round = 0; round < kMaxDropRounds; ++round) {
      stop.limit = max_out_of_range - dropped;
      summary = solve(false, &stop);
      if (summary.termination_type == ceres::USER_FAILURE ||
          summary.termination_type == ceres::FAILURE)
        break;
      if (options.max_free_iterations > 0 && summary.termination_type == ceres::NO_CONVERGENCE) {
        capped = true;  // on bounded from here, the points clamped into their range
        break;
      }
      std::vector<int> out;
      for (int j = 0; j < num_points; ++j)
        if (out_of_range(j)) out.push_back(j);
      if (out.empty()) {
        solved_free = true;
        break;
      }
      if (dropped + static_cast<int>(out.size()) > max_out_of_range) break;
      for (int j : out) point_used[j] = false;
      for (int i = 0; i < n; ++i) result.used[i] = result.used[i] && point_used[obs.point[i]];
      dropped += static_cast<int>(out.size());
      // A keyframe left without observations would make the covariance singular: bounded instead.
      std::vector<bool> still(num_keyframes, false);
      for (int i = 0; i < n; ++i) {
        if (!result.used[i]) continue;
        still[obs.keyframe[i]] = true;
        if (!blocks[i].in_anchor) still[data.point_anchor[obs.point[i]]] = true;
      }
      if (still != involved) break;
    }
    if (solved_free) {
      result.points_out_of_range = dropped;
    } else if (capped) {
      result.points_out_of_range = dropped;
      for (int j = 0; j < num_points; ++j)
        points(j, 2) = std::clamp(points(j, 2), rho_low, rho_high);
      result.message = "the free solve reached its iteration cap: on with bounds from there; ";
    } else {  // back to the start, bounded
      globals = start_globals;
      points = start_points;
      result.used = start_used;
      point_used = start_point_used;
      result.message =
          "points left their range in the free solve: solved with bounds from the start; ";
    }
  }
  if (!solved_free) {
    summary = solve(true, nullptr);
  }
  result.solved_with_bounds = has_bounds && !solved_free;
  result.termination = ceres::TerminationTypeToString(summary.termination_type);
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.iterations = iterations;
  result.initial_cost = first_cost;
  result.final_cost = summary.final_cost;
  result.message += summary.message;
  result.solve_time_s = solve_time_s;
  result.camera_params = intrinsics;
  result.line_delay_s = line_delay_us * kMicroseconds;
  result.keyframe_poses = poses;
  result.points = points;
  for (int j = 0; j < num_points; ++j) {
    if (!point_used[j]) continue;
    result.points_beyond_infinity += points(j, 2) < 0.0 ? 1 : 0;
    result.points_at_bounds += points(j, 2) <= rho_low || points(j, 2) >= rho_high ? 1 : 0;
  }

  // Residuals at the solution.
  result.residuals_px = Eigen::MatrixX2d::Constant(n, 2, std::numeric_limits<double>::quiet_NaN());
  result.inlier = Eigen::Matrix<bool, Eigen::Dynamic, 1>::Constant(n, false);
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!result.used[i]) continue;
    double residual[2];
    if (!evaluate(i, residual, nullptr)) continue;  // cannot happen: Ceres keeps them projectable
    result.residuals_px.row(i) << residual[0], residual[1];
    const double norm = std::hypot(residual[0], residual[1]);
    result.inlier[i] = loss == nullptr || norm <= options.robust_loss_scale_px;
    sum_sq += residual[0] * residual[0] + residual[1] * residual[1];
  }
  result.rms_px = std::sqrt(sum_sq / std::max(1, 2 * num_used));

  if (options.compute_covariance) {
    covariance();
  } else {  // zeros of the documented size
    result.covariance_model = Eigen::MatrixXd::Zero(num_globals_full, num_globals_full);
    result.covariance_tracks = result.covariance_two_way = result.covariance_model;
    result.remaining_step = Eigen::VectorXd::Zero(num_globals_full);
  }
  return result;
}

}  // namespace rscalib::bundle
