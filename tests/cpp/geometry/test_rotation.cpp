#include <cmath>

#include <Eigen/Geometry>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "rscalib/geometry/pose.hpp"
#include "rscalib/geometry/rotation.hpp"

using namespace rscalib::geometry;

TEST(Rotation, UnwrapRemovesTwoPiJumps) {
  // A rotation about z sweeping through pi: the minimal rotation vector jumps from
  // +pi*z to -pi*z; unwrapped it keeps increasing and the rotations are unchanged.
  const int count = 60;
  Eigen::MatrixX3d wrapped(count, 3);
  for (int k = 0; k < count; ++k) {
    const double angle = 2.5 + 0.05 * k;  // 2.5 .. 5.45 rad
    const Eigen::Matrix3d rotation =
        Eigen::AngleAxisd(angle, Eigen::Vector3d(0.1, 0.2, 1).normalized()).toRotationMatrix();
    wrapped.row(k) = RotationMatrixToVector(rotation).transpose();
  }
  const Eigen::MatrixX3d unwrapped = UnwrapRotationVectors(wrapped);
  for (int k = 1; k < count; ++k) EXPECT_LT((unwrapped.row(k) - unwrapped.row(k - 1)).norm(), 0.06);
  double max_jump_before = 0;
  for (int k = 1; k < count; ++k)
    max_jump_before = std::max(max_jump_before, (wrapped.row(k) - wrapped.row(k - 1)).norm());
  EXPECT_GT(max_jump_before, 5.0);  // the input really did jump
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector3d a = wrapped.row(k).transpose(), b = unwrapped.row(k).transpose();
    EXPECT_LT((RotationVectorToMatrix(a.data()) - RotationVectorToMatrix(b.data())).norm(), 1e-12);
  }
}

TEST(Rotation, TransformIsFiniteForJetsAtZeroRotation) {
  using Jet = ceres::Jet<double, 6>;
  Jet state[6];
  for (int i = 0; i < 6; ++i) state[i] = Jet(0.0, i);
  const double point_w[3] = {0.3, -0.2, 1.0};
  Jet point_c[3];
  TransformWorldToCamera(state, point_w, point_c);
  EXPECT_NEAR(point_c[0].a, 0.3, 1e-15);
  // d x_c / d phi at phi = 0 is -[x_w]x: d(x_c.x)/d(phi_y) = z_w.
  EXPECT_NEAR(point_c[0].v[4], 1.0, 1e-12);
  EXPECT_NEAR(point_c[0].v[0], 1.0, 1e-15);
  for (int r = 0; r < 3; ++r)
    for (int i = 0; i < 6; ++i) EXPECT_TRUE(std::isfinite(point_c[r].v[i]));
}
