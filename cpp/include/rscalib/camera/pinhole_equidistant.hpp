#pragma once
// OpenCV's fisheye (equidistant) model, as cv2.fisheye.projectPoints with zero skew.
//
// params layout (8): [fx, fy, cx, cy, k1, k2, k3, k4]
//   a = X/Z, b = Y/Z, r = sqrt(a^2 + b^2), theta = atan(r)
//   theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
//   u = fx (theta_d / r) a + cx, v = fy (theta_d / r) b + cy
#include <cmath>

#include <ceres/jet.h>

#include "rscalib/core/scalar.hpp"

namespace rscalib::camera {

struct PinholeEquidistant {
  static constexpr int kNumParams = 8;
  static constexpr const char* kName = "pinhole-equidistant";

  // theta_d / r as a function of r^2; smooth at r = 0 (series there, so Jets stay finite).
  template <typename T>
  static T DistortionScale(const T* params, const T& r2) {
    using std::atan;
    using std::sqrt;
    if (ScalarValue(r2) < 1e-16) {
      // atan(r)/r ~ 1 - r^2/3, theta^2 ~ r^2.
      return T(1.0) + (params[4] - T(1.0 / 3.0)) * r2;
    }
    const T r = sqrt(r2);
    const T theta = atan(r);
    const T theta2 = theta * theta;
    const T poly =
        T(1.0) +
        theta2 * (params[4] + theta2 * (params[5] + theta2 * (params[6] + theta2 * params[7])));
    return theta * poly / r;
  }

  template <typename T>
  static bool Project(const T* params, const T* point_c, T* uv) {
    if (!(point_c[2] > T(0.0))) return false;
    const T a = point_c[0] / point_c[2];
    const T b = point_c[1] / point_c[2];
    const T scale = DistortionScale(params, a * a + b * b);
    uv[0] = params[0] * scale * a + params[2];
    uv[1] = params[1] * scale * b + params[3];
    return true;
  }
};

}  // namespace rscalib::camera
