// Per-call cost of pose-spline evaluation in C++ (docs/benchmarks.md).
// Usage: rscalib_bench_spline [calls]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "rscalib/spline/pose_spline.hpp"
#include "rscalib/spline/cubic_bspline.hpp"

using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const int calls = argc > 1 ? std::atoi(argv[1]) : 2000000;
  auto spline = rscalib::spline::CubicBSpline::Uniform(0.0, 60.0, 600, 6);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> value(-0.3, 0.3), time(0.0, 60.0);
  for (int i = 0; i < spline.mutable_control_points().size(); ++i)
    spline.mutable_control_points().data()[i] = value(rng);
  std::vector<double> times(calls);
  for (double& t : times) t = time(rng);
  double sink = 0.0;

  auto started = Clock::now();
  for (double t : times) sink += spline.Evaluate(t)[0];
  const double evaluate_ns = std::chrono::duration<double, std::nano>(Clock::now() - started).count() / calls;

  started = Clock::now();
  for (double t : times) sink += rscalib::spline::PoseAt(spline, t).translation_cw[0];
  const double pose_ns = std::chrono::duration<double, std::nano>(Clock::now() - started).count() / calls;

  // The cost functors' path: cached span power basis, 4 control points, rotate a point.
  std::vector<rscalib::spline::SpanPowerBasis> bases;
  for (int span = 3; span < spline.num_control_points(); ++span) bases.push_back(spline.PowerBasis(span));
  const double point_w[3] = {0.1, 0.2, 0.0};
  started = Clock::now();
  for (double t : times) {
    const int span = spline.SpanAt(t);
    double w[3][4];
    rscalib::spline::EvaluateSpanBasis(bases[span - 3], t, 0, w);
    const double* c[4];
    for (int j = 0; j < 4; ++j) c[j] = spline.control_points().data() + 6 * (span - 3 + j);
    double state[6], point_c[3];
    rscalib::spline::CombineControlPoints(w[0], c, 6, state);
    rscalib::geometry::TransformWorldToCamera(state, point_w, point_c);
    sink += point_c[2];
  }
  const double functor_ns = std::chrono::duration<double, std::nano>(Clock::now() - started).count() / calls;

  std::printf("{\"calls\": %d, \"evaluate_ns\": %.1f, \"pose_ns\": %.1f, \"span_basis_transform_ns\": %.1f, "
              "\"sink\": %.3f}\n", calls, evaluate_ns, pose_ns, functor_ns, sink);
  return 0;
}
