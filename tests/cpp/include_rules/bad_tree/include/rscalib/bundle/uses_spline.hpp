#pragma once
// Fixture of the include_rules test: bundle builds on core, geometry and camera, not on spline.
#include <rscalib/camera/camera_model.hpp>
#include <rscalib/spline/cubic_bspline.hpp>
