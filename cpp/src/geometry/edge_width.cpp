// Compiled with -ffp-contract=off (CMakeLists.txt): a fused multiply-add would round once where
// numpy rounds twice, and the numbers must be numpy's to the bit.
#include "rscalib/geometry/edge_width.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "rscalib/core/error.hpp"

namespace rscalib::geometry {

EdgeProfileMaps EdgeProfileMapsFor(const Eigen::MatrixX2d& a, const Eigen::MatrixX2d& b,
                                   bool across_rim, double fraction,
                                   const Eigen::VectorXd& profile_s, double max_half_px,
                                   double min_half_px) {
  if (a.rows() != b.rows()) throw InputError("a and b must have one row per edge");
  if (profile_s.size() < 3) throw InputError("a profile needs at least 3 samples");
  struct Profile {
    double cx, cy, dx, dy, half;
  };
  std::vector<Profile> kept;
  kept.reserve(static_cast<std::size_t>(across_rim ? 2 * a.rows() : a.rows()));
  const auto keep = [&](double cx, double cy, double dx, double dy, double half) {
    half = std::min(half, max_half_px);
    if (half >= min_half_px) kept.push_back({cx, cy, dx, dy, half});
  };
  // circle grids: every edge's start centres first, then its end centres (numpy's concatenate)
  for (int pass = 0; pass < (across_rim ? 2 : 1); ++pass) {
    for (Eigen::Index i = 0; i < a.rows(); ++i) {
      const double ax = a(i, 0), ay = a(i, 1), bx = b(i, 0), by = b(i, 1);
      const double length = std::hypot(bx - ax, by - ay);
      if (!(length > 1e-6)) continue;
      const double tx = (bx - ax) / length, ty = (by - ay) / length;
      if (across_rim) {
        const double half = length * fraction;
        if (pass == 0) {
          keep(ax + tx * half, ay + ty * half, tx, ty, half);
        } else {
          keep(bx + -tx * half, by + -ty * half, -tx, -ty, half);
        }
      } else {
        keep(0.5 * (ax + bx), 0.5 * (ay + by), -ty, tx, length * fraction);
      }
    }
  }
  const Eigen::Index samples = profile_s.size();
  EdgeProfileMaps maps;
  maps.map_x.resize(static_cast<Eigen::Index>(kept.size()), samples);
  maps.map_y.resize(static_cast<Eigen::Index>(kept.size()), samples);
  maps.half_px.resize(static_cast<Eigen::Index>(kept.size()));
  for (std::size_t i = 0; i < kept.size(); ++i) {
    const Profile& p = kept[i];
    const auto row = static_cast<Eigen::Index>(i);
    maps.half_px[row] = p.half;
    for (Eigen::Index j = 0; j < samples; ++j) {
      const double s = profile_s[j] * p.half;
      maps.map_x(row, j) = static_cast<float>(p.cx + s * p.dx);
      maps.map_y(row, j) = static_cast<float>(p.cy + s * p.dy);
    }
  }
  return maps;
}

double EdgeWidthFromProfiles(
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>&
        profiles,
    const Eigen::VectorXd& half_px, double min_contrast) {
  const Eigen::Index count = profiles.rows(), samples = profiles.cols();
  if (half_px.size() != count) throw InputError("half_px must have one value per profile");
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (samples < 3) throw InputError("a profile needs at least 3 samples");
  const Eigen::Index smoothed_samples = samples - 2;
  const Eigen::Index ends = std::max<Eigen::Index>(2, samples / 12);
  if (ends > smoothed_samples) throw InputError("profiles too short for their ends");
  std::vector<double> smoothed(static_cast<std::size_t>(smoothed_samples));
  std::vector<double> widths;
  widths.reserve(static_cast<std::size_t>(count));
  // numpy's mean over a few columns of the profiles: summed left to right
  const auto sum_of = [](const double* values, Eigen::Index n) {
    double sum = values[0];
    for (Eigen::Index k = 1; k < n; ++k) sum += values[k];
    return sum;
  };
  for (Eigen::Index i = 0; i < count; ++i) {
    for (Eigen::Index j = 0; j < smoothed_samples; ++j) {
      const double p0 = profiles(i, j), p1 = profiles(i, j + 1), p2 = profiles(i, j + 2);
      smoothed[static_cast<std::size_t>(j)] = (p0 + p1 + p2) / 3.0;
    }
    const double step = 2.0 * half_px[i] / static_cast<double>(samples - 1);
    const double last =
        sum_of(smoothed.data() + smoothed_samples - ends, ends) / static_cast<double>(ends);
    const double first = sum_of(smoothed.data(), ends) / static_cast<double>(ends);
    const double contrast = std::abs(last - first);
    double steepest = 0.0;
    for (Eigen::Index j = 0; j + 1 < smoothed_samples; ++j)
      steepest = std::max(steepest, std::abs(smoothed[static_cast<std::size_t>(j + 1)] -
                                             smoothed[static_cast<std::size_t>(j)]));
    const double slope = steepest / step;
    if (contrast > min_contrast && slope > 0.0)
      widths.push_back(std::max(contrast / slope - step, 0.0));
  }
  if (widths.empty()) return nan;
  std::sort(widths.begin(), widths.end());
  const double h = 0.75 * static_cast<double>(widths.size() - 1);
  const auto low = static_cast<std::size_t>(h);
  if (low + 1 >= widths.size()) return widths[low];
  const double fraction = h - static_cast<double>(low);
  const double below = widths[low], above = widths[low + 1];
  // numpy's lerp: from the nearer end
  return fraction >= 0.5 ? above - (above - below) * (1.0 - fraction)
                         : below + (above - below) * fraction;
}

}  // namespace rscalib::geometry
