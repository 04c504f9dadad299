#pragma once
// Cubic (order 4) B-spline basis on a non-uniform knot vector.
//
// Knot vector layout (docs/conventions.md, "Trajectory spline"): for n control points
// the knot vector has n + 4 entries, clamped: knots[0..3] are equal to the domain start,
// knots[n..n+3] to the domain end. Span i (3 <= i <= n-1) is [knots[i], knots[i+1]) and
// its curve is sum_{j=0..3} w_j(t) c_{i-3+j}. Segment index = span - 3.
//
// Inside a span every basis function is a cubic polynomial in u = t - knots[i]; we store
// its power-basis coefficients (SpanPowerBasis), computed once from Cox-de Boor in double,
// and evaluate that polynomial for any scalar type T (double or ceres::Jet). This is what
// lets a cost functor keep "its" span while autodiff moves t slightly across a knot.
#include <Eigen/Core>

namespace rscalib::spline {

constexpr int kSplineOrder = 4;
constexpr int kSplineDegree = 3;

// Row j holds the coefficients of w_j(u) = sum_k M(j, k) u^k, u = t - span_start.
struct SpanPowerBasis {
  int span = -1;
  double span_start = 0.0;
  Eigen::Matrix4d coefficients = Eigen::Matrix4d::Zero();
};

// Index i with knots[i] <= t < knots[i+1] restricted to the valid spans [3, n-1];
// t at (or beyond) the domain end maps to the last span, before the start to the first.
int FindSpan(const double* knots, int num_control_points, double t);

// Basis functions of span `span` and their derivatives 0..max_derivative (<= 3) at t
// (Cox-de Boor / de Boor's derivative recursion). ders[k][j] = d^k w_j / dt^k.
void BasisFunctionDerivatives(const double* knots, int span, double t, int max_derivative,
                              double ders[4][4]);

SpanPowerBasis ComputeSpanPowerBasis(const double* knots, int span);

// Weights (and up to the second derivative) of the 4 active control points at time t,
// from the span's power basis; weights[k][j] = d^k w_j / dt^k. T: double or ceres::Jet.
template <typename T>
void EvaluateSpanBasis(const SpanPowerBasis& basis, const T& t, int max_derivative,
                       T weights[3][4]) {
  const T u = t - basis.span_start;
  const T u2 = u * u;
  const T u3 = u2 * u;
  const Eigen::Matrix4d& m = basis.coefficients;
  for (int j = 0; j < 4; ++j) {
    weights[0][j] = m(j, 0) + m(j, 1) * u + m(j, 2) * u2 + m(j, 3) * u3;
    if (max_derivative >= 1) weights[1][j] = m(j, 1) + 2.0 * m(j, 2) * u + 3.0 * m(j, 3) * u2;
    if (max_derivative >= 2) weights[2][j] = 2.0 * m(j, 2) + 6.0 * m(j, 3) * u;
  }
}

// x = sum_j w_j c_j over the 4 active control points (each `dimension` long).
template <typename T, typename C>
void CombineControlPoints(const T weights[4], const C* const control_points[4], int dimension,
                          T* out) {
  for (int d = 0; d < dimension; ++d) {
    out[d] = weights[0] * control_points[0][d];
    for (int j = 1; j < 4; ++j) out[d] += weights[j] * control_points[j][d];
  }
}

// Two-point Gauss-Legendre nodes and weights on a span: the acceleration of a cubic
// is linear in a span, so its square integrates exactly with these (motion prior).
struct SpanQuadrature {
  double t[2];
  double weight[2];
};
SpanQuadrature AccelerationQuadrature(double span_start, double span_end);

}  // namespace rscalib::spline
