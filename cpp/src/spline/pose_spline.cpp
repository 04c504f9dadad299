#include "rscalib/spline/pose_spline.hpp"

#include "rscalib/core/error.hpp"

namespace rscalib::spline {

void CheckPoseSpline(const CubicBSpline& pose_spline) {
  if (pose_spline.dimension() != geometry::kPoseStateDim)
    throw InputError("a pose spline has dimension 6 ([translation; rotation vector])");
}

geometry::Pose PoseAt(const CubicBSpline& pose_spline, double t) {
  CheckPoseSpline(pose_spline);
  Eigen::Matrix<double, 6, 1> state = pose_spline.Evaluate(t, 0);
  return geometry::PoseFromState(state);
}

}  // namespace rscalib::spline
