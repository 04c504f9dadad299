#include "rscalib/geometry/pose.hpp"

#include "rscalib/geometry/rotation.hpp"

namespace rscalib::geometry {

Pose PoseFromState(const Eigen::Matrix<double, 6, 1>& state) {
  Pose pose;
  pose.translation_cw = state.head<3>();
  pose.rotation_cw = RotationVectorToMatrix(state.data() + 3);
  return pose;
}

}  // namespace rscalib::geometry
