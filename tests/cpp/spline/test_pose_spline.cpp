#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "rscalib/core/error.hpp"
#include "rscalib/geometry/rotation.hpp"
#include "rscalib/spline/pose_spline.hpp"

using namespace rscalib::spline;

TEST(PoseSpline, PoseAtIsThePoseOfTheSplineState) {
  CubicBSpline curve = CubicBSpline::Uniform(0.0, 2.0, 5, 6);
  for (int i = 0; i < curve.num_control_points(); ++i)
    curve.mutable_control_points().row(i) << 0.1 * i, -0.2, 1.0 + 0.05 * i, 0.3, 0.1 * i, -0.4;
  for (double t : {0.0, 0.37, 1.2, 2.0}) {
    const Eigen::VectorXd state = curve.Evaluate(t);
    const rscalib::geometry::Pose pose = PoseAt(curve, t);
    EXPECT_EQ(pose.translation_cw, state.head<3>());
    EXPECT_LT((pose.rotation_cw -
               rscalib::geometry::RotationVectorToMatrix(state.tail<3>().eval().data()))
                  .norm(),
              1e-15);
  }
}

TEST(PoseSpline, RejectsASplineThatIsNotSixDimensional) {
  const CubicBSpline curve = CubicBSpline::Uniform(0.0, 1.0, 2, 3);
  EXPECT_THROW(PoseAt(curve, 0.5), rscalib::InputError);
  EXPECT_THROW(CheckPoseSpline(curve), rscalib::InputError);
}
