#pragma once
// Civera's radial model (Civera et al. 2009 §III; docs/formulation.md §10), defined from
// distorted to undistorted pixels with radii in millimetres via the pixel size (dx, dy)
// mm/pixel:
//   r_d = sqrt((dx (u_d - Cx))^2 + (dy (v_d - Cy))^2)
//   u_u = Cx + (u_d - Cx)(1 + k1 r_d^2 + k2 r_d^4),  v likewise
// Projection: u_u = Cx + f h_x / h_z, v_u = Cy + f h_y / h_z, then the distorted pixel by
// solving r_u = r_d (1 + k1 r_d^2 + k2 r_d^4) for r_d with Newton.
//
// params layout (5): [f, Cx, Cy, k1 (mm^-2), k2 (mm^-4)]; the pixel size is a constant.
#include <algorithm>
#include <cmath>
#include <limits>

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
    double rd = 0.0;
    if (!SolveDistortedRadius(k1, k2, std::sqrt(ru2_value), &rd)) return false;
    const double rd2 = rd * rd;
    const double dg = 1.0 + rd2 * (3.0 * k1 + 5.0 * k2 * rd2);
    const T ru_t = sqrt(ru2);
    const T g_t = T(rd) * (T(1.0) + T(rd2) * (params[3] + T(rd2) * params[4])) - ru_t;
    const T rd_t = T(rd) - g_t / dg;  // value rd, first derivatives exact
    const T scale = rd_t / ru_t;      // = 1 / (1 + k1 rd^2 + k2 rd^4)
    uv_d[0] = params[1] + du * scale;
    uv_d[1] = params[2] + dv * scale;
    return true;
  }

  // r_d with r_d (1 + k1 r_d^2 + k2 r_d^4) = r_u on the rising branch from r_d = 0 (where
  // the model is invertible): Newton kept inside a bisection bracket [0, r_peak].
  static bool SolveDistortedRadius(double k1, double k2, double ru, double* rd_out) {
    const auto g = [&](double r) {
      const double r2 = r * r;
      return r * (1.0 + r2 * (k1 + r2 * k2)) - ru;
    };
    const auto dg = [&](double r) {
      const double r2 = r * r;
      return 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2);
    };
    // Upper end of the bracket: the first zero of dg (r_peak), or a radius where g > 0.
    double hi = std::max(ru, 1e-12);
    if (k2 < 0.0 || k1 < 0.0) {
      // dg(r) = 1 + 3 k1 s + 5 k2 s^2 with s = r^2: smallest positive root, if any.
      double peak_s = std::numeric_limits<double>::infinity();
      if (k2 != 0.0) {
        const double disc = 9.0 * k1 * k1 - 20.0 * k2;
        if (disc >= 0.0) {
          for (double sign : {-1.0, 1.0}) {
            const double s_root = (-3.0 * k1 + sign * std::sqrt(disc)) / (10.0 * k2);
            if (s_root > 0.0) peak_s = std::min(peak_s, s_root);
          }
        }
      } else if (k1 < 0.0) {
        peak_s = -1.0 / (3.0 * k1);
      }
      if (std::isfinite(peak_s)) {
        hi = std::sqrt(peak_s);
        if (g(hi) < 0.0) return false;  // r_u beyond the largest distorted radius
      }
    }
    for (int doubling = 0; g(hi) < 0.0; ++doubling) {
      if (doubling > 200) return false;
      hi *= 2.0;
    }
    double lo = 0.0, rd = std::min(ru, hi);
    for (int iteration = 0; iteration < 100; ++iteration) {
      const double value = g(rd);
      if (value < 0.0) lo = rd;
      else hi = rd;
      const double slope = dg(rd);
      double next = rd - value / slope;
      if (!(slope > 0.0) || !(next > lo && next < hi)) next = 0.5 * (lo + hi);
      if (std::abs(next - rd) <= 1e-15 * std::max(1.0, ru) ||
          hi - lo <= 1e-15 * std::max(1.0, ru)) {
        rd = next;
        break;
      }
      rd = next;
    }
    if (!(std::abs(g(rd)) <= 1e-12 * std::max(1.0, ru)) || !(dg(rd) > 0.0)) return false;
    *rd_out = rd;
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
