// Cubic B-spline basis: span search, Cox-de Boor with derivatives, power basis per span
// (docs/formulation.md §1).
#include "rscalib/spline/bspline_basis.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace rscalib::spline {

int FindSpan(const double* knots, int num_control_points, double t) {
  const int first = kSplineDegree;
  const int last = num_control_points - 1;
  if (t >= knots[last + 1]) return last;
  if (t <= knots[first]) return first;
  // Largest i in [first, last] with knots[i] <= t.
  const double* it = std::upper_bound(knots + first, knots + last + 1, t);
  return static_cast<int>(it - knots) - 1;
}

void BasisFunctionDerivatives(const double* knots, int span, double t, int max_derivative,
                              double ders[4][4]) {
  constexpr int p = kSplineDegree;
  // ndu: basis functions (upper triangle) and knot differences (lower triangle).
  double ndu[p + 1][p + 1];
  double left[p + 1], right[p + 1];
  ndu[0][0] = 1.0;
  for (int j = 1; j <= p; ++j) {
    left[j] = t - knots[span + 1 - j];
    right[j] = knots[span + j] - t;
    double saved = 0.0;
    for (int r = 0; r < j; ++r) {
      ndu[j][r] = right[r + 1] + left[j - r];
      const double temp = ndu[r][j - 1] / ndu[j][r];
      ndu[r][j] = saved + right[r + 1] * temp;
      saved = left[j - r] * temp;
    }
    ndu[j][j] = saved;
  }
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j) ders[k][j] = 0.0;
  for (int r = 0; r <= p; ++r) ders[0][r] = ndu[r][p];

  const int n = std::min(max_derivative, p);
  double a[2][p + 1];
  for (int r = 0; r <= p; ++r) {
    int s1 = 0, s2 = 1;
    a[0][0] = 1.0;
    for (int k = 1; k <= n; ++k) {
      double d = 0.0;
      const int rk = r - k, pk = p - k;
      if (r >= k) {
        a[s2][0] = a[s1][0] / ndu[pk + 1][rk];
        d = a[s2][0] * ndu[rk][pk];
      }
      const int j1 = (rk >= -1) ? 1 : -rk;
      const int j2 = (r - 1 <= pk) ? k - 1 : p - r;
      for (int j = j1; j <= j2; ++j) {
        a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][rk + j];
        d += a[s2][j] * ndu[rk + j][pk];
      }
      if (r <= pk) {
        a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
        d += a[s2][k] * ndu[r][pk];
      }
      ders[k][r] = d;
      std::swap(s1, s2);
    }
  }
  double factor = p;
  for (int k = 1; k <= n; ++k) {
    for (int j = 0; j <= p; ++j) ders[k][j] *= factor;
    factor *= (p - k);
  }
}

SpanPowerBasis ComputeSpanPowerBasis(const double* knots, int span) {
  SpanPowerBasis basis;
  basis.span = span;
  basis.span_start = knots[span];
  double ders[4][4];
  BasisFunctionDerivatives(knots, span, knots[span], 3, ders);
  // Taylor expansion at the span start: coefficient of u^k is w^(k)(start) / k!.
  constexpr double kInverseFactorial[4] = {1.0, 1.0, 0.5, 1.0 / 6.0};
  for (int j = 0; j < 4; ++j)
    for (int k = 0; k < 4; ++k) basis.coefficients(j, k) = ders[k][j] * kInverseFactorial[k];
  return basis;
}

SpanQuadrature AccelerationQuadrature(double span_start, double span_end) {
  const double half = 0.5 * (span_end - span_start);
  const double mid = 0.5 * (span_end + span_start);
  const double offset = half / std::sqrt(3.0);
  return SpanQuadrature{{mid - offset, mid + offset}, {half, half}};
}

}  // namespace rscalib::spline
