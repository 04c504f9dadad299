#include "rscalib/geometry/rotation.hpp"

#include <cmath>

#include <Eigen/Geometry>

namespace rscalib::geometry {

Eigen::Vector3d RotationMatrixToVector(const Eigen::Matrix3d& rotation) {
  const Eigen::AngleAxisd angle_axis(rotation);
  return angle_axis.angle() * angle_axis.axis();
}

Eigen::MatrixX3d UnwrapRotationVectors(const Eigen::MatrixX3d& rotation_vectors) {
  constexpr double kTwoPi = 2.0 * M_PI;
  Eigen::MatrixX3d out = rotation_vectors;
  for (Eigen::Index k = 1; k < out.rows(); ++k) {
    const Eigen::Vector3d previous = out.row(k - 1).transpose();
    const Eigen::Vector3d current = rotation_vectors.row(k).transpose();
    if (!current.allFinite() || !previous.allFinite()) continue;  // an unknown rotation: as given
    const double angle = current.norm();
    Eigen::Vector3d axis;
    if (angle > 1e-12) {
      axis = current / angle;
    } else if (previous.norm() > 1e-12) {
      axis = previous.normalized();  // identity: any axis; keep the neighbour's
    } else {
      continue;
    }
    // Candidates axis * (angle + 2 pi m); the nearest to `previous` has m near this.
    const long m0 = std::lround((axis.dot(previous) - angle) / kTwoPi);
    Eigen::Vector3d best = current;
    double best_distance = (current - previous).norm();
    for (long m = m0 - 1; m <= m0 + 1; ++m) {
      const Eigen::Vector3d candidate = axis * (angle + kTwoPi * static_cast<double>(m));
      const double distance = (candidate - previous).norm();
      if (distance < best_distance) {
        best_distance = distance;
        best = candidate;
      }
    }
    out.row(k) = best.transpose();
  }
  return out;
}

}  // namespace rscalib::geometry
