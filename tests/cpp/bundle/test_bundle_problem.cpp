// SolveBundle on a synthetic room walk (synthetic_scene.hpp): the camera and the line delay
// recovered inside their bounds from a perturbed start; its covariances against a dense
// computation from Ceres' own Jacobian (Problem::Evaluate) in another gauge; input errors.
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include <Eigen/Dense>
#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include "rscalib/bundle/bundle_problem.hpp"
#include "rscalib/bundle/pose_manifold.hpp"
#include "rscalib/bundle/reprojection_cost.hpp"
#include "rscalib/core/error.hpp"
#include "synthetic_scene.hpp"

namespace rscalib::bundle {
namespace {

using testing::MakeScene;
using testing::PerturbStart;
using testing::Scene;
using testing::SceneOptions;

constexpr double kZ99 = 2.5758293035489004;

camera::CameraModel WithParams(const camera::CameraModel& cam, const Eigen::VectorXd& params) {
  return camera::CameraModel(cam.name(), params, cam.width(), cam.height(), cam.pixel_size_mm());
}

// The truth inside value +- 2.576 sqrt(covariance) for every free global.
void ExpectInsideBounds(const BundleResult& result, const Eigen::VectorXd& truth_params,
                        double truth_delay_s, const Eigen::MatrixXd& covariance, const char* what) {
  for (int i = 0; i < truth_params.size(); ++i) {
    const double half = kZ99 * std::sqrt(covariance(i, i));
    EXPECT_GT(half, 0.0) << what << " parameter " << i;
    EXPECT_LE(std::abs(result.camera_params[i] - truth_params[i]), half)
        << what << " parameter " << i << ": " << result.camera_params[i] << " vs "
        << truth_params[i];
  }
  const int d = static_cast<int>(truth_params.size());
  if (covariance(d, d) > 0.0) {
    const double half = kZ99 * std::sqrt(covariance(d, d));
    EXPECT_LE(std::abs(result.line_delay_s - truth_delay_s), half)
        << what << " line delay " << result.line_delay_s << " +- " << half;
  }
}

TEST(SolveBundle, RecoversTheCameraOfAGlobalShutterWalkWithOutliers) {
  SceneOptions options;
  options.outlier_fraction = 0.02;
  Scene scene = MakeScene(options);
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 11);
  scene.data.line_delay.mode = LineDelayMode::kEstimated;
  BundleOptions solve;
  solve.robust_loss_scale_px = 1.0;  // soft_l1
  const BundleResult result = SolveBundle(WithParams(scene.camera, start), scene.data, solve);
  ASSERT_TRUE(result.converged) << result.message;
  EXPECT_TRUE(result.covariance_ok);
  EXPECT_GT(scene.data.observations.keyframe.size(), 5000);
  EXPECT_EQ(result.dropped_observations, 0);
  const Eigen::VectorXd truth = scene.camera.params();
  EXPECT_LT(std::abs(result.camera_params[0] / truth[0] - 1.0), 0.005);
  // the camera, and a line delay of zero, inside their bounds
  ExpectInsideBounds(result, truth, 0.0, result.covariance_two_way, "two-way");
  ExpectInsideBounds(result, truth, 0.0, result.covariance_model, "model");
  // the residuals of the inliers are the simulated noise; the outliers are flagged
  double sum_sq = 0.0;
  int count = 0, flagged = 0, outliers = 0;
  for (int i = 0; i < result.inlier.size(); ++i) {
    outliers += scene.outlier[i] ? 1 : 0;
    flagged += (!result.inlier[i] && scene.outlier[i]) ? 1 : 0;
    if (scene.outlier[i]) continue;
    sum_sq += result.residuals_px.row(i).squaredNorm();
    count += 2;
  }
  EXPECT_NEAR(std::sqrt(sum_sq / count), 0.3, 0.03);
  EXPECT_GT(outliers, 50);
  EXPECT_GT(flagged, 0.8 * outliers);
  EXPECT_LT(result.step_sigma, 0.01);
}

TEST(SolveBundle, RecoversTheLineDelayOfARollingShutter) {
  SceneOptions options;
  options.line_delay_s = 60e-6;
  Scene scene = MakeScene(options);
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 12);
  scene.data.line_delay.mode = LineDelayMode::kEstimated;
  const BundleResult result =
      SolveBundle(WithParams(scene.camera, start), scene.data, BundleOptions());
  ASSERT_TRUE(result.converged) << result.message;
  EXPECT_NEAR(result.line_delay_s, 60e-6, 6e-6);
  ExpectInsideBounds(result, scene.camera.params(), 60e-6, result.covariance_two_way, "two-way");
  EXPECT_NEAR(result.sigma_px, 0.3, 0.03);
  // ignoring the shutter fits worse, and its principal point misses the truth by > 3 sigma
  scene.data.line_delay.mode = LineDelayMode::kFixed;
  const BundleResult global =
      SolveBundle(WithParams(scene.camera, start), scene.data, BundleOptions());
  EXPECT_GT(global.final_cost, 1.03 * result.final_cost);
  EXPECT_GT(std::abs(global.camera_params[1] - scene.camera.params()[1]),
            3.0 * std::sqrt(global.covariance_two_way(1, 1)));
  // a tight prior at the truth narrows the bound of d; the camera stays inside its bounds
  scene.data.line_delay.mode = LineDelayMode::kPrior;
  scene.data.line_delay.prior_mean_s = 60e-6;
  scene.data.line_delay.prior_sigma_s = 0.3e-6;
  const BundleResult prior =
      SolveBundle(WithParams(scene.camera, start), scene.data, BundleOptions());
  const int d = 5;
  EXPECT_LT(prior.covariance_model(d, d), 0.5 * result.covariance_model(d, d));
  EXPECT_LT(std::sqrt(prior.covariance_model(d, d)), 0.4e-6);
  EXPECT_NEAR(prior.line_delay_s, 60e-6, 1e-6);
  ExpectInsideBounds(prior, scene.camera.params(), 60e-6, prior.covariance_two_way, "prior");
}

TEST(SolveBundle, FarPointsAndAHeldCameraParameter) {
  // points 5x further (the room 30 m wide, parallax a few px): rho near 0, the camera still
  // found; cx and cy held at the truth stay there and have zero rows in the covariance
  SceneOptions options;
  options.room_scale = 5.0;
  Scene scene = MakeScene(options);
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 13);
  start[1] = scene.camera.params()[1];
  start[2] = scene.camera.params()[2];
  scene.data.free_intrinsics.setConstant(5, true);
  scene.data.free_intrinsics[1] = scene.data.free_intrinsics[2] = false;
  const BundleResult result =
      SolveBundle(WithParams(scene.camera, start), scene.data, BundleOptions());
  ASSERT_TRUE(result.converged) << result.message;
  EXPECT_EQ(result.camera_params[1], scene.camera.params()[1]);
  EXPECT_EQ(result.covariance_model(1, 1), 0.0);
  EXPECT_EQ(result.covariance_two_way(2, 0), 0.0);
  EXPECT_EQ(result.covariance_model(5, 5), 0.0);  // the line delay is fixed by default
  EXPECT_LT(std::abs(result.camera_params[0] / scene.camera.params()[0] - 1.0), 0.005);
}

TEST(SolveBundle, ACameraOnlyTurningKeepsItsPointsInRange) {
  // 3 mm of translation against 2 cm of start noise: the points' depths are not observed; the
  // inverse-depth bounds keep them off the cameras, the solve converges, and the camera (fixed by
  // the rotation alone) is inside its model bounds (the clustered ones vary from start to start
  // here: cx's from 0.09 to 0.12 px about an estimate 2.4 model sigmas from the truth)
  SceneOptions options;
  options.walk = 0.005;
  Scene scene = MakeScene(options);
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 15);
  const BundleResult result =
      SolveBundle(WithParams(scene.camera, start), scene.data, BundleOptions());
  ASSERT_TRUE(result.converged) << result.message;
  ExpectInsideBounds(result, scene.camera.params(), 0.0, result.covariance_model, "model");
  EXPECT_GT(result.points_at_bounds, 0);
  // many points left their range in the free solve: the answer is that of Ceres' bounds from the
  // start, as with the free solve off
  EXPECT_TRUE(result.solved_with_bounds);
  EXPECT_EQ(result.points_out_of_range, 0);
  BundleOptions ceres_bounds;
  ceres_bounds.free_points_first = false;
  const BundleResult bounded =
      SolveBundle(WithParams(scene.camera, start), scene.data, ceres_bounds);
  for (int i = 0; i < 5; ++i)
    EXPECT_NEAR(result.camera_params[i], bounded.camera_params[i],
                1e-9 * std::abs(bounded.camera_params[i]))
        << "camera parameter " << i;
  const double median = 1.0 / 3.0;  // about: the room's walls 2-4 m away, the scale as the start's
  EXPECT_LE(result.points.col(2).maxCoeff(), 100.0 * median * 2.0);
  BundleOptions unbounded;
  unbounded.near_limit = 0.0;
  unbounded.beyond_infinity_limit = -1.0;
  unbounded.max_iterations = 20;
  const BundleResult wandering =
      SolveBundle(WithParams(scene.camera, start), scene.data, unbounded);
  EXPECT_GT(wandering.points.col(2).cwiseAbs().maxCoeff(),
            result.points.col(2).cwiseAbs().maxCoeff());
}

// One track whose motion fits a point far beyond infinity (rho = -0.6 of the median, the bound is
// -0.1): the free solve drops it as an outlier instead of holding it at the bound, and the camera
// is that of the other points; with the free solve off (Ceres' bounds) it stays, at its bound.
TEST(SolveBundle, APointBeyondInfinityIsDroppedInTheFreeSolve) {
  Scene scene = MakeScene(SceneOptions());
  auto& data = scene.data;
  std::vector<int> seen(data.points.rows(), 0);
  for (Eigen::Index i = 0; i < data.observations.point.size(); ++i)
    ++seen[data.observations.point[i]];
  const int bad = static_cast<int>(std::max_element(seen.begin(), seen.end()) - seen.begin());
  std::vector<double> rho(data.points.col(2).data(),
                          data.points.col(2).data() + data.points.rows());
  std::nth_element(rho.begin(), rho.begin() + rho.size() / 2, rho.end());
  const Eigen::Vector3d beyond(data.points(bad, 0), data.points(bad, 1),
                               -0.6 * rho[rho.size() / 2]);
  const int anchor = data.point_anchor[bad];
  for (Eigen::Index i = 0; i < data.observations.point.size(); ++i) {
    if (data.observations.point[i] != bad) continue;
    Eigen::Vector3d h;
    AnchoredPointInCamera(data.keyframe_poses.row(anchor).data(),
                          data.keyframe_poses.row(data.observations.keyframe[i]).data(),
                          beyond.data(), h.data());
    Eigen::Vector2d uv;
    ASSERT_TRUE(h[2] > 0.0 && scene.camera.Project(h, &uv));
    data.observations.uv_px.row(i) = uv.transpose();
  }
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 16);
  BundleOptions solve;
  solve.robust_loss_scale_px = 1.0;
  const BundleResult result = SolveBundle(WithParams(scene.camera, start), scene.data, solve);
  ASSERT_TRUE(result.converged) << result.message;
  EXPECT_FALSE(result.solved_with_bounds);
  EXPECT_EQ(result.points_out_of_range, 1);
  EXPECT_EQ(result.points_at_bounds, 0);
  for (Eigen::Index i = 0; i < data.observations.point.size(); ++i)
    EXPECT_EQ(result.used[i], data.observations.point[i] != bad);
  ExpectInsideBounds(result, scene.camera.params(), 0.0, result.covariance_two_way, "two-way");
  solve.free_points_first = false;
  const BundleResult held = SolveBundle(WithParams(scene.camera, start), scene.data, solve);
  EXPECT_TRUE(held.solved_with_bounds);
  EXPECT_EQ(held.points_out_of_range, 0);
  EXPECT_GE(held.points_at_bounds, 1);
  EXPECT_EQ(held.used.count(), held.used.size());  // the point stays in the solve, at its bound
}

// The covariances from the Schur complements against dense ones from Ceres' Jacobian of the
// same problem in another gauge (one point's inverse depth held instead of a baseline).
TEST(SolveBundle, CovariancesMatchADenseComputationInAnotherGauge) {
  SceneOptions options;
  options.keyframes = 10;
  options.keyframe_interval_s = 0.2;
  options.points_per_face = 40;
  options.line_delay_s = 40e-6;
  options.outlier_fraction = 0.03;
  Scene scene = MakeScene(options);
  Eigen::VectorXd start;
  PerturbStart(&scene, &start, 14);
  scene.data.line_delay.mode = LineDelayMode::kEstimated;
  BundleOptions solve;
  solve.robust_loss = "soft_l1";
  solve.robust_loss_scale_px = 1.0;
  const BundleResult result = SolveBundle(WithParams(scene.camera, start), scene.data, solve);
  ASSERT_TRUE(result.converged) << result.message;
  ASSERT_EQ(result.dropped_observations, 0);
  const auto& obs = scene.data.observations;
  const int n = static_cast<int>(obs.keyframe.size());
  const int num_points = static_cast<int>(result.points.rows());
  const int num_keyframes = static_cast<int>(result.keyframe_poses.rows());
  ASSERT_GT(n, 400);

  // The problem at the solution, without a loss (the weights are applied below).
  Eigen::VectorXd intrinsics = result.camera_params;
  KeyframePoseMatrix poses = result.keyframe_poses;
  AnchoredPointMatrix points = result.points;
  double delay_us = result.line_delay_s * 1e6;
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  PoseManifold pose_manifold;
  std::vector<int> seen(num_points, 0);
  for (int i = 0; i < n; ++i) ++seen[obs.point[i]];
  const int gauge_point =
      static_cast<int>(std::max_element(seen.begin(), seen.end()) - seen.begin());
  ceres::SubsetManifold hold_rho(3, {2});
  const double pixel_size[2] = {0.0112, 0.0112};
  for (int i = 0; i < n; ++i) {
    const int k = obs.keyframe[i], j = obs.point[i], a = scene.data.point_anchor[j];
    const Eigen::Vector2d uv = obs.uv_px.row(i).transpose();
    const Eigen::Vector2d velocity = obs.image_velocity_px_s.row(i).transpose();
    ceres::CostFunction* cost = ReprojectionCost::Create(scene.camera.type(), pixel_size, uv.data(),
                                                         velocity.data(), 119.5, k == a);
    if (k == a)
      problem.AddResidualBlock(cost, nullptr, intrinsics.data(), points.row(j).data(), &delay_us);
    else
      problem.AddResidualBlock(cost, nullptr, intrinsics.data(), poses.row(a).data(),
                               poses.row(k).data(), points.row(j).data(), &delay_us);
  }
  std::vector<double*> free_blocks = {intrinsics.data(), &delay_us};
  for (int k = 1; k < num_keyframes; ++k) {
    problem.SetManifold(poses.row(k).data(), &pose_manifold);
    free_blocks.push_back(poses.row(k).data());
  }
  problem.SetManifold(points.row(gauge_point).data(), &hold_rho);
  for (int j = 0; j < num_points; ++j) free_blocks.push_back(points.row(j).data());
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.parameter_blocks = free_blocks;
  std::vector<double> residuals;
  ceres::CRSMatrix crs;
  ASSERT_TRUE(problem.Evaluate(evaluate, nullptr, &residuals, nullptr, &crs));
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r)
    for (int e = crs.rows[r]; e < crs.rows[r + 1]; ++e) jacobian(r, crs.cols[e]) = crs.values[e];
  ASSERT_EQ(crs.num_rows, 2 * n);
  const int unknowns = crs.num_cols;
  ASSERT_EQ(unknowns, 5 + 1 + 6 * (num_keyframes - 1) + 3 * num_points - 1);

  // Dense: H = J^T W J with the soft_l1 weights, its inverse, each observation's influence.
  Eigen::VectorXd weight(2 * n);
  double weighted_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    const double sq =
        residuals[2 * i] * residuals[2 * i] + residuals[2 * i + 1] * residuals[2 * i + 1];
    weight[2 * i] = weight[2 * i + 1] = 1.0 / std::sqrt(1.0 + sq / (1.0 * 1.0));
    weighted_sq += weight[2 * i] * sq;
  }
  const Eigen::MatrixXd normal = jacobian.transpose() * weight.asDiagonal() * jacobian;
  const Eigen::MatrixXd inverse = normal.inverse();
  const double sigma2 = weighted_sq / (2 * n - unknowns);
  const int g = 6;  // f, cx, cy, k1, k2, d (µs)
  const Eigen::MatrixXd model = sigma2 * inverse.topLeftCorner(g, g);
  Eigen::MatrixXd per_point = Eigen::MatrixXd::Zero(num_points, g);
  Eigen::MatrixXd per_keyframe = Eigen::MatrixXd::Zero(num_keyframes, g);
  Eigen::MatrixXd per_observation = Eigen::MatrixXd::Zero(g, g);
  const Eigen::Map<const Eigen::VectorXd> r(residuals.data(), 2 * n);
  for (int i = 0; i < n; ++i) {
    const Eigen::VectorXd score = jacobian.middleRows(2 * i, 2).transpose() *
                                  (weight.segment(2 * i, 2).cwiseProduct(r.segment(2 * i, 2)));
    const Eigen::VectorXd influence = (inverse * score).head(g);
    per_point.row(obs.point[i]) += influence.transpose();
    per_keyframe.row(obs.keyframe[i]) += influence.transpose();
    per_observation += influence * influence.transpose();
  }
  const Eigen::MatrixXd by_track =
      per_point.transpose() * per_point * num_points / (num_points - 1.0);
  const Eigen::MatrixXd by_keyframe =
      per_keyframe.transpose() * per_keyframe * num_keyframes / (num_keyframes - 1.0);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(by_track + by_keyframe - per_observation);
  const Eigen::MatrixXd two_way = eigen.eigenvectors() *
                                  eigen.eigenvalues().cwiseMax(0.0).asDiagonal() *
                                  eigen.eigenvectors().transpose();
  // The result's line delay is in s/row: scale the dense ones (µs) to match.
  Eigen::VectorXd unit = Eigen::VectorXd::Ones(g);
  unit[5] = 1e-6;
  const auto compare = [&](const Eigen::MatrixXd& expected, const Eigen::MatrixXd& actual,
                           const char* what) {
    for (int a = 0; a < g; ++a)
      for (int b = 0; b < g; ++b) {
        const double scale = std::sqrt(expected(a, a) * expected(b, b));
        EXPECT_NEAR(actual(a, b), expected(a, b) * unit[a] * unit[b],
                    1e-6 * scale * unit[a] * unit[b])
            << what << " (" << a << ", " << b << ")";
      }
  };
  compare(model, result.covariance_model, "model");
  compare(by_track, result.covariance_tracks, "by track");
  compare(two_way, result.covariance_two_way, "two-way");
  EXPECT_NEAR(result.sigma_px, std::sqrt(sigma2), 1e-9);
}

TEST(SolveBundle, RefusesBadInputWithAReason) {
  Scene scene = MakeScene(SceneOptions());
  const auto expect_error = [&](BundleData data, const std::string& words,
                                BundleOptions options = BundleOptions()) {
    try {
      SolveBundle(scene.camera, data, options);
      ADD_FAILURE() << "no error for " << words;
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find(words), std::string::npos) << error.what();
    }
  };
  BundleData bad = scene.data;
  bad.observations.keyframe[3] = 99;
  expect_error(bad, "outside 0..29");
  bad = scene.data;
  bad.observations.point[0] = -1;
  expect_error(bad, "observation point[0]");
  bad = scene.data;
  bad.observations.uv_px(5, 1) = std::nan("");
  expect_error(bad, "uv_px has a NaN");
  bad = scene.data;
  bad.observations.image_velocity_px_s.conservativeResize(10, 2);
  expect_error(bad, "one row per observation");
  bad = scene.data;
  bad.free_intrinsics.setConstant(5, false);
  expect_error(bad, "nothing global to estimate");
  bad = scene.data;
  bad.free_intrinsics.setConstant(4, true);
  expect_error(bad, "free_intrinsics has 4 entries");
  bad = scene.data;
  bad.line_delay.mode = LineDelayMode::kPrior;
  expect_error(bad, "positive, finite sigma");
  bad = scene.data;
  bad.line_delay.mode = LineDelayMode::kEstimated;
  bad.observations.image_velocity_px_s.setZero();
  expect_error(bad, "every image velocity is zero");
  bad = scene.data;
  for (Eigen::Index k = 1; k < bad.keyframe_poses.rows(); ++k)
    bad.keyframe_poses.row(k) = bad.keyframe_poses.row(0);
  expect_error(bad, "the scale is not defined");
  // a handful of observations for hundreds of unknowns
  bad = scene.data;
  bad.observations.keyframe.conservativeResize(40);
  bad.observations.point.conservativeResize(40);
  bad.observations.uv_px.conservativeResize(40, 2);
  bad.observations.image_velocity_px_s.conservativeResize(40, 2);
  expect_error(bad, "too few observations");
  BundleOptions options;
  options.robust_loss = "tukey";
  expect_error(scene.data, "robust_loss", options);
  options = BundleOptions();
  options.linear_solver = "qr";
  expect_error(scene.data, "linear_solver", options);
}

}  // namespace
}  // namespace rscalib::bundle
