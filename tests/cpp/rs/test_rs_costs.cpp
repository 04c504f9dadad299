#include <memory>
#include <random>

#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include "rscalib/rs/error_standardisation.hpp"
#include "rscalib/rs/motion_prior_cost.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

using namespace rscalib;

namespace {

spline::CubicBSpline RandomPoseSpline(std::mt19937& rng) {
  auto curve = spline::CubicBSpline::Uniform(0.0, 2.0, 6, 6);
  std::uniform_real_distribution<double> small(-0.05, 0.05);
  for (int i = 0; i < curve.num_control_points(); ++i) {
    curve.mutable_control_points().row(i) << small(rng), small(rng), 0.6 + small(rng), small(rng),
        small(rng), small(rng);
  }
  return curve;
}

}  // namespace

TEST(RsReprojectionCost, AutodiffMatchesNumericDiffIncludingLineDelay) {
  std::mt19937 rng(7);
  const auto curve = RandomPoseSpline(rng);
  Eigen::VectorXd params(9);
  params << 500, 500, 320, 240, -0.2, 0.05, 1e-3, -1e-3, 0.0;
  const camera::CameraModel cam("pinhole-radtan", params, 640, 480);
  const rs::SpanCamera span_camera{cam.type(), cam.params().data(), 9, cam.pixel_size_mm().data()};
  const int span = 5;
  const auto basis = curve.PowerBasis(span);
  const double uv[2] = {300.0, 200.0}, point_w[3] = {0.05, -0.03, 0.0};
  const Eigen::Matrix2d weight = (Eigen::Matrix2d() << 2.0, 0.3, 0.0, 1.5).finished();
  const double frame_offset = 0.1;
  std::unique_ptr<ceres::CostFunction> autodiff(
      rs::RsReprojectionCost::Create(basis, span_camera, frame_offset, uv, point_w, weight));
  std::unique_ptr<ceres::CostFunction> numeric(
      new ceres::NumericDiffCostFunction<rs::RsReprojectionCost, ceres::CENTRAL, 2, 6, 6, 6, 6, 1>(
          new rs::RsReprojectionCost(basis, span_camera, frame_offset, uv, point_w, weight)));
  double line_delay = 60e-6;
  const double* blocks[5];
  for (int j = 0; j < 4; ++j) blocks[j] = curve.control_points().data() + 6 * (span - 3 + j);
  blocks[4] = &line_delay;
  double r_a[2], r_n[2];
  std::vector<std::vector<double>> j_a(5), j_n(5);
  double* ja[5];
  double* jn[5];
  for (int b = 0; b < 5; ++b) {
    const int size = b < 4 ? 12 : 2;
    j_a[b].resize(size);
    j_n[b].resize(size);
    ja[b] = j_a[b].data();
    jn[b] = j_n[b].data();
  }
  ASSERT_TRUE(autodiff->Evaluate(blocks, r_a, ja));
  ASSERT_TRUE(numeric->Evaluate(blocks, r_n, jn));
  EXPECT_NEAR(r_a[0], r_n[0], 1e-12);
  EXPECT_NEAR(r_a[1], r_n[1], 1e-12);
  for (int b = 0; b < 5; ++b)
    for (size_t k = 0; k < j_a[b].size(); ++k)
      EXPECT_NEAR(j_a[b][k], j_n[b][k], 1e-5 * (1.0 + std::abs(j_a[b][k])))
          << "block " << b << " entry " << k;
  // d r / d d is not zero: the line delay is observable through the spline's time derivative.
  EXPECT_GT(std::abs(j_a[4][0]) + std::abs(j_a[4][1]), 1.0);
}

TEST(MotionPriorCost, EqualsTheIntegralOfWeightedSquaredAcceleration) {
  std::mt19937 rng(8);
  const auto curve = RandomPoseSpline(rng);
  Eigen::Matrix<double, 6, 1> q;
  q << 1.0, 2.0, 0.5, 10.0, 20.0, 5.0;
  for (int span = 3; span < curve.num_control_points(); ++span) {
    std::unique_ptr<ceres::CostFunction> cost(
        rs::MotionPriorCost::Create(curve.knots().data(), span, q));
    const double* blocks[4];
    for (int j = 0; j < 4; ++j) blocks[j] = curve.control_points().data() + 6 * (span - 3 + j);
    double r[12];
    ASSERT_TRUE(cost->Evaluate(blocks, r, nullptr));
    double sum = 0.0;
    for (double x : r) sum += x * x;
    // Midpoint rule with many samples as the independent reference.
    const double a = curve.knots()[span], b = curve.knots()[span + 1];
    const int n = 20000;
    double integral = 0.0;
    for (int k = 0; k < n; ++k) {
      const Eigen::VectorXd acc = curve.Evaluate(a + (k + 0.5) * (b - a) / n, 2);
      integral += (acc.array().square() / q.array()).sum() * (b - a) / n;
    }
    EXPECT_NEAR(sum, integral, 1e-6 * integral);
  }
}

TEST(ErrorStandardisation, WhitensTheErrorCovariance) {
  const double d = 80e-6, sigma = 0.4;
  const Eigen::Vector2d velocity(900.0, -2500.0);
  const Eigen::Matrix2d a = rs::ErrorNoiseMap(d, velocity);
  const auto w = rs::ComputeStandardisationWeight(d, velocity, sigma, 0.8);
  const Eigen::Matrix2d whitened =
      w.sqrt_information * (sigma * sigma * a * a.transpose()) * w.sqrt_information.transpose();
  EXPECT_LT((whitened - Eigen::Matrix2d::Identity()).norm(), 1e-12);
  EXPECT_FALSE(w.clamped);
  EXPECT_TRUE(
      rs::ComputeStandardisationWeight(d, Eigen::Vector2d(0.0, 20000.0), sigma, 0.8).clamped);
}
