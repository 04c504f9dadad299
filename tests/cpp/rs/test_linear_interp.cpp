// The linear-interpolation (Hedborg et al. 2012) baseline: cost functor and solver.
#include <cmath>
#include <memory>
#include <random>

#include <ceres/jet.h>
#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include "rscalib/geometry/rotation.hpp"
#include "rscalib/rs/linear_interp_cost.hpp"
#include "rscalib/rs/linear_interp_solver.hpp"

using namespace rscalib;

namespace {

using Pose6 = Eigen::Matrix<double, 6, 1>;

camera::CameraModel TestCamera() {
  Eigen::VectorXd params(9);
  params << 500, 500, 320, 240, -0.2, 0.05, 1e-3, -1e-3, 0.0;
  return camera::CameraModel("pinhole-radtan", params, 640, 480);
}

rs::SpanCamera ToSpanCamera(const camera::CameraModel& cam) {
  return rs::SpanCamera{cam.type(), cam.params().data(), static_cast<int>(cam.params().size()),
                        cam.pixel_size_mm().data()};
}

Eigen::Matrix3d Rotation(const Pose6& pose) {
  return geometry::RotationVectorToMatrix(pose.data() + 3);
}

// A camera ~0.6 m in front of the target, looking at it.
Pose6 RandomPose(std::mt19937& rng) {
  std::uniform_real_distribution<double> small(-0.1, 0.1);
  Pose6 pose;
  pose << small(rng), small(rng), 0.6 + small(rng), small(rng), small(rng), small(rng);
  return pose;
}

}  // namespace

TEST(LinearInterpCost, AutodiffMatchesNumericDiffIncludingLineDelay) {
  std::mt19937 rng(11);
  const auto cam = TestCamera();
  const auto span_camera = ToSpanCamera(cam);
  const Pose6 pose_a = RandomPose(rng), pose_b = RandomPose(rng);
  const double uv[2] = {300.0, 200.0}, point_w[3] = {0.05, -0.03, 0.0};
  const Eigen::Matrix2d weight = (Eigen::Matrix2d() << 2.0, 0.3, 0.0, 1.5).finished();
  const double interval_s = 1.0 / 30.0;
  for (const double frame_offset_s : {0.0, interval_s}) {
    std::unique_ptr<ceres::CostFunction> autodiff(
        rs::LinearInterpCost::Create(span_camera, frame_offset_s, interval_s, uv, point_w, weight));
    std::unique_ptr<ceres::CostFunction> numeric(
        new ceres::NumericDiffCostFunction<rs::LinearInterpCost, ceres::CENTRAL, 2, 6, 6, 1>(
            new rs::LinearInterpCost(span_camera, frame_offset_s, interval_s, uv, point_w,
                                     weight)));
    double line_delay = 40e-6;
    const double* blocks[3] = {pose_a.data(), pose_b.data(), &line_delay};
    double r_a[2], r_n[2];
    double ja[3][12], jn[3][12];
    double* jap[3] = {ja[0], ja[1], ja[2]};
    double* jnp[3] = {jn[0], jn[1], jn[2]};
    ASSERT_TRUE(autodiff->Evaluate(blocks, r_a, jap));
    ASSERT_TRUE(numeric->Evaluate(blocks, r_n, jnp));
    EXPECT_NEAR(r_a[0], r_n[0], 1e-12);
    EXPECT_NEAR(r_a[1], r_n[1], 1e-12);
    const int sizes[3] = {12, 12, 2};
    for (int b = 0; b < 3; ++b)
      for (int k = 0; k < sizes[b]; ++k)
        EXPECT_NEAR(ja[b][k], jn[b][k], 1e-5 * (1.0 + std::abs(ja[b][k])))
            << "block " << b << " entry " << k;
    // d enters through s: the derivative is not zero when the poses differ.
    EXPECT_GT(std::abs(ja[2][0]) + std::abs(ja[2][1]), 1.0);
  }
}

TEST(LinearInterpCost, EndpointsReturnTheFramePosesExactly) {
  std::mt19937 rng(12);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose6 pose_a = RandomPose(rng), pose_b = RandomPose(rng);
    const Pose6 at0 = rs::LinearInterpPoseState(pose_a, pose_b, 0.0);
    const Pose6 at1 = rs::LinearInterpPoseState(pose_a, pose_b, 1.0);
    // |phi| < pi here, so the rotation vectors themselves must agree.
    EXPECT_LT((at0 - pose_a).norm(), 1e-12);
    EXPECT_LT((at1 - pose_b).norm(), 1e-12);
  }
}

TEST(LinearInterpCost, JetAndDoubleAgreeAndFollowTheGeodesic) {
  using Jet = ceres::Jet<double, 13>;
  std::mt19937 rng(13);
  const Pose6 pose_a = RandomPose(rng), pose_b = RandomPose(rng);
  const double s = 0.37;
  Jet ja[6], jb[6], js(s, 12), state_j[6];
  for (int i = 0; i < 6; ++i) {
    ja[i] = Jet(pose_a[i], i);
    jb[i] = Jet(pose_b[i], 6 + i);
  }
  rs::InterpolatePoseStateLinear(ja, jb, js, state_j);
  const Pose6 state = rs::LinearInterpPoseState(pose_a, pose_b, s);
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(state_j[i].a, state[i], 1e-14);
  // R(s) = R_a Exp(s Log(R_a^T R_b)); c(s) = (1 - s) c_a + s c_b.
  const Eigen::Matrix3d r_a = Rotation(pose_a), r_b = Rotation(pose_b);
  const Eigen::Vector3d log_rel = geometry::RotationMatrixToVector(r_a.transpose() * r_b);
  const Eigen::Vector3d s_log = s * log_rel;
  const Eigen::Matrix3d r_s = r_a * geometry::RotationVectorToMatrix(s_log.data());
  const Eigen::Vector3d c_s =
      (1 - s) * (-r_a.transpose() * pose_a.head<3>()) + s * (-r_b.transpose() * pose_b.head<3>());
  EXPECT_LT((Rotation(state) - r_s).norm(), 1e-12);
  EXPECT_LT((state.head<3>() + r_s * c_s).norm(), 1e-12);
}

TEST(LinearInterpCost, JetIsFiniteForIdenticalPoses) {
  // Log at the identity: R_a^T R_b = I exactly.
  using Jet = ceres::Jet<double, 13>;
  std::mt19937 rng(14);
  const Pose6 pose = RandomPose(rng);
  Jet ja[6], jb[6], js(0.5, 12), state[6];
  for (int i = 0; i < 6; ++i) {
    ja[i] = Jet(pose[i], i);
    jb[i] = Jet(pose[i], 6 + i);
  }
  rs::InterpolatePoseStateLinear(ja, jb, js, state);
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(state[i].a, pose[i], 1e-12);
    for (int k = 0; k < 13; ++k) EXPECT_TRUE(std::isfinite(state[i].v[k]));
    // At s = 1/2 the pose moves half with each endpoint.
    EXPECT_NEAR(state[i].v[i], 0.5, 1e-9);
    EXPECT_NEAR(state[i].v[6 + i], 0.5, 1e-9);
  }
}

TEST(LinearInterpSolver, RecoversLineDelayFromConstantVelocityMotion) {
  // Constant linear and angular velocity: the linear model is exact (geodesic motion
  // about a fixed axis with a centre moving on a line), so d comes back to noise level.
  const auto cam = TestCamera();
  const double fps = 30.0, d_true = 30e-6;
  const int num_frames = 12;
  const Eigen::Vector3d omega(0.8, -0.6, 0.2), centre0(0.1, 0.08, -0.55),
      velocity(0.15, -0.1, 0.05);
  const Eigen::Matrix3d r0 = Eigen::Matrix3d::Identity();
  auto pose_at = [&](double t) {
    const Eigen::Vector3d phi = omega * t;
    const Eigen::Matrix3d r = r0 * geometry::RotationVectorToMatrix(phi.data());
    const Eigen::Vector3d c = centre0 + velocity * t;
    Pose6 pose;
    pose.head<3>() = -r * c;
    pose.tail<3>() = geometry::RotationMatrixToVector(r);
    return pose;
  };
  std::vector<int> frames;
  std::vector<Eigen::Vector2d> uvs;
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k < num_frames; ++k) {
    for (int i = 0; i < 9; ++i)
      for (int j = 0; j < 6; ++j) {
        const Eigen::Vector3d point_w(0.04 * i, 0.04 * j, 0.0);
        // Fixed point v = v_proj(T(t_k + v d) P).
        double v = 240.0;
        Eigen::Vector2d uv;
        for (int it = 0; it < 50; ++it) {
          const Pose6 pose = pose_at(k / fps + v * d_true);
          const Eigen::Vector3d pc = Rotation(pose) * point_w + pose.head<3>();
          ASSERT_TRUE(cam.Project(pc, &uv));
          v = uv[1];
        }
        frames.push_back(k);
        uvs.push_back(uv);
        points.push_back(point_w);
      }
  }
  rs::LinearInterpObservations obs;
  obs.frame_index.resize(frames.size());
  obs.uv.resize(frames.size(), 2);
  obs.point_w.resize(frames.size(), 3);
  for (size_t m = 0; m < frames.size(); ++m) {
    obs.frame_index[m] = frames[m];
    obs.uv.row(m) = uvs[m].transpose();
    obs.point_w.row(m) = points[m].transpose();
  }
  Eigen::VectorXd frame_time_s(num_frames);
  rs::FramePoseMatrix poses(num_frames, 6);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 1e-3);
  for (int k = 0; k < num_frames; ++k) {
    frame_time_s[k] = k / fps;
    poses.row(k) = pose_at(k / fps).transpose();
    for (int i = 0; i < 6; ++i) poses(k, i) += noise(rng);
  }
  double d = 0.0;
  rs::LinearInterpOptions options;
  options.pixel_sigma = 0.3;
  const auto summary = rs::SolveLineDelayLinear(obs, frame_time_s, cam, &poses, &d, options);
  EXPECT_NEAR(d, d_true, 1e-9);
  EXPECT_LT(summary.rms_px, 1e-4);
  EXPECT_TRUE(summary.covariance_ok);
  EXPECT_EQ(summary.isolated, 0);
  EXPECT_EQ(summary.extrapolated, 54);  // the last frame uses the pair before it
  EXPECT_EQ(summary.num_chains, 1);
  for (int k = 0; k < num_frames; ++k)
    EXPECT_LT((poses.row(k).transpose() - pose_at(k / fps)).norm(), 1e-6) << "frame " << k;
}
