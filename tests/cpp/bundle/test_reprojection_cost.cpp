// The anchored inverse-depth point, the reprojection functor (double and ceres::Jet, against a
// direct computation and central differences) and the pose manifolds of the bundle adjustment.
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <ceres/autodiff_cost_function.h>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "rscalib/bundle/anchored_point.hpp"
#include "rscalib/bundle/baseline_manifold.hpp"
#include "rscalib/bundle/line_delay_prior_cost.hpp"
#include "rscalib/bundle/pose_manifold.hpp"
#include "rscalib/bundle/reprojection_cost.hpp"
#include "rscalib/camera/camera_model.hpp"
#include "rscalib/geometry/pose.hpp"

namespace rscalib::bundle {
namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;

Vector6d RandomPose(std::mt19937* rng, double angle = 0.4) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Vector6d pose;
  for (int i = 0; i < 3; ++i) pose[i] = 0.3 * normal(*rng);
  for (int i = 3; i < 6; ++i) pose[i] = angle * normal(*rng);
  return pose;
}

// A world point in front of both cameras (about 2 m ahead of the anchor).
Eigen::Vector3d PointAhead(const Vector6d& anchor, std::mt19937* rng) {
  std::uniform_real_distribution<double> uniform(-0.3, 0.3);
  const Eigen::Vector3d in_anchor(uniform(*rng), uniform(*rng), 2.0 + uniform(*rng));
  const Eigen::Vector3d abr(in_anchor[0] / in_anchor[2], in_anchor[1] / in_anchor[2],
                            1.0 / in_anchor[2]);
  return WorldPointFromAnchored(anchor.data(), abr);
}

camera::CameraModel Camera(const std::string& model) {
  if (model == "civera-radial") {
    Eigen::VectorXd p(5);
    p << 194.06, 160.22, 128.87, 0.06333, 0.0139;
    return camera::CameraModel(model, p, 320, 240, Eigen::Vector2d(0.0112, 0.0112));
  }
  if (model == "pinhole-radtan") {
    Eigen::VectorXd p(9);
    p << 520.0, 515.0, 320.5, 240.2, -0.21, 0.08, 1e-3, -5e-4, -0.01;
    return camera::CameraModel(model, p, 640, 480);
  }
  Eigen::VectorXd p(8);
  p << 300.0, 301.0, 320.0, 240.0, 0.05, -0.01, 0.002, -0.0005;
  return camera::CameraModel(model, p, 640, 480);
}

TEST(AnchoredPoint, MatchesTheXyzProjection) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 50; ++trial) {
    const Vector6d anchor = RandomPose(&rng), observer = RandomPose(&rng, 0.1);
    const Eigen::Vector3d x_w = PointAhead(anchor, &rng);
    Eigen::Vector3d abr;
    ASSERT_TRUE(AnchoredPointFromWorld(anchor.data(), x_w, &abr));
    Eigen::Vector3d expected, h, in_anchor, h_anchor;
    geometry::TransformWorldToCamera(observer.data(), x_w.data(), expected.data());
    AnchoredPointInCamera(anchor.data(), observer.data(), abr.data(), h.data());
    EXPECT_LT((h / abr[2] - expected).norm(), 1e-12 * expected.norm());
    // in its anchor: the ray (a, b, 1), from either formula
    geometry::TransformWorldToCamera(anchor.data(), x_w.data(), in_anchor.data());
    AnchoredPointInAnchor(abr.data(), h_anchor.data());
    EXPECT_LT((h_anchor * in_anchor[2] - in_anchor).norm(), 1e-12);
    AnchoredPointInCamera(anchor.data(), anchor.data(), abr.data(), h.data());
    EXPECT_LT((h - h_anchor).norm(), 1e-12);
    EXPECT_LT((WorldPointFromAnchored(anchor.data(), abr) - x_w).norm(), 1e-12);
  }
}

TEST(AnchoredPoint, FarPointsTendToTheirDirection) {
  std::mt19937 rng(4);
  const Vector6d anchor = RandomPose(&rng), observer = RandomPose(&rng);
  const Eigen::Vector3d ray(0.1, -0.05, 1.0);
  Eigen::Vector3d at_infinity, direction;
  const Eigen::Vector3d abr(ray[0], ray[1], 0.0);
  AnchoredPointInCamera(anchor.data(), observer.data(), abr.data(), at_infinity.data());
  // the direction rotated by R_j R_a^T, without translation
  const double minus_phi[3] = {-anchor[3], -anchor[4], -anchor[5]};
  Eigen::Vector3d in_world;
  ceres::AngleAxisRotatePoint(minus_phi, ray.data(), in_world.data());
  ceres::AngleAxisRotatePoint(observer.data() + 3, in_world.data(), direction.data());
  EXPECT_LT((at_infinity - direction).norm(), 1e-14);
  // and a point 1 km away projects within 1e-3 of it
  const Eigen::Vector3d far(ray[0], ray[1], 1e-3);
  Eigen::Vector3d h;
  AnchoredPointInCamera(anchor.data(), observer.data(), far.data(), h.data());
  EXPECT_LT((h - direction).norm(), 1e-3);
  EXPECT_GT((h - direction).norm(), 1e-5);
}

struct CostCase {
  std::string model;
  bool in_anchor;
};

class ReprojectionCostTest : public ::testing::TestWithParam<CostCase> {};

// The residual and its autodiff Jacobians at a random configuration, the blocks as Create's.
struct Evaluation {
  Eigen::Vector2d residual;
  std::vector<Eigen::MatrixXd> jacobians;
};

TEST_P(ReprojectionCostTest, ValueMatchesADirectComputationAndJacobiansCentralDifferences) {
  const CostCase c = GetParam();
  const camera::CameraModel cam = Camera(c.model);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 10; ++trial) {
    const Vector6d anchor = RandomPose(&rng, 0.1);
    const Vector6d observer = c.in_anchor ? anchor : RandomPose(&rng, 0.05);
    // anchor and observer both look along +z of the world roughly: the point 2 m ahead
    const Eigen::Vector3d x_w = PointAhead(anchor, &rng);
    Eigen::Vector3d abr;
    ASSERT_TRUE(AnchoredPointFromWorld(anchor.data(), x_w, &abr));
    Eigen::Vector3d x_c;
    geometry::TransformWorldToCamera(observer.data(), x_w.data(), x_c.data());
    Eigen::Vector2d uv_true;
    ASSERT_TRUE(cam.Project(x_c, &uv_true));
    const Eigen::Vector2d uv_obs = uv_true + Eigen::Vector2d(0.7, -0.4);
    const Eigen::Vector2d velocity(120.0, -45.0);
    const double reference_row = cam.height() / 2.0 - 0.5;
    double line_delay_us = 31.0;
    Eigen::VectorXd intrinsics = cam.params();
    const double pixel_size[2] = {cam.pixel_size_mm()[0], cam.pixel_size_mm()[1]};
    std::unique_ptr<ceres::CostFunction> cost(ReprojectionCost::Create(
        cam.type(), pixel_size, uv_obs.data(), velocity.data(), reference_row, c.in_anchor));
    Vector6d anchor_block = anchor, observer_block = observer;
    std::vector<double*> blocks;
    if (c.in_anchor) blocks = {intrinsics.data(), abr.data(), &line_delay_us};
    else
      blocks = {intrinsics.data(), anchor_block.data(), observer_block.data(), abr.data(),
                &line_delay_us};
    ASSERT_EQ(cost->parameter_block_sizes().size(), blocks.size());
    // value: uv_obs - (pi(x_c) + velocity (v_obs - v_ref) d)
    Eigen::Vector2d residual;
    ASSERT_TRUE(cost->Evaluate(blocks.data(), residual.data(), nullptr));
    const Eigen::Vector2d expected =
        uv_obs - (uv_true + velocity * (uv_obs[1] - reference_row) * line_delay_us * 1e-6);
    EXPECT_LT((residual - expected).norm(), 1e-9) << c.model;
    // the functor with Jets directly: the same value
    using Jet = ceres::Jet<double, 4>;
    ReprojectionCost functor(cam.type(), pixel_size, uv_obs.data(), velocity.data(), reference_row);
    std::vector<Jet> jet_intrinsics(intrinsics.size());
    for (int i = 0; i < intrinsics.size(); ++i) jet_intrinsics[i] = Jet(intrinsics[i]);
    Jet jet_point[3] = {Jet(abr[0], 0), Jet(abr[1], 1), Jet(abr[2], 2)};
    Jet jet_delay(line_delay_us, 3), jet_residual[2];
    Jet jet_anchor[6], jet_observer[6];
    for (int i = 0; i < 6; ++i) jet_anchor[i] = Jet(anchor[i]), jet_observer[i] = Jet(observer[i]);
    const bool ok = c.in_anchor
                        ? functor(jet_intrinsics.data(), jet_point, &jet_delay, jet_residual)
                        : functor(jet_intrinsics.data(), jet_anchor, jet_observer, jet_point,
                                  &jet_delay, jet_residual);
    ASSERT_TRUE(ok);
    EXPECT_NEAR(jet_residual[0].a, residual[0], 1e-12);
    EXPECT_NEAR(jet_residual[1].a, residual[1], 1e-12);
    // d r / d d is -velocity (v_obs - v_ref) 1e-6, exactly
    EXPECT_NEAR(jet_residual[0].v[3], -velocity[0] * (uv_obs[1] - reference_row) * 1e-6, 1e-15);
    // autodiff Jacobians against central differences of the double functor
    std::vector<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> jacobians;
    std::vector<double*> jacobian_ptrs;
    for (int size : cost->parameter_block_sizes()) jacobians.emplace_back(2, size);
    for (auto& j : jacobians) jacobian_ptrs.push_back(j.data());
    ASSERT_TRUE(cost->Evaluate(blocks.data(), residual.data(), jacobian_ptrs.data()));
    for (size_t b = 0; b < blocks.size(); ++b) {
      for (int i = 0; i < cost->parameter_block_sizes()[b]; ++i) {
        double& x = blocks[b][i];
        const double saved = x, step = 1e-6 * std::max(1.0, std::abs(x));
        Eigen::Vector2d plus, minus;
        x = saved + step;
        ASSERT_TRUE(cost->Evaluate(blocks.data(), plus.data(), nullptr));
        x = saved - step;
        ASSERT_TRUE(cost->Evaluate(blocks.data(), minus.data(), nullptr));
        x = saved;
        const Eigen::Vector2d numeric = (plus - minus) / (2 * step);
        const double scale = std::max(1.0, numeric.norm());
        EXPECT_LT((jacobians[b].col(i) - numeric).norm(), 2e-5 * scale)
            << c.model << " block " << b << " parameter " << i;
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Models, ReprojectionCostTest,
                         ::testing::Values(CostCase{"civera-radial", false},
                                           CostCase{"civera-radial", true},
                                           CostCase{"pinhole-radtan", false},
                                           CostCase{"pinhole-equidistant", false},
                                           CostCase{"pinhole-equidistant", true}));

// Create's cost from another keyframe chains its Jacobian by hand (ChainedReprojectionCost): the
// same residual to the bit and the same Jacobians as autodiff of the whole functor, to rounding.
template <int kNumIntrinsics>
std::unique_ptr<ceres::CostFunction> WholeAutodiff(const ReprojectionCost& functor) {
  return std::make_unique<
      ceres::AutoDiffCostFunction<ReprojectionCost, 2, kNumIntrinsics, 6, 6, 3, 1>>(
      new ReprojectionCost(functor));
}

TEST(ReprojectionCost, TheChainedJacobianIsTheWholeFunctorsAutodiff) {
  for (const std::string model : {"civera-radial", "pinhole-radtan", "pinhole-equidistant"}) {
    const camera::CameraModel cam = Camera(model);
    std::mt19937 rng(11);
    for (int trial = 0; trial < 20; ++trial) {
      const Vector6d anchor = RandomPose(&rng, 0.1);
      const Vector6d observer = RandomPose(&rng, 0.05);
      const Eigen::Vector3d x_w = PointAhead(anchor, &rng);
      Eigen::Vector3d abr;
      ASSERT_TRUE(AnchoredPointFromWorld(anchor.data(), x_w, &abr));
      abr[2] *= (trial % 4 == 0) ? 0.0 : 1.0;  // every fourth point at infinity (rho = 0)
      const Eigen::Vector2d uv_obs(0.4 * cam.width() + trial, 0.6 * cam.height() - trial);
      const Eigen::Vector2d velocity(80.0 - 7.0 * trial, 30.0 + 3.0 * trial);
      double line_delay_us = 20.0 + trial;
      Eigen::VectorXd intrinsics = cam.params();
      const double pixel_size[2] = {cam.pixel_size_mm()[0], cam.pixel_size_mm()[1]};
      const ReprojectionCost functor(cam.type(), pixel_size, uv_obs.data(), velocity.data(),
                                     cam.height() / 2.0 - 0.5);
      std::unique_ptr<ceres::CostFunction> chained(ReprojectionCost::Create(
          cam.type(), pixel_size, uv_obs.data(), velocity.data(), cam.height() / 2.0 - 0.5, false));
      std::unique_ptr<ceres::CostFunction> whole;
      switch (intrinsics.size()) {
        case 5: whole = WholeAutodiff<5>(functor); break;
        case 8: whole = WholeAutodiff<8>(functor); break;
        default: whole = WholeAutodiff<9>(functor); break;
      }
      Vector6d anchor_block = anchor, observer_block = observer;
      double* blocks[5] = {intrinsics.data(), anchor_block.data(), observer_block.data(),
                           abr.data(), &line_delay_us};
      std::vector<Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor>> j_chained, j_whole;
      std::vector<double*> p_chained, p_whole;
      for (int size : whole->parameter_block_sizes()) {
        j_chained.emplace_back(2, size);
        j_whole.emplace_back(2, size);
      }
      for (size_t b = 0; b < j_whole.size(); ++b) {
        p_chained.push_back(j_chained[b].data());
        p_whole.push_back(j_whole[b].data());
      }
      Eigen::Vector2d r_chained, r_whole, r_plain, r_whole_plain;
      ASSERT_TRUE(chained->Evaluate(blocks, r_chained.data(), p_chained.data())) << model;
      ASSERT_TRUE(whole->Evaluate(blocks, r_whole.data(), p_whole.data())) << model;
      EXPECT_EQ(r_chained, r_whole) << model;
      // without Jacobians both evaluate the functor in double
      ASSERT_TRUE(chained->Evaluate(blocks, r_plain.data(), nullptr));
      ASSERT_TRUE(whole->Evaluate(blocks, r_whole_plain.data(), nullptr));
      EXPECT_EQ(r_plain, r_whole_plain) << model;
      for (size_t b = 0; b < j_whole.size(); ++b) {
        const double scale = std::max(1.0, j_whole[b].cwiseAbs().maxCoeff());
        EXPECT_LT((j_chained[b] - j_whole[b]).cwiseAbs().maxCoeff(), 1e-12 * scale)
            << model << " block " << b << " trial " << trial;
      }
      // a block Ceres holds constant gets no Jacobian: the others are still filled
      double* some[5] = {nullptr, p_chained[1], nullptr, p_chained[3], nullptr};
      j_chained[1].setZero();
      ASSERT_TRUE(chained->Evaluate(blocks, r_chained.data(), some));
      EXPECT_LT((j_chained[1] - j_whole[1]).cwiseAbs().maxCoeff(),
                1e-12 * std::max(1.0, j_whole[1].cwiseAbs().maxCoeff()));
    }
  }
}

TEST(ReprojectionCost, BehindTheCameraIsNotProjected) {
  const camera::CameraModel cam = Camera("civera-radial");
  const double pixel_size[2] = {0.0112, 0.0112};
  const double uv[2] = {160.0, 120.0}, velocity[2] = {0.0, 0.0};
  std::unique_ptr<ceres::CostFunction> cost(
      ReprojectionCost::Create(cam.type(), pixel_size, uv, velocity, 119.5, false));
  Eigen::VectorXd intrinsics = cam.params();
  Vector6d anchor = Vector6d::Zero(), observer = Vector6d::Zero();
  observer[2] = -3.0;  // the observer 3 m in front of the anchor, looking the same way
  Eigen::Vector3d point(0.0, 0.0, 0.5);  // 2 m in front of the anchor: behind the observer
  double line_delay_us = 0.0;
  double* blocks[5] = {intrinsics.data(), anchor.data(), observer.data(), point.data(),
                       &line_delay_us};
  double residual[2];
  EXPECT_FALSE(cost->Evaluate(blocks, residual, nullptr));
  point[2] = 0.25;  // 4 m: in front of both
  EXPECT_TRUE(cost->Evaluate(blocks, residual, nullptr));
}

TEST(LineDelayPriorCost, IsThePixelScaledStandardisedOffset) {
  std::unique_ptr<ceres::CostFunction> cost(LineDelayPriorCost::Create(30.0, 0.5, 0.25));
  double delay = 31.0, residual = 0.0, jacobian = 0.0;
  double* blocks[1] = {&delay};
  double* jacobians[1] = {&jacobian};
  ASSERT_TRUE(cost->Evaluate(blocks, &residual, jacobians));
  EXPECT_DOUBLE_EQ(residual, 0.25 * (31.0 - 30.0) / 0.5);
  EXPECT_DOUBLE_EQ(jacobian, 0.5);
}

// Plus then Minus gives the step back; Plus at zero is the identity; PlusJacobian against
// central differences of Plus.
template <typename Manifold>
void CheckManifold(const Manifold& manifold, const Vector6d& x, std::mt19937* rng) {
  const int tangent = manifold.TangentSize();
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd delta(tangent);
  for (int i = 0; i < tangent; ++i) delta[i] = 0.05 * normal(*rng);
  Vector6d moved, same;
  Eigen::VectorXd back(tangent), zero = Eigen::VectorXd::Zero(tangent);
  ASSERT_TRUE(manifold.Plus(x.data(), zero.data(), same.data()));
  EXPECT_LT((same - x).norm(), 1e-14);
  ASSERT_TRUE(manifold.Plus(x.data(), delta.data(), moved.data()));
  ASSERT_TRUE(manifold.Minus(moved.data(), x.data(), back.data()));
  EXPECT_LT((back - delta).norm(), 1e-12);
  Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::RowMajor> jacobian(6, tangent);
  ASSERT_TRUE(manifold.PlusJacobian(x.data(), jacobian.data()));
  for (int i = 0; i < tangent; ++i) {
    Eigen::VectorXd step = Eigen::VectorXd::Zero(tangent);
    step[i] = 1e-6;
    Vector6d plus, minus;
    manifold.Plus(x.data(), step.data(), plus.data());
    step[i] = -1e-6;
    manifold.Plus(x.data(), step.data(), minus.data());
    EXPECT_LT((jacobian.col(i) - (plus - minus) / 2e-6).norm(), 1e-7) << "column " << i;
  }
}

TEST(PoseManifold, PlusMinusAndJacobianAlsoNearAHalfTurn) {
  std::mt19937 rng(5);
  PoseManifold manifold;
  for (int trial = 0; trial < 10; ++trial) CheckManifold(manifold, RandomPose(&rng, 0.8), &rng);
  Vector6d turned = RandomPose(&rng);
  turned.tail<3>() = Eigen::Vector3d(0.0, 3.1, 0.2);  // |phi| close to pi
  CheckManifold(manifold, turned, &rng);
  // a step across pi keeps |phi| <= pi and the same rotation
  Vector6d moved;
  const double delta[6] = {0, 0, 0, 0, 0.2, 0};
  manifold.Plus(turned.data(), delta, moved.data());
  EXPECT_LE(moved.tail<3>().norm(), M_PI + 1e-12);
}

TEST(BaselineManifold, HoldsTheDistanceFromTheFirstCentre) {
  std::mt19937 rng(6);
  const Eigen::Vector3d first_centre(0.1, -0.2, 0.3);
  BaselineManifold manifold(new BaselineManifoldFunctor(first_centre));
  const auto centre = [](const Vector6d& pose) {
    const double minus_phi[3] = {-pose[3], -pose[4], -pose[5]};
    Eigen::Vector3d rotated;
    ceres::AngleAxisRotatePoint(minus_phi, pose.data(), rotated.data());
    return Eigen::Vector3d(-rotated);
  };
  for (int trial = 0; trial < 10; ++trial) {
    const Vector6d x = RandomPose(&rng, 0.8);
    CheckManifold(manifold, x, &rng);
    std::normal_distribution<double> normal(0.0, 1.0);
    double delta[5];
    for (double& d : delta) d = 0.3 * normal(rng);
    Vector6d moved;
    manifold.Plus(x.data(), delta, moved.data());
    EXPECT_NEAR((centre(moved) - first_centre).norm(), (centre(x) - first_centre).norm(), 1e-12);
    EXPECT_GT((centre(moved) - centre(x)).norm(), 1e-3);  // but the centre moved
  }
}

}  // namespace
}  // namespace rscalib::bundle
