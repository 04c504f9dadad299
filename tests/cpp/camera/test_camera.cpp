#include <random>

#include <gtest/gtest.h>

#include "rscalib/camera/camera_model.hpp"
#include "rscalib/core/error.hpp"

using namespace rscalib::camera;

namespace {

std::vector<CameraModel> Cameras() {
  Eigen::VectorXd radtan(9), fisheye(8), civera(5);
  radtan << 520, 515, 321, 242, -0.28, 0.09, 1e-3, -5e-4, 0.01;
  fisheye << 380, 382, 318, 236, 0.05, -0.01, 0.004, -0.001;
  civera << 194.06, 160.22, 128.87, 0.06333, 0.0139;
  return {CameraModel("pinhole-radtan", radtan, 640, 480),
          CameraModel("pinhole-equidistant", fisheye, 640, 480),
          CameraModel("civera-radial", civera, 320, 240, Eigen::Vector2d(0.0112, 0.0112))};
}

}  // namespace

TEST(CameraModel, JacobiansMatchCentralDifferences) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> xy(-0.5, 0.5), z(1.0, 3.0);
  for (const CameraModel& camera : Cameras()) {
    for (int trial = 0; trial < 20; ++trial) {
      const Eigen::Vector3d point(xy(rng), xy(rng), z(rng));
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> d_point;
      Eigen::Matrix<double, 2, Eigen::Dynamic> d_params;
      ASSERT_TRUE(camera.ProjectWithJacobians(point, &uv, &d_point, &d_params)) << camera.name();
      for (int i = 0; i < 3; ++i) {
        const double h = 1e-6;
        Eigen::Vector3d plus = point, minus = point;
        plus[i] += h;
        minus[i] -= h;
        Eigen::Vector2d up, um;
        camera.Project(plus, &up);
        camera.Project(minus, &um);
        EXPECT_LT(((up - um) / (2 * h) - d_point.col(i)).norm(), 1e-5 * (1 + d_point.col(i).norm()))
            << camera.name() << " point " << i;
      }
      for (int i = 0; i < camera.params().size(); ++i) {
        const double h = 1e-6 * std::max(1.0, std::abs(camera.params()[i]));
        Eigen::VectorXd plus = camera.params(), minus = camera.params();
        plus[i] += h;
        minus[i] -= h;
        const CameraModel cp(camera.name(), plus, 640, 480, camera.pixel_size_mm());
        const CameraModel cm(camera.name(), minus, 640, 480, camera.pixel_size_mm());
        Eigen::Vector2d up, um;
        cp.Project(point, &up);
        cm.Project(point, &um);
        EXPECT_LT(((up - um) / (2 * h) - d_params.col(i)).norm(),
                  1e-5 * (1 + d_params.col(i).norm()))
            << camera.name() << " param " << i;
      }
    }
  }
}

TEST(CameraModel, UnprojectInvertsProject) {
  std::mt19937 rng(6);
  std::uniform_real_distribution<double> xy(-0.4, 0.4), z(0.5, 4.0);
  for (const CameraModel& camera : Cameras()) {
    for (int trial = 0; trial < 100; ++trial) {
      const Eigen::Vector3d point(xy(rng), xy(rng), z(rng));
      Eigen::Vector2d uv, uv_again;
      Eigen::Vector3d ray;
      ASSERT_TRUE(camera.Project(point, &uv));
      ASSERT_TRUE(camera.Unproject(uv, &ray)) << camera.name();
      EXPECT_LT((ray - point / point.z()).norm(), 1e-9) << camera.name();
      ASSERT_TRUE(camera.Project(ray, &uv_again));
      EXPECT_LT((uv_again - uv).norm(), 1e-9) << camera.name();
    }
  }
}

TEST(CameraModel, CiveraDistortUndistortRoundTrip) {
  const CameraModel camera = Cameras()[2];
  const double* p = camera.params().data();
  const double* pixel = camera.pixel_size_mm().data();
  for (double u = 0; u <= 320; u += 16)
    for (double v = 0; v <= 240; v += 12) {
      const double uv_d[2] = {u, v};
      double uv_u[2], uv_back[2];
      CiveraRadial::Undistort(p, pixel, uv_d, uv_u);
      ASSERT_TRUE(CiveraRadial::Distort(p, pixel, uv_u, uv_back));
      EXPECT_NEAR(uv_back[0], u, 1e-9);
      EXPECT_NEAR(uv_back[1], v, 1e-9);
    }
}

TEST(CameraModel, RejectsBadParameters) {
  EXPECT_THROW(CameraModel("pinhole", Eigen::VectorXd::Ones(4), 640, 480), rscalib::InputError);
  EXPECT_THROW(CameraModel("pinhole-radtan", Eigen::VectorXd::Ones(6), 640, 480),
               rscalib::InputError);
  EXPECT_THROW(CameraModel("civera-radial", Eigen::VectorXd::Ones(5), 320, 240),
               rscalib::InputError);
}
