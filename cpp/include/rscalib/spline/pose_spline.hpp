#pragma once
// A 6-D cubic B-spline of pose states [p; phi] (docs/conventions.md, "Frames and poses"):
// the camera trajectory T_cw(t).
#include "rscalib/geometry/pose.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

namespace rscalib::spline {

// Throws InputError unless `pose_spline` has dimension geometry::kPoseStateDim.
void CheckPoseSpline(const CubicBSpline& pose_spline);

// T_cw(t) of a 6-D pose spline.
geometry::Pose PoseAt(const CubicBSpline& pose_spline, double t);

}  // namespace rscalib::spline
