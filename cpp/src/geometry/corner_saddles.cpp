// Compiled with -ffp-contract=off (CMakeLists.txt): numpy's sample places to the bit.
#include "rscalib/geometry/corner_saddles.hpp"

#include <algorithm>
#include <vector>

#include "rscalib/core/error.hpp"

namespace rscalib::geometry {

namespace {

// numpy's median: the middle value, or the mean of the middle two
double Median(std::vector<double> values) {
  const std::size_t half = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(half),
                   values.end());
  const double upper = values[half];
  if (values.size() % 2 == 1) return upper;
  const double lower =
      *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(half));
  return (lower + upper) / 2.0;
}

}  // namespace

void SaddleSamplePoints(const Eigen::MatrixX2d& grid, int rows, int cols, double fraction,
                        SampleMap* map_x, SampleMap* map_y) {
  if (rows < 2 || cols < 2 || grid.rows() != static_cast<Eigen::Index>(rows) * cols)
    throw InputError("grid must hold rows x cols (each at least 2) corners");
  const auto at = [&](int r, int c, int k) {
    return grid(static_cast<Eigen::Index>(r) * cols + c, k);
  };
  // central differences inside, one-sided at the ends (numpy's gradient, unit spacing)
  const auto along_cols = [&](int r, int c, int k) {
    if (c == 0) return at(r, 1, k) - at(r, 0, k);
    if (c == cols - 1) return at(r, cols - 1, k) - at(r, cols - 2, k);
    return (at(r, c + 1, k) - at(r, c - 1, k)) / 2.0;
  };
  const auto along_rows = [&](int r, int c, int k) {
    if (r == 0) return at(1, c, k) - at(0, c, k);
    if (r == rows - 1) return at(rows - 1, c, k) - at(rows - 2, c, k);
    return (at(r + 1, c, k) - at(r - 1, c, k)) / 2.0;
  };
  map_x->resize(grid.rows(), 4);
  map_y->resize(grid.rows(), 4);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const Eigen::Index i = static_cast<Eigen::Index>(r) * cols + c;
      for (int k = 0; k < 2; ++k) {
        const double g = at(r, c, k), u = along_cols(r, c, k), v = along_rows(r, c, k);
        const double diagonal = fraction * (u + v), anti = fraction * (u - v);
        SampleMap& map = k == 0 ? *map_x : *map_y;
        map(i, 0) = static_cast<float>(g + diagonal);
        map(i, 1) = static_cast<float>(g - diagonal);
        map(i, 2) = static_cast<float>(g + anti);
        map(i, 3) = static_cast<float>(g - anti);
      }
    }
  }
}

bool CornersAreSaddles(
    const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>>& values,
    const Eigen::Ref<const Eigen::Matrix<bool, Eigen::Dynamic, 1>>& even, double min_contrast,
    double min_gap_fraction) {
  const Eigen::Index n = values.rows();
  if (even.size() != n) throw InputError("even must have one value per corner");
  if (n == 0) throw InputError("no corners to check");
  std::vector<double> convention(static_cast<std::size_t>(n)), other(convention.size()),
      spread(convention.size());
  for (Eigen::Index i = 0; i < n; ++i) {
    const double v0 = values(i, 0), v1 = values(i, 1), v2 = values(i, 2), v3 = values(i, 3);
    const double diagonal_bright = std::min(v0, v1) - std::max(v2, v3);
    const double anti_bright = std::min(v2, v3) - std::max(v0, v1);
    const auto k = static_cast<std::size_t>(i);
    convention[k] = even[i] ? diagonal_bright : anti_bright;
    other[k] = even[i] ? anti_bright : diagonal_bright;
    spread[k] =
        std::max(std::max(v0, v1), std::max(v2, v3)) - std::min(std::min(v0, v1), std::min(v2, v3));
  }
  const std::vector<double>& gap = Median(convention) >= Median(other) ? convention : other;
  const double contrast = Median(spread);
  return contrast >= min_contrast &&
         *std::min_element(gap.begin(), gap.end()) >= min_gap_fraction * contrast;
}

}  // namespace rscalib::geometry
