#pragma once
// OpenCV's pinhole camera with radial-tangential distortion (k1, k2, p1, p2, k3).
//
// params layout (9): [fx, fy, cx, cy, k1, k2, p1, p2, k3]
//   x = X/Z, y = Y/Z, r2 = x^2 + y^2
//   x'' = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) + 2 p1 x y + p2 (r2 + 2 x^2)
//   y'' = y (1 + k1 r2 + k2 r2^2 + k3 r2^3) + p1 (r2 + 2 y^2) + 2 p2 x y
//   u = fx x'' + cx, v = fy y'' + cy            (as cv2.projectPoints)
namespace rscalib::camera {

struct PinholeRadtan {
  static constexpr int kNumParams = 9;
  static constexpr const char* kName = "pinhole-radtan";

  // Distortion of normalised coordinates (x, y) -> (x'', y'').
  template <typename T>
  static void Distort(const T* params, const T& x, const T& y, T* xd, T* yd) {
    const T r2 = x * x + y * y;
    const T radial = T(1.0) + r2 * (params[4] + r2 * (params[5] + r2 * params[8]));
    const T p1 = params[6], p2 = params[7];
    *xd = x * radial + T(2.0) * p1 * x * y + p2 * (r2 + T(2.0) * x * x);
    *yd = y * radial + p1 * (r2 + T(2.0) * y * y) + T(2.0) * p2 * x * y;
  }

  // Returns false for points not in front of the camera (Z <= 0).
  template <typename T>
  static bool Project(const T* params, const T* point_c, T* uv) {
    if (!(point_c[2] > T(0.0))) return false;
    const T x = point_c[0] / point_c[2];
    const T y = point_c[1] / point_c[2];
    T xd, yd;
    Distort(params, x, y, &xd, &yd);
    uv[0] = params[0] * xd + params[2];
    uv[1] = params[1] * yd + params[3];
    return true;
  }
};

}  // namespace rscalib::camera
