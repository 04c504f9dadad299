// Fixture of the include_rules test: implements no header of its name.
#include "rscalib/camera/camera_model.hpp"
