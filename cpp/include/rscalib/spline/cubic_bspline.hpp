#pragma once
// A non-uniform cubic B-spline curve x(t) in R^N with clamped ends
// (layout in bspline_basis.hpp and docs/conventions.md).
//
// Control points are stored row-major, one contiguous row per control point, so that
// a solver can use each row directly as a parameter block.
#include <vector>

#include <Eigen/Core>

#include "rscalib/spline/bspline_basis.hpp"

namespace rscalib::spline {

using ControlPoints = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

class CubicBSpline {
 public:
  // knots: n + 4 non-decreasing values, clamped (4 equal at each end);
  // control_points: n x dimension.
  CubicBSpline(std::vector<double> knots, ControlPoints control_points);

  // Clamped knot vector from strictly increasing breakpoints b_0 < ... < b_m:
  // [b0, b0, b0, b0, b1, ..., b_{m-1}, bm, bm, bm, bm] (m + 3 control points).
  static std::vector<double> ClampedKnots(const std::vector<double>& breakpoints);
  // num_segments uniform segments on [t_begin, t_end], all control points zero.
  static CubicBSpline Uniform(double t_begin, double t_end, int num_segments, int dimension);

  int dimension() const { return static_cast<int>(control_points_.cols()); }
  int num_control_points() const { return static_cast<int>(control_points_.rows()); }
  int num_segments() const { return num_control_points() - kSplineDegree; }
  double t_begin() const { return knots_[kSplineDegree]; }
  double t_end() const { return knots_[num_control_points()]; }
  const std::vector<double>& knots() const { return knots_; }
  // Distinct knots b_0..b_m of the domain (segment s is [b_s, b_{s+1})).
  std::vector<double> Breakpoints() const;
  const ControlPoints& control_points() const { return control_points_; }
  ControlPoints& mutable_control_points() { return control_points_; }

  // Span of t (see FindSpan); throws InputError when t is outside the domain by more
  // than a relative 1e-12 of its length.
  int SpanAt(double t) const;
  int SegmentAt(double t) const { return SpanAt(t) - kSplineDegree; }
  SpanPowerBasis PowerBasis(int span) const { return ComputeSpanPowerBasis(knots_.data(), span); }

  // d^derivative x / dt^derivative at t, derivative in 0..3.
  Eigen::VectorXd Evaluate(double t, int derivative = 0) const;
  // Vectorised: out is count x dimension, row-major.
  void EvaluateMany(const double* times, int count, int derivative, double* out) const;

  // Boehm knot insertion: adds knot t (strictly inside the domain) without changing
  // the curve; the control points around it are replaced by 4 new ones (one more in all).
  void InsertKnot(double t);

 private:
  std::vector<double> knots_;
  ControlPoints control_points_;
};

}  // namespace rscalib::spline
