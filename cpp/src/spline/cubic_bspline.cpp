#include "rscalib/spline/cubic_bspline.hpp"

#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <utility>

#include "rscalib/core/error.hpp"
#include "rscalib/core/memory_limit.hpp"

namespace rscalib::spline {

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
  if (dimension < 1) throw InputError("cubic B-spline needs dimension >= 1");
  if (!(t_end > t_begin) || !std::isfinite(t_end - t_begin))
    throw InputError("spline domain must be finite and have positive length");
  // Breakpoints, knots and control points, counted in doubles (no int overflow below).
  const double values = (num_segments + 1.0) * 2 + 6 + (num_segments + 3.0) * dimension;
  CheckMemory(8.0 * values, "a uniform spline of " + std::to_string(num_segments) + " segments x " +
                                std::to_string(dimension) + " dimensions");
  if (num_segments > std::numeric_limits<int>::max() - 2 * kSplineOrder)
    throw InputError("too many spline segments: " + std::to_string(num_segments));
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
    message << "time " << t << " s is outside the spline domain [" << t_begin() << ", " << t_end()
            << "] s";
    throw InputError(message.str());
  }
  return FindSpan(knots_.data(), num_control_points(), t);
}

Eigen::VectorXd CubicBSpline::Evaluate(double t, int derivative) const {
  Eigen::VectorXd out(dimension());
  EvaluateMany(&t, 1, derivative, out.data());
  return out;
}

void CubicBSpline::EvaluateMany(const double* times, int count, int derivative, double* out) const {
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
