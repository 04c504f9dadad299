// The detectors' checks in the core: the local-homography residual and the blur measure.
#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "rscalib/geometry/corner_saddles.hpp"
#include "rscalib/geometry/edge_width.hpp"
#include "rscalib/geometry/local_homography.hpp"

using namespace rscalib::geometry;

namespace {

// A 6 x 5 grid of 1-unit steps seen through a homography, and each point's 8 nearest neighbours.
void PerspectiveGrid(Eigen::MatrixX2d* xy, Eigen::MatrixX2d* uv, Eigen::MatrixXi* nearest) {
  const int cols = 6, rows = 5, n = cols * rows;
  Eigen::Matrix3d h;
  h << 40, 3, 100, -2, 38, 80, 0.002, 0.001, 1;
  xy->resize(n, 2);
  uv->resize(n, 2);
  for (int i = 0; i < n; ++i) {
    (*xy)(i, 0) = i % cols;
    (*xy)(i, 1) = i / cols;
    const Eigen::Vector3d p = h * Eigen::Vector3d((*xy)(i, 0), (*xy)(i, 1), 1.0);
    uv->row(i) = p.head<2>().transpose() / p[2];
  }
  nearest->resize(n, 8);
  for (int i = 0; i < n; ++i) {
    std::vector<int> others;
    for (int j = 0; j < n; ++j)
      if (j != i) others.push_back(j);
    std::sort(others.begin(), others.end(), [&](int a, int b) {
      return (xy->row(a) - xy->row(i)).squaredNorm() < (xy->row(b) - xy->row(i)).squaredNorm();
    });
    for (int k = 0; k < 8; ++k) (*nearest)(i, k) = others[static_cast<std::size_t>(k)];
  }
}

}  // namespace

TEST(LocalHomography, ZeroOnAPerspectiveGridLargeOnAMovedPoint) {
  Eigen::MatrixX2d xy, uv;
  Eigen::MatrixXi nearest;
  PerspectiveGrid(&xy, &uv, &nearest);
  const Eigen::VectorXd clean = LocalHomographyResidual(xy, uv, nearest);
  EXPECT_LT(clean.maxCoeff(), 1e-9);
  uv(14, 0) += 12.0;  // about a third of a grid step
  const Eigen::VectorXd moved = LocalHomographyResidual(xy, uv, nearest);
  EXPECT_GT(moved[14], 0.25);
}

TEST(LocalHomography, RefusesMoreNeighboursThanItHolds) {
  Eigen::MatrixX2d xy = Eigen::MatrixX2d::Random(20, 2), uv = xy;
  Eigen::MatrixXi nearest = Eigen::MatrixXi::Zero(20, 17);
  EXPECT_THROW(LocalHomographyResidual(xy, uv, nearest), std::exception);
}

TEST(EdgeWidth, BoxBlurOfLPixelsMeasuresAboutL) {
  // profiles across a step edge blurred by a box of L px, sampled every `step` px
  const int samples = 48;
  const double half = 16.0, step = 2.0 * half / (samples - 1);
  for (double blur_px : {1.0, 4.0, 9.0}) {
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> profiles(5, samples);
    for (int j = 0; j < samples; ++j) {
      const double x = -half + j * step;
      const double ramp = std::clamp(x / blur_px + 0.5, 0.0, 1.0);
      profiles.col(j).setConstant(std::round(40.0 + 180.0 * ramp));
    }
    const double width = EdgeWidthFromProfiles(profiles, Eigen::VectorXd::Constant(5, half), 20.0);
    EXPECT_NEAR(width, blur_px, 0.25 * blur_px + 1.0) << blur_px;
  }
  // no contrast: not measurable
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> flat =
      Eigen::MatrixXd::Constant(3, samples, 128.0);
  EXPECT_TRUE(std::isnan(EdgeWidthFromProfiles(flat, Eigen::VectorXd::Constant(3, half), 20.0)));
}

TEST(EdgeWidth, MapsCrossTheEdgeAtItsMiddle) {
  Eigen::MatrixX2d a(2, 2), b(2, 2);
  a << 10, 20, 5, 5;
  b << 50, 20, 5.5, 5;  // the second is too short for a profile (half 0.2 px < 1.5)
  Eigen::VectorXd s = Eigen::VectorXd::LinSpaced(48, -1.0, 1.0);
  const EdgeProfileMaps maps = EdgeProfileMapsFor(a, b, false, 0.4, s, 16.0, 1.5);
  ASSERT_EQ(maps.half_px.size(), 1);
  EXPECT_DOUBLE_EQ(maps.half_px[0], 16.0);
  for (int j = 0; j < 48; ++j)
    EXPECT_FLOAT_EQ(maps.map_x(0, j), 30.0f);  // across a horizontal edge
  EXPECT_FLOAT_EQ(maps.map_y(0, 0), 20.0f - 16.0f);
  EXPECT_FLOAT_EQ(maps.map_y(0, 47), 20.0f + 16.0f);
}

TEST(CornerSaddles, SamplesFollowTheGridsDiagonals) {
  // a 3 x 4 grid of 10 px steps: the samples lie 0.3 x (10, 10) and 0.3 x (10, -10) from each
  // corner
  Eigen::MatrixX2d grid(12, 2);
  for (int i = 0; i < 12; ++i) grid.row(i) << 50.0 + 10.0 * (i % 4), 80.0 + 10.0 * (i / 4);
  SampleMap map_x, map_y;
  SaddleSamplePoints(grid, 3, 4, 0.3, &map_x, &map_y);
  for (int i = 0; i < 12; ++i) {
    EXPECT_FLOAT_EQ(map_x(i, 0), static_cast<float>(grid(i, 0) + 3.0));
    EXPECT_FLOAT_EQ(map_y(i, 0), static_cast<float>(grid(i, 1) + 3.0));
    EXPECT_FLOAT_EQ(map_x(i, 2), static_cast<float>(grid(i, 0) + 3.0));
    EXPECT_FLOAT_EQ(map_y(i, 2), static_cast<float>(grid(i, 1) - 3.0));
  }
  EXPECT_THROW(SaddleSamplePoints(grid, 2, 4, 0.3, &map_x, &map_y), std::exception);
}

TEST(CornerSaddles, AlternatingSaddlesPassAnEdgeCornerFails) {
  const int n = 12;
  Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor> values(n, 4);
  Eigen::Matrix<bool, Eigen::Dynamic, 1> even(n);
  for (int i = 0; i < n; ++i) {
    even[i] = ((i / 4) + (i % 4)) % 2 == 0;
    if (even[i]) {
      values.row(i) << 200, 210, 30, 40;  // the diagonal pair bright
    } else {
      values.row(i) << 35, 25, 205, 195;
    }
  }
  EXPECT_TRUE(CornersAreSaddles(values, even, 20.0, 0.25));
  values.row(5) << 200, 210, 190, 40;  // three bright quadrants: a square's outer corner
  EXPECT_FALSE(CornersAreSaddles(values, even, 20.0, 0.25));
  Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor> flat =
      Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>::Constant(n, 4, 128.0);
  EXPECT_FALSE(CornersAreSaddles(flat, even, 20.0, 0.25));  // no contrast
}
