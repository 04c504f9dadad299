#include <map>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "rscalib/core/error.hpp"
#include "rscalib/spline/spline_fit.hpp"

namespace rscalib::spline {

CubicBSpline FitCubicBSpline(const std::vector<double>& knots, const Eigen::VectorXd& times,
                             const Eigen::MatrixXd& samples, const SplineFitOptions& options) {
  const int n = static_cast<int>(knots.size()) - kSplineOrder;
  const int dim = static_cast<int>(samples.cols());
  const int m = static_cast<int>(times.size());
  if (samples.rows() != m) throw InputError("spline fit: times and samples differ in length");
  if (!samples.allFinite())
    throw InputError("spline fit: samples must be finite (NaN or infinity given)");
  if (!options.sample_weight.empty() && static_cast<int>(options.sample_weight.size()) != m)
    throw InputError("spline fit: one sample weight per sample is needed");
  const auto& lambda_in = options.acceleration_weight;
  if (!lambda_in.empty() && lambda_in.size() != 1 && static_cast<int>(lambda_in.size()) != dim)
    throw InputError("spline fit: acceleration_weight needs 1 or dimension values");
  // Validates the knot vector.
  CubicBSpline spline(knots, ControlPoints::Zero(n, dim));

  using Triplet = Eigen::Triplet<double>;
  std::vector<Triplet> data_terms, penalty_terms;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, dim);
  double ders[4][4];
  for (int s = 0; s < m; ++s) {
    const double w = options.sample_weight.empty() ? 1.0 : options.sample_weight[s];
    if (!(w >= 0.0)) throw InputError("spline fit: sample weights must be >= 0");
    const int span = spline.SpanAt(times[s]);
    BasisFunctionDerivatives(knots.data(), span, times[s], 0, ders);
    for (int a = 0; a < 4; ++a) {
      rhs.row(span - 3 + a) += w * ders[0][a] * samples.row(s);
      for (int b = 0; b < 4; ++b)
        data_terms.emplace_back(span - 3 + a, span - 3 + b, w * ders[0][a] * ders[0][b]);
    }
  }
  // \int x''(t)^2 dt per span, exact with 2-point Gauss (x'' is linear in a span).
  for (int span = kSplineDegree; span < n; ++span) {
    if (knots[span + 1] <= knots[span]) continue;
    const SpanQuadrature q = AccelerationQuadrature(knots[span], knots[span + 1]);
    for (int g = 0; g < 2; ++g) {
      BasisFunctionDerivatives(knots.data(), span, q.t[g], 2, ders);
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          penalty_terms.emplace_back(span - 3 + a, span - 3 + b,
                                     q.weight[g] * ders[2][a] * ders[2][b]);
    }
  }
  Eigen::SparseMatrix<double> normal(n, n), penalty(n, n);
  normal.setFromTriplets(data_terms.begin(), data_terms.end());
  penalty.setFromTriplets(penalty_terms.begin(), penalty_terms.end());

  // Dimensions sharing a penalty weight share a factorisation.
  std::map<double, std::vector<int>> dims_by_lambda;
  for (int d = 0; d < dim; ++d) {
    const double lambda =
        lambda_in.empty() ? 0.0 : (lambda_in.size() == 1 ? lambda_in[0] : lambda_in[d]);
    if (!(lambda >= 0.0)) throw InputError("spline fit: acceleration weights must be >= 0");
    dims_by_lambda[lambda].push_back(d);
  }
  ControlPoints control_points(n, dim);
  for (const auto& [lambda, dims] : dims_by_lambda) {
    Eigen::SparseMatrix<double> system = normal + lambda * penalty;
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(system);
    bool ok = solver.info() == Eigen::Success;
    if (ok) {
      const Eigen::VectorXd diagonal = solver.vectorD();
      ok = diagonal.minCoeff() > 1e-12 * std::max(1.0, diagonal.cwiseAbs().maxCoeff());
    }
    if (!ok)
      throw InputError(
          "spline fit is singular: some knot spans have too few samples; use fewer knots or "
          "an acceleration penalty");
    for (int d : dims) control_points.col(d) = solver.solve(rhs.col(d));
  }
  return CubicBSpline(knots, std::move(control_points));
}

}  // namespace rscalib::spline
