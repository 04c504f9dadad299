#include <limits>
#include <random>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "rscalib/core/error.hpp"
#include "rscalib/spline/cubic_bspline.hpp"
#include "rscalib/spline/spline_fit.hpp"

using namespace rscalib::spline;

namespace {

CubicBSpline RandomSpline(std::mt19937& rng, int segments, int dimension) {
  std::uniform_real_distribution<double> gap(0.2, 1.5), value(-2.0, 2.0);
  std::vector<double> breakpoints{0.3};
  for (int s = 0; s < segments; ++s) breakpoints.push_back(breakpoints.back() + gap(rng));
  ControlPoints c(segments + 3, dimension);
  for (int i = 0; i < c.size(); ++i) c.data()[i] = value(rng);
  return CubicBSpline(CubicBSpline::ClampedKnots(breakpoints), c);
}

}  // namespace

TEST(BSplineBasis, PowerBasisMatchesCoxDeBoorAndSumsToOne) {
  std::mt19937 rng(1);
  const CubicBSpline curve = RandomSpline(rng, 7, 1);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double t = curve.t_begin() + u01(rng) * (curve.t_end() - curve.t_begin());
    const int span = curve.SpanAt(t);
    double ders[4][4];
    BasisFunctionDerivatives(curve.knots().data(), span, t, 2, ders);
    double weights[3][4];
    EvaluateSpanBasis(curve.PowerBasis(span), t, 2, weights);
    double sum = 0.0, sum_d1 = 0.0;
    for (int j = 0; j < 4; ++j) {
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(weights[k][j], ders[k][j], 1e-10);
      sum += weights[0][j];
      sum_d1 += weights[1][j];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_NEAR(sum_d1, 0.0, 1e-10);
  }
}

TEST(BSplineBasis, JetTimeCarriesTheDerivative) {
  // Instantiated with ceres::Jet: d w_j / dt from autodiff equals the analytic derivative.
  std::mt19937 rng(2);
  const CubicBSpline curve = RandomSpline(rng, 5, 1);
  using Jet = ceres::Jet<double, 1>;
  for (double t : {0.31, 1.0, 2.2, curve.t_end() - 1e-3}) {
    const SpanPowerBasis basis = curve.PowerBasis(curve.SpanAt(t));
    double w[3][4];
    Jet wj[3][4];
    EvaluateSpanBasis(basis, t, 2, w);
    EvaluateSpanBasis(basis, Jet(t, 0), 1, wj);
    for (int j = 0; j < 4; ++j) {
      EXPECT_NEAR(wj[0][j].a, w[0][j], 1e-14);
      EXPECT_NEAR(wj[0][j].v[0], w[1][j], 1e-10);
    }
  }
}

TEST(BSpline, KnotInsertionLeavesCurveUnchanged) {
  std::mt19937 rng(3);
  CubicBSpline curve = RandomSpline(rng, 6, 3);
  const CubicBSpline original = curve;
  std::uniform_real_distribution<double> u01(0.01, 0.99);
  for (int insertions = 0; insertions < 10; ++insertions)
    curve.InsertKnot(curve.t_begin() + u01(rng) * (curve.t_end() - curve.t_begin()));
  EXPECT_EQ(curve.num_control_points(), original.num_control_points() + 10);
  for (int trial = 0; trial < 300; ++trial) {
    const double t =
        original.t_begin() + (trial + 0.5) / 300.0 * (original.t_end() - original.t_begin());
    for (int derivative = 0; derivative <= 2; ++derivative)
      EXPECT_LT((curve.Evaluate(t, derivative) - original.Evaluate(t, derivative)).norm(), 1e-12);
  }
}

TEST(BSpline, FitRecoversGeneratingSpline) {
  std::mt19937 rng(4);
  const CubicBSpline truth = RandomSpline(rng, 8, 2);
  const int m = 400;
  Eigen::VectorXd times(m);
  for (int s = 0; s < m; ++s)
    times[s] = truth.t_begin() + (s + 0.5) / m * (truth.t_end() - truth.t_begin());
  Eigen::MatrixXd samples(m, 2);
  for (int s = 0; s < m; ++s) samples.row(s) = truth.Evaluate(times[s]).transpose();
  const CubicBSpline fitted = FitCubicBSpline(truth.knots(), times, samples);
  EXPECT_LT((fitted.control_points() - truth.control_points()).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(BSpline, RejectsBadInput) {
  EXPECT_THROW(CubicBSpline({0, 0, 0, 1, 1, 1}, ControlPoints::Zero(2, 1)), rscalib::InputError);
  const CubicBSpline curve = CubicBSpline::Uniform(0.0, 1.0, 3, 1);
  EXPECT_THROW(curve.Evaluate(1.5), rscalib::InputError);
  // Two spans without samples and no penalty: singular.
  Eigen::VectorXd times(2);
  times << 0.1, 0.2;
  EXPECT_THROW(FitCubicBSpline(curve.knots(), times, Eigen::MatrixXd::Zero(2, 1)),
               rscalib::InputError);
}

TEST(BSpline, RefusesAbsurdSizesBeforeAllocating) {
  // Petabytes: InputError from the size check, never std::bad_alloc or an out-of-memory kill.
  const int huge = std::numeric_limits<int>::max();
  EXPECT_THROW(CubicBSpline::Uniform(0.0, 1.0, huge / 2, 1000), rscalib::InputError);
  EXPECT_THROW(CubicBSpline::Uniform(0.0, 1.0, 1000, huge), rscalib::InputError);
  EXPECT_THROW(CubicBSpline::Uniform(0.0, 1.0, 4, 0), rscalib::InputError);
  EXPECT_THROW(CubicBSpline::Uniform(0.0, std::numeric_limits<double>::infinity(), 4, 1),
               rscalib::InputError);
}
