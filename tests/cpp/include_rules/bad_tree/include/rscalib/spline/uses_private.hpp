#pragma once
// Fixture of the include_rules test: an installed header includes a private one.
#include <vector>

#include "solver_common.hpp"
