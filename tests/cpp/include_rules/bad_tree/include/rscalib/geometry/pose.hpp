#pragma once
// Fixture of the include_rules test: geometry must not depend on spline.
#include "rscalib/core/error.hpp"
#include "rscalib/spline/cubic_bspline.hpp"
