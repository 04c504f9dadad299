// Fixture of the include_rules test: a source that follows the rules.
#include "rscalib/camera/camera_model.hpp"
