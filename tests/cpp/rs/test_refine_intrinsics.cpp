// The functors of the joint refinement of the intrinsics (docs/formulation.md §14):
// autodiff (ceres::Jet) against central differences (ceres::NumericDiff, double).
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include "rscalib/core/error.hpp"
#include "rscalib/rs/intrinsics_prior_cost.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"
#include "rscalib/rs/rs_reprojection_intrinsics_cost.hpp"
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

// Evaluates `cost` at `blocks`; returns residual and row-major Jacobians.
void Evaluate(const ceres::CostFunction& cost, const std::vector<const double*>& blocks,
              std::vector<double>* residual, std::vector<std::vector<double>>* jacobians) {
  const int num_residuals = cost.num_residuals();
  residual->assign(num_residuals, 0.0);
  jacobians->resize(blocks.size());
  std::vector<double*> pointers;
  for (size_t b = 0; b < blocks.size(); ++b) {
    (*jacobians)[b].assign(num_residuals * cost.parameter_block_sizes()[b], 0.0);
    pointers.push_back((*jacobians)[b].data());
  }
  ASSERT_TRUE(cost.Evaluate(blocks.data(), residual->data(), pointers.data()));
}

void ExpectSameJacobians(const std::vector<std::vector<double>>& a,
                         const std::vector<std::vector<double>>& b, double relative) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k)
    for (size_t i = 0; i < a[k].size(); ++i)
      EXPECT_NEAR(a[k][i], b[k][i], relative * (1.0 + std::abs(a[k][i])))
          << "block " << k << " entry " << i;
}

struct Case {
  const char* model;
  std::vector<double> params;
};

}  // namespace

TEST(RsReprojectionIntrinsicsCost, AutodiffMatchesNumericDiffForEveryBlock) {
  const std::vector<Case> cases = {
      {"pinhole-radtan", {500, 505, 320, 240, -0.2, 0.05, 1e-3, -1e-3, 0.01}},
      {"pinhole-equidistant", {420, 418, 330, 236, 0.02, -0.01, 0.003, -0.001}},
  };
  std::mt19937 rng(11);
  for (const Case& c : cases) {
    const auto curve = RandomPoseSpline(rng);
    const Eigen::VectorXd params =
        Eigen::Map<const Eigen::VectorXd>(c.params.data(), c.params.size());
    const camera::CameraModel cam(c.model, params, 640, 480);
    const rs::CameraModelOf model(cam);
    const int span = 5;
    const auto basis = curve.PowerBasis(span);
    const double uv[2] = {300.0, 200.0}, point_w[3] = {0.05, -0.03, 0.0};
    const Eigen::Matrix2d weight = (Eigen::Matrix2d() << 2.0, 0.3, 0.0, 1.5).finished();
    const double frame_offset = 0.1;
    std::unique_ptr<ceres::CostFunction> autodiff(
        rs::RsReprojectionIntrinsicsCost::Create(basis, model, frame_offset, uv, point_w, weight));
    std::unique_ptr<ceres::CostFunction> numeric(
        new ceres::NumericDiffCostFunction<rs::RsReprojectionIntrinsicsCost, ceres::CENTRAL, 2, 6,
                                           6, 6, 6, 1, rs::kIntrinsicsBlockSize>(
            new rs::RsReprojectionIntrinsicsCost(basis, model, frame_offset, uv, point_w, weight)));
    double line_delay = 60e-6;
    rs::IntrinsicsVector intrinsics = rs::IntrinsicsVector::Zero();
    intrinsics.head(params.size()) = params;
    std::vector<const double*> blocks;
    for (int j = 0; j < 4; ++j)
      blocks.push_back(curve.control_points().data() + 6 * (span - 3 + j));
    blocks.push_back(&line_delay);
    blocks.push_back(intrinsics.data());
    std::vector<double> r_a, r_n;
    std::vector<std::vector<double>> j_a, j_n;
    Evaluate(*autodiff, blocks, &r_a, &j_a);
    Evaluate(*numeric, blocks, &r_n, &j_n);
    EXPECT_NEAR(r_a[0], r_n[0], 1e-12) << c.model;
    EXPECT_NEAR(r_a[1], r_n[1], 1e-12) << c.model;
    ExpectSameJacobians(j_a, j_n, 1e-5);
    // d r / d fx and d r / d cx are not zero: the intrinsics are observable.
    EXPECT_GT(std::abs(j_a[5][0]), 1e-3) << c.model;
    EXPECT_NEAR(j_a[5][2], -weight(0, 0), 1e-12) << c.model;  // r0 = w00 (u - cx - ...) ...
    // Padding entries beyond the model's parameters do not enter.
    for (int i = static_cast<int>(params.size()); i < rs::kIntrinsicsBlockSize; ++i)
      EXPECT_EQ(j_a[5][i], 0.0) << c.model << " padding " << i;

    // With the intrinsics at the camera's values it is the known-camera cost, exactly.
    const rs::SpanCamera span_camera = rs::MakeSpanCamera(cam);
    std::unique_ptr<ceres::CostFunction> known(
        rs::RsReprojectionCost::Create(basis, span_camera, frame_offset, uv, point_w, weight));
    std::vector<double> r_k;
    std::vector<std::vector<double>> j_k;
    Evaluate(*known, std::vector<const double*>(blocks.begin(), blocks.end() - 1), &r_k, &j_k);
    EXPECT_EQ(r_a[0], r_k[0]);
    EXPECT_EQ(r_a[1], r_k[1]);
    for (int b = 0; b < 5; ++b)
      for (size_t i = 0; i < j_k[b].size(); ++i) EXPECT_NEAR(j_a[b][i], j_k[b][i], 1e-12);
  }
}

TEST(IntrinsicsPriorCost, IsTheMahalanobisDistanceOverTheFreeParameters) {
  const int n = 9;
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd a(n, n);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) a(r, c) = normal(rng);
  const Eigen::MatrixXd covariance = a * a.transpose() + 0.5 * Eigen::MatrixXd::Identity(n, n);
  const std::vector<int> fixed = {8};  // k3 held
  const rs::IntrinsicsMatrix s = rs::IntrinsicsPriorSqrtInformation(covariance, fixed);
  rs::IntrinsicsVector mean, value;
  for (int i = 0; i < n; ++i) {
    mean[i] = normal(rng);
    value[i] = mean[i] + normal(rng);
  }
  std::unique_ptr<ceres::CostFunction> autodiff(rs::IntrinsicsPriorCost::Create(mean, s));
  std::unique_ptr<ceres::CostFunction> numeric(
      new ceres::NumericDiffCostFunction<rs::IntrinsicsPriorCost, ceres::CENTRAL,
                                         rs::kIntrinsicsBlockSize, rs::kIntrinsicsBlockSize>(
          new rs::IntrinsicsPriorCost(mean, s)));
  std::vector<double> r_a, r_n;
  std::vector<std::vector<double>> j_a, j_n;
  Evaluate(*autodiff, {value.data()}, &r_a, &j_a);
  Evaluate(*numeric, {value.data()}, &r_n, &j_n);
  ExpectSameJacobians(j_a, j_n, 1e-7);

  const Eigen::VectorXd free_diff = (value - mean).head(8);
  const double expected = free_diff.dot(covariance.topLeftCorner(8, 8).ldlt().solve(free_diff));
  double cost = 0.0;
  for (double r : r_a) cost += r * r;
  EXPECT_NEAR(cost, expected, 1e-9 * expected);
  // The fixed parameter neither costs nor pulls.
  for (int r = 0; r < n; ++r) EXPECT_EQ(j_a[0][r * n + 8], 0.0);
  EXPECT_EQ(r_a[8], 0.0);
}

TEST(IntrinsicsPriorCost, RejectsCovariancesThatAreNotPositiveDefinite) {
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Identity(4, 4);
  covariance(2, 2) = -1.0;
  EXPECT_THROW(rs::IntrinsicsPriorSqrtInformation(covariance, {}), InputError);
  EXPECT_NO_THROW(rs::IntrinsicsPriorSqrtInformation(covariance, {2}));  // held: ignored
  EXPECT_THROW(rs::IntrinsicsPriorSqrtInformation(covariance, {4}), InputError);
  EXPECT_THROW(rs::IntrinsicsPriorSqrtInformation(Eigen::MatrixXd::Identity(3, 4), {}), InputError);
}
