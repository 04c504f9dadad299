#pragma once
// Fixture of the include_rules test: a header that follows the rules.
#include "rscalib/geometry/pose.hpp"
