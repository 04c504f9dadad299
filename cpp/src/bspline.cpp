#include <algorithm>
#include <cmath>
#include <sstream>

#include "rscalib/core/error.hpp"
#include "rscalib/spline/bspline_basis.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

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

// ---------------------------------------------------------------- CubicBSpline

CubicBSpline::CubicBSpline(std::vector<double> knots, ControlPoints control_points)
    : knots_(std::move(knots)), control_points_(std::move(control_points)) {
  const int n = static_cast<int>(control_points_.rows());
  if (n < kSplineOrder)
    throw InputError("cubic B-spline needs at least 4 control points, got " + std::to_string(n));
  if (control_points_.cols() < 1) throw InputError("cubic B-spline needs dimension >= 1");
  if (static_cast<int>(knots_.size()) != n + kSplineOrder)
    throw InputError("cubic B-spline with " + std::to_string(n) + " control points needs " +
                     std::to_string(n + kSplineOrder) + " knots, got " +
                     std::to_string(knots_.size()));
  for (size_t i = 1; i < knots_.size(); ++i)
    if (!(knots_[i] >= knots_[i - 1]) || !std::isfinite(knots_[i]))
      throw InputError("knots must be finite and non-decreasing");
  for (int i = 1; i < kSplineOrder; ++i)
    if (knots_[i] != knots_[0] || knots_[n + i] != knots_[n])
      throw InputError("knots must be clamped: 4 equal knots at each end");
  if (!(knots_[n] > knots_[0])) throw InputError("spline domain must have positive length");
  for (int i = kSplineOrder, run = 1; i < n; ++i) {
    run = (knots_[i] == knots_[i - 1] && i > kSplineOrder) ? run + 1 : 1;
    if (run > kSplineDegree)
      throw InputError("an interior knot may repeat at most 3 times (the curve would break)");
  }
}

std::vector<double> CubicBSpline::ClampedKnots(const std::vector<double>& breakpoints) {
  if (breakpoints.size() < 2) throw InputError("need at least 2 breakpoints");
  for (size_t i = 1; i < breakpoints.size(); ++i)
    if (!(breakpoints[i] > breakpoints[i - 1]))
      throw InputError("breakpoints must be strictly increasing");
  std::vector<double> knots;
  knots.reserve(breakpoints.size() + 6);
  knots.insert(knots.end(), 3, breakpoints.front());
  knots.insert(knots.end(), breakpoints.begin(), breakpoints.end());
  knots.insert(knots.end(), 3, breakpoints.back());
  return knots;
}

CubicBSpline CubicBSpline::Uniform(double t_begin, double t_end, int num_segments, int dimension) {
  if (num_segments < 1) throw InputError("need at least one spline segment");
  if (!(t_end > t_begin)) throw InputError("spline domain must have positive length");
  std::vector<double> breakpoints(num_segments + 1);
  for (int s = 0; s <= num_segments; ++s)
    breakpoints[s] = t_begin + (t_end - t_begin) * s / num_segments;
  breakpoints.back() = t_end;
  return CubicBSpline(ClampedKnots(breakpoints),
                      ControlPoints::Zero(num_segments + kSplineDegree, dimension));
}

std::vector<double> CubicBSpline::Breakpoints() const {
  std::vector<double> out;
  for (int i = kSplineDegree; i <= num_control_points(); ++i)
    if (out.empty() || knots_[i] != out.back()) out.push_back(knots_[i]);
  return out;
}

int CubicBSpline::SpanAt(double t) const {
  const double tolerance = 1e-12 * (t_end() - t_begin());
  if (!(t >= t_begin() - tolerance && t <= t_end() + tolerance)) {
    std::ostringstream message;
    message.precision(17);
    message << "time " << t << " s is outside the spline domain [" << t_begin() << ", "
            << t_end() << "] s";
    throw InputError(message.str());
  }
  return FindSpan(knots_.data(), num_control_points(), t);
}

Eigen::VectorXd CubicBSpline::Evaluate(double t, int derivative) const {
  Eigen::VectorXd out(dimension());
  EvaluateMany(&t, 1, derivative, out.data());
  return out;
}

void CubicBSpline::EvaluateMany(const double* times, int count, int derivative,
                                double* out) const {
  if (derivative < 0 || derivative > 3) throw InputError("derivative order must be 0..3");
  const int dim = dimension();
  double ders[4][4];
  for (int m = 0; m < count; ++m) {
    const int span = SpanAt(times[m]);
    BasisFunctionDerivatives(knots_.data(), span, times[m], derivative, ders);
    double* row = out + static_cast<size_t>(m) * dim;
    for (int d = 0; d < dim; ++d) {
      double value = 0.0;
      for (int j = 0; j < 4; ++j) value += ders[derivative][j] * control_points_(span - 3 + j, d);
      row[d] = value;
    }
  }
}

void CubicBSpline::InsertKnot(double t) {
  if (!(t > t_begin() && t < t_end()))
    throw InputError("a knot can only be inserted strictly inside the spline domain");
  const int n = num_control_points();
  const int k = FindSpan(knots_.data(), n, t);  // knots[k] <= t < knots[k+1]
  int multiplicity = 0;
  for (int i = k; i >= 0 && knots_[i] == t; --i) ++multiplicity;
  if (multiplicity >= 2)
    throw InputError("knot already present twice; another copy would break C1 continuity");
  // New control point Q_i = (1 - a_i) P_{i-1} + a_i P_i for i in (k-p, k], a_i from knots.
  ControlPoints updated(n + 1, dimension());
  updated.topRows(k - kSplineDegree + 1) = control_points_.topRows(k - kSplineDegree + 1);
  for (int i = k - kSplineDegree + 1; i <= k; ++i) {
    const double alpha = (t - knots_[i]) / (knots_[i + kSplineDegree] - knots_[i]);
    updated.row(i) = (1.0 - alpha) * control_points_.row(i - 1) + alpha * control_points_.row(i);
  }
  updated.bottomRows(n - k) = control_points_.bottomRows(n - k);
  knots_.insert(knots_.begin() + k + 1, t);
  control_points_ = std::move(updated);
}

}  // namespace rscalib::spline
