// RsReprojectionAnalyticCost (the Jacobian chained through the basis weights by hand) against
// the autodiff functor RsReprojectionCost (ceres::Jet of all 25 parameters) and central
// differences, for every camera model, random spans, points, times and weights; the same for
// AnalyticIntrinsicsTerm against RsReprojectionIntrinsicsCost (the intrinsics as unknowns).
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <ceres/autodiff_cost_function.h>
#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include "rscalib/rs/rs_reprojection_analytic_cost.hpp"
#include "rscalib/rs/rs_reprojection_cost.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

using namespace rscalib;

namespace {

std::vector<camera::CameraModel> Cameras() {
  Eigen::VectorXd radtan(9), fisheye(8), civera(5);
  radtan << 520, 515, 321, 242, -0.28, 0.09, 1e-3, -5e-4, 0.01;
  fisheye << 380, 382, 318, 236, 0.05, -0.01, 0.004, -0.001;
  civera << 194.06, 160.22, 128.87, 0.06333, 0.0139;
  return {camera::CameraModel("pinhole-radtan", radtan, 640, 480),
          camera::CameraModel("pinhole-equidistant", fisheye, 640, 480),
          camera::CameraModel("civera-radial", civera, 320, 240, Eigen::Vector2d(0.0112, 0.0112))};
}

// A pose spline with non-uniform knots around a camera 0.6 m in front of the target, turning.
spline::CubicBSpline RandomPoseSpline(std::mt19937& rng) {
  std::uniform_real_distribution<double> step(0.05, 0.2), small(-0.08, 0.08), angle(-0.6, 0.6);
  std::vector<double> breaks = {1000.0};  // a large absolute time, as in real videos
  for (int i = 0; i < 8; ++i) breaks.push_back(breaks.back() + step(rng));
  spline::CubicBSpline curve(spline::CubicBSpline::ClampedKnots(breaks),
                             spline::ControlPoints::Zero(static_cast<int>(breaks.size()) + 2, 6));
  for (int i = 0; i < curve.num_control_points(); ++i)
    curve.mutable_control_points().row(i) << small(rng), small(rng), 0.6 + small(rng), angle(rng),
        angle(rng), angle(rng);
  return curve;
}

struct Evaluation {
  double residual[2];
  double jacobian[5][12];  // row-major 2 x block size
};

bool Evaluate(const ceres::CostFunction& cost, const double* const* blocks, Evaluation* out) {
  double* jacobians[5];
  for (int b = 0; b < 5; ++b) jacobians[b] = out->jacobian[b];
  return cost.Evaluate(blocks, out->residual, jacobians);
}

}  // namespace

TEST(RsReprojectionAnalyticCost, EqualsTheAutodiffFunctorAndCentralDifferences) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> unit(0.0, 1.0), offset(-0.05, 0.05), pixel(-3.0, 3.0);
  int compared = 0;
  for (const camera::CameraModel& camera : Cameras()) {
    const rs::SpanCamera cam = rs::MakeSpanCamera(camera);
    for (int trial = 0; trial < 40; ++trial) {
      const spline::CubicBSpline curve = RandomPoseSpline(rng);
      const int span =
          3 + static_cast<int>(unit(rng) * curve.num_segments()) % curve.num_segments();
      const spline::SpanPowerBasis basis = curve.PowerBasis(span);
      const double length = curve.knots()[span + 1] - curve.knots()[span];
      const double point_w[3] = {offset(rng) * 4, offset(rng) * 4, 0.0};
      // The measured pixel near the true projection at a time inside the span.
      const double line_delay = 30e-6 + 60e-6 * unit(rng);
      const double v = unit(rng) * camera.height();
      const double frame_offset = unit(rng) * length - v * line_delay;
      const double* c[4];
      for (int j = 0; j < 4; ++j) c[j] = curve.control_points().data() + 6 * (span - 3 + j);
      double uv_true[2];
      if (!rs::ProjectAtSpanTime(basis, cam, point_w, c, frame_offset + v * line_delay, uv_true))
        continue;
      const double uv[2] = {uv_true[0] + pixel(rng), v};
      const Eigen::Matrix2d weight =
          (Eigen::Matrix2d() << 2.0 + unit(rng), 0.5 * unit(rng), 0.0, 1.5 + unit(rng)).finished();

      const rs::RsReprojectionAnalyticCost analytic(basis, cam, frame_offset, uv, point_w, weight);
      const std::unique_ptr<ceres::CostFunction> autodiff(
          rs::RsReprojectionCost::Create(basis, cam, frame_offset, uv, point_w, weight));
      const ceres::NumericDiffCostFunction<rs::RsReprojectionCost, ceres::CENTRAL, 2, 6, 6, 6, 6, 1>
          numeric(new rs::RsReprojectionCost(basis, cam, frame_offset, uv, point_w, weight));
      const double* blocks[5] = {c[0], c[1], c[2], c[3], &line_delay};
      Evaluation a, r, n;
      ASSERT_TRUE(Evaluate(analytic, blocks, &a));
      ASSERT_TRUE(Evaluate(*autodiff, blocks, &r));
      ASSERT_TRUE(Evaluate(numeric, blocks, &n));
      double residual_only[2];
      ASSERT_TRUE(analytic.Evaluate(blocks, residual_only, nullptr));
      for (int k = 0; k < 2; ++k) {
        EXPECT_NEAR(a.residual[k], r.residual[k], 1e-12 * (1.0 + std::abs(r.residual[k])));
        EXPECT_NEAR(residual_only[k], r.residual[k], 1e-12 * (1.0 + std::abs(r.residual[k])));
      }
      for (int b = 0; b < 5; ++b) {
        const int size = b < 4 ? 12 : 2;
        double scale = 0.0;  // of the block: entries that are ~0 by cancellation compare to it
        for (int k = 0; k < size; ++k) scale = std::max(scale, std::abs(r.jacobian[b][k]));
        for (int k = 0; k < size; ++k) {
          EXPECT_NEAR(a.jacobian[b][k], r.jacobian[b][k], 1e-9 * scale)
              << camera.name() << " block " << b << " entry " << k;
          // central differences: rounding of the ~10-unit residual over steps of ~1e-8 (2e-5)
          EXPECT_NEAR(a.jacobian[b][k], n.jacobian[b][k], 1e-5 * scale + 2e-5)
              << camera.name() << " block " << b << " entry " << k;
        }
      }
      ++compared;
    }
  }
  EXPECT_GT(compared, 100);
}

TEST(RsReprojectionAnalyticCost, LeavesOutTheJacobiansItIsNotAskedFor) {
  std::mt19937 rng(3);
  const spline::CubicBSpline curve = RandomPoseSpline(rng);
  const camera::CameraModel camera = Cameras()[0];
  const rs::SpanCamera cam = rs::MakeSpanCamera(camera);
  const int span = 5;
  const double point_w[3] = {0.05, -0.03, 0.0}, uv[2] = {300.0, 200.0}, line_delay = 40e-6;
  const rs::RsReprojectionAnalyticCost cost(curve.PowerBasis(span), cam, 0.01, uv, point_w,
                                            Eigen::Matrix2d::Identity());
  const double* blocks[5];
  for (int j = 0; j < 4; ++j) blocks[j] = curve.control_points().data() + 6 * (span - 3 + j);
  blocks[4] = &line_delay;
  double residual[2], only_d[2], all[5][12];
  double* some[5] = {nullptr, nullptr, nullptr, nullptr, only_d};
  double* every[5] = {all[0], all[1], all[2], all[3], all[4]};
  ASSERT_TRUE(cost.Evaluate(blocks, residual, some));
  ASSERT_TRUE(cost.Evaluate(blocks, residual, every));
  EXPECT_EQ(only_d[0], all[4][0]);
  EXPECT_EQ(only_d[1], all[4][1]);
  EXPECT_GT(std::abs(only_d[0]) + std::abs(only_d[1]), 1.0);  // d is observable
}

TEST(RsReprojectionGroupCost, StacksTheErrorsOfItsMembers) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> unit(0.0, 1.0), offset(-0.1, 0.1);
  const spline::CubicBSpline curve = RandomPoseSpline(rng);
  const camera::CameraModel camera = Cameras()[1];
  const rs::SpanCamera cam = rs::MakeSpanCamera(camera);
  const int span = 6;
  const spline::SpanPowerBasis basis = curve.PowerBasis(span);
  const double line_delay = 45e-6,
               frame_offset = 0.2 * (curve.knots()[span + 1] - curve.knots()[span]);
  std::vector<rs::AnalyticReprojectionTerm> members;
  for (int m = 0; m < 7; ++m) {
    const double point_w[3] = {offset(rng), offset(rng), 0.0};
    const double uv[2] = {640 * unit(rng), 480 * unit(rng)};
    members.emplace_back(basis, cam, frame_offset, uv, point_w,
                         Eigen::Matrix2d::Identity() * (1.0 + unit(rng)));
  }
  const rs::RsReprojectionGroupCost group(members);
  ASSERT_EQ(group.num_residuals(), 14);
  const double* blocks[5];
  for (int j = 0; j < 4; ++j) blocks[j] = curve.control_points().data() + 6 * (span - 3 + j);
  blocks[4] = &line_delay;
  std::vector<double> residuals(14);
  std::vector<std::vector<double>> jacobian(5);
  double* jacobians[5];
  for (int b = 0; b < 5; ++b) {
    jacobian[b].resize(14 * (b < 4 ? 6 : 1));
    jacobians[b] = jacobian[b].data();
  }
  jacobians[2] = nullptr;  // a block held constant
  ASSERT_TRUE(group.Evaluate(blocks, residuals.data(), jacobians));
  for (int m = 0; m < 7; ++m) {
    const rs::RsReprojectionAnalyticCost single(basis, cam, frame_offset, members[m].measurement.uv,
                                                members[m].measurement.point_w,
                                                members[m].measurement.sqrt_information);
    Evaluation one;
    ASSERT_TRUE(Evaluate(single, blocks, &one));
    for (int k = 0; k < 2; ++k) EXPECT_EQ(residuals[2 * m + k], one.residual[k]);
    for (int b = 0; b < 5; ++b) {
      if (b == 2) continue;
      const int size = b < 4 ? 6 : 1;
      for (int k = 0; k < 2 * size; ++k)
        EXPECT_EQ(jacobian[b][2 * m * size + k], one.jacobian[b][k]) << "member " << m;
    }
  }
}

TEST(AnalyticIntrinsicsTerm, EqualsTheAutodiffFunctorAndCentralDifferences) {
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> unit(0.0, 1.0), offset(-0.05, 0.05), pixel(-3.0, 3.0);
  constexpr int kTheta = rs::kIntrinsicsBlockSize;
  const int sizes[6] = {6, 6, 6, 6, 1, kTheta};
  int compared = 0;
  for (const camera::CameraModel& camera : Cameras()) {
    const rs::CameraModelOf model(camera);
    const rs::SpanCamera cam = rs::MakeSpanCamera(camera);
    rs::IntrinsicsVector theta = rs::IntrinsicsVector::Zero();
    theta.head(camera.params().size()) = camera.params();
    for (int trial = 0; trial < 30; ++trial) {
      const spline::CubicBSpline curve = RandomPoseSpline(rng);
      const int span =
          3 + static_cast<int>(unit(rng) * curve.num_segments()) % curve.num_segments();
      const spline::SpanPowerBasis basis = curve.PowerBasis(span);
      const double length = curve.knots()[span + 1] - curve.knots()[span];
      const double point_w[3] = {offset(rng) * 4, offset(rng) * 4, 0.0};
      const double line_delay = 30e-6 + 60e-6 * unit(rng);
      const double v = unit(rng) * camera.height();
      const double frame_offset = unit(rng) * length - v * line_delay;
      const double* c[4];
      for (int j = 0; j < 4; ++j) c[j] = curve.control_points().data() + 6 * (span - 3 + j);
      double uv_true[2];
      if (!rs::ProjectAtSpanTime(basis, cam, point_w, c, frame_offset + v * line_delay, uv_true))
        continue;
      const double uv[2] = {uv_true[0] + pixel(rng), v};
      const Eigen::Matrix2d weight =
          (Eigen::Matrix2d() << 2.0 + unit(rng), 0.5 * unit(rng), 0.0, 1.5 + unit(rng)).finished();

      const rs::AnalyticIntrinsicsTerm term(basis, model, frame_offset, uv, point_w, weight);
      const rs::RsReprojectionIntrinsicsGroupCost analytic({term});
      const std::unique_ptr<ceres::CostFunction> autodiff(rs::RsReprojectionIntrinsicsCost::Create(
          basis, model, frame_offset, uv, point_w, weight));
      const ceres::NumericDiffCostFunction<rs::RsReprojectionIntrinsicsCost, ceres::CENTRAL, 2, 6,
                                           6, 6, 6, 1, kTheta>
          numeric(new rs::RsReprojectionIntrinsicsCost(basis, model, frame_offset, uv, point_w,
                                                       weight));
      const double* blocks[6] = {c[0], c[1], c[2], c[3], &line_delay, theta.data()};
      double residual[3][2], jacobian[3][6][2 * kTheta];
      const ceres::CostFunction* costs[3] = {&analytic, autodiff.get(), &numeric};
      for (int f = 0; f < 3; ++f) {
        double* jacobians[6];
        for (int b = 0; b < 6; ++b) jacobians[b] = jacobian[f][b];
        ASSERT_TRUE(costs[f]->Evaluate(blocks, residual[f], jacobians));
      }
      double residual_only[2];
      ASSERT_TRUE(term.Evaluate(blocks, residual_only, nullptr));
      for (int k = 0; k < 2; ++k) {
        EXPECT_NEAR(residual[0][k], residual[1][k], 1e-12 * (1.0 + std::abs(residual[1][k])));
        EXPECT_NEAR(residual_only[k], residual[1][k], 1e-12 * (1.0 + std::abs(residual[1][k])));
      }
      for (int b = 0; b < 6; ++b) {
        double scale = 0.0;
        for (int k = 0; k < 2 * sizes[b]; ++k) scale = std::max(scale, std::abs(jacobian[1][b][k]));
        for (int k = 0; k < 2 * sizes[b]; ++k) {
          EXPECT_NEAR(jacobian[0][b][k], jacobian[1][b][k], 1e-9 * scale + 1e-12)
              << camera.name() << " block " << b << " entry " << k;
          // central differences: relative steps of ~1e-6 on f ~ 500 px and on k ~ 0.1
          EXPECT_NEAR(jacobian[0][b][k], jacobian[2][b][k], 1e-5 * scale + 2e-5)
              << camera.name() << " block " << b << " entry " << k;
        }
      }
      // the intrinsics are observable: the focal length moves the error
      EXPECT_GT(std::abs(jacobian[0][5][0]) + std::abs(jacobian[0][5][kTheta]), 1e-3);
      ++compared;
    }
  }
  EXPECT_GT(compared, 70);
}
