#pragma once
// Civera's radial model (SPEC §4), defined from distorted to undistorted pixels with
// radii in millimetres via the pixel size (dx, dy) mm/pixel:
//   r_d = sqrt((dx (u_d - Cx))^2 + (dy (v_d - Cy))^2)
//   u_u = Cx + (u_d - Cx)(1 + k1 r_d^2 + k2 r_d^4),  v likewise
// Projection: u_u = Cx + f h_x / h_z, v_u = Cy + f h_y / h_z, then the distorted pixel by
// solving r_u = r_d (1 + k1 r_d^2 + k2 r_d^4) for r_d with Newton.
//
// params layout (5): [f, Cx, Cy, k1 (mm^-2), k2 (mm^-4)]; the pixel size is a constant.
#include <algorithm>
#include <cmath>

#include "rscalib/core/scalar.hpp"

namespace rscalib::camera {

struct CiveraRadial {
  static constexpr int kNumParams = 5;
  static constexpr const char* kName = "civera-radial";

  // Distorted -> undistorted pixel (closed form).
  template <typename T>
  static void Undistort(const T* params, const double* pixel_size_mm, const T* uv_d, T* uv_u) {
    const T du = uv_d[0] - params[1];
    const T dv = uv_d[1] - params[2];
    const T rd2 = (pixel_size_mm[0] * du) * (pixel_size_mm[0] * du) +
                  (pixel_size_mm[1] * dv) * (pixel_size_mm[1] * dv);
    const T scale = T(1.0) + rd2 * (params[3] + rd2 * params[4]);
    uv_u[0] = params[1] + du * scale;
    uv_u[1] = params[2] + dv * scale;
  }

  // Undistorted -> distorted pixel. Newton runs on plain doubles; one last Newton step
  // in T carries the derivatives (implicit function theorem), so Jets are exact.
  // Returns false where r_d(1 + k1 r_d^2 + k2 r_d^4) is not invertible (derivative <= 0).
  template <typename T>
  static bool Distort(const T* params, const double* pixel_size_mm, const T* uv_u, T* uv_d) {
    using std::sqrt;
    const T du = uv_u[0] - params[1];
    const T dv = uv_u[1] - params[2];
    const T ru2 = (pixel_size_mm[0] * du) * (pixel_size_mm[0] * du) +
                  (pixel_size_mm[1] * dv) * (pixel_size_mm[1] * dv);
    const double ru2_value = ScalarValue(ru2);
    if (ru2_value < 1e-300) {  // at the centre distortion is the identity
      uv_d[0] = uv_u[0];
      uv_d[1] = uv_u[1];
      return true;
    }
    const double k1 = ScalarValue(params[3]), k2 = ScalarValue(params[4]);
    const double ru = std::sqrt(ru2_value);
    double rd = ru;
    for (int iteration = 0; iteration < 50; ++iteration) {
      const double rd2 = rd * rd;
      const double g = rd * (1.0 + rd2 * (k1 + rd2 * k2)) - ru;
      const double dg = 1.0 + rd2 * (3.0 * k1 + 5.0 * k2 * rd2);
      if (!(dg > 0.0)) return false;
      const double step = g / dg;
      rd -= step;
      if (std::abs(step) <= 1e-15 * std::max(1.0, ru)) break;
    }
    const double rd2 = rd * rd;
    const double dg = 1.0 + rd2 * (3.0 * k1 + 5.0 * k2 * rd2);
    if (!(dg > 0.0) || !(rd > 0.0)) return false;
    const T ru_t = sqrt(ru2);
    const T g_t = T(rd) * (T(1.0) + T(rd2) * (params[3] + T(rd2) * params[4])) - ru_t;
    const T rd_t = T(rd) - g_t / dg;  // value rd, first derivatives exact
    const T scale = rd_t / ru_t;     // = 1 / (1 + k1 rd^2 + k2 rd^4)
    uv_d[0] = params[1] + du * scale;
    uv_d[1] = params[2] + dv * scale;
    return true;
  }

  template <typename T>
  static bool Project(const T* params, const double* pixel_size_mm, const T* point_c, T* uv) {
    if (!(point_c[2] > T(0.0))) return false;
    const T uv_u[2] = {params[1] + params[0] * point_c[0] / point_c[2],
                       params[2] + params[0] * point_c[1] / point_c[2]};
    return Distort(params, pixel_size_mm, uv_u, uv);
  }
};

}  // namespace rscalib::camera
