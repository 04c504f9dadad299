#pragma once
// The plain double inside a scalar that may be a ceres::Jet: discrete decisions
// (which knot span, which branch of a formula) are taken on the value alone.
#include <ceres/jet.h>

namespace rscalib {

inline double ScalarValue(double x) { return x; }

template <typename T, int N>
double ScalarValue(const ceres::Jet<T, N>& x) {
  return ScalarValue(x.a);
}

}  // namespace rscalib
