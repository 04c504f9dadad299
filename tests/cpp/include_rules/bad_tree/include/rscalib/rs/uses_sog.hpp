#pragma once
// Fixture of the include_rules test: rs and sog are peers.
#include <rscalib/camera/camera_model.hpp>
#include <rscalib/sog/ekf.hpp>
