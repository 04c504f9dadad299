#pragma once
// Layout of one EKF state of the SOG self-calibration (docs/sog.md §2), in the paper's
// order (eq. 6, 8): calibration, camera pose, velocities, then the map features.
//   x = [f, Cx, Cy, k1, k2 | r (3) | q (4) | v (3) | w (3) | y_1 | y_2 | ...]
// q = (qw, qx, qy, qz) is the camera-to-world rotation (x_w = R(q) x_c + r), so the world
// to camera rotation of docs/conventions.md is R(q)^T and p = -R(q)^T r. w is the angular
// velocity in the camera frame. Calibration and pose are contiguous (columns 0..11), so a
// measurement row touches one 12-column block plus its feature.
namespace rscalib::sog {

constexpr int kCalibration = 0;       // f, Cx, Cy, k1 (mm^-2), k2 (mm^-4)
constexpr int kPosition = 5;          // r, camera centre in the world
constexpr int kQuaternion = 8;        // q_wc, scalar first
constexpr int kVelocity = 12;         // v, world frame, m/s
constexpr int kAngularVelocity = 15;  // w, camera frame, rad/s
constexpr int kCalibrationDim = 5;
constexpr int kMeasuredCameraDim = 12;  // calibration + r + q: what a projection depends on
constexpr int kMotionDim = 13;          // r, q, v, w: what the motion model changes
constexpr int kCameraDim = 18;

// Map features: inverse depth (x0, y0, z0, theta, phi, rho) or Euclidean (X, Y, Z).
enum class FeatureKind { kInverseDepth, kXyz };
constexpr int kInverseDepthDim = 6;
constexpr int kXyzDim = 3;
inline int FeatureDim(FeatureKind kind) {
  return kind == FeatureKind::kInverseDepth ? kInverseDepthDim : kXyzDim;
}

}  // namespace rscalib::sog
