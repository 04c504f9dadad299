#pragma once
// Errors the core reports to its callers. The Python binding maps InputError to
// rscalib.InputError (a ValueError), so bad input never aborts the interpreter.
#include <stdexcept>
#include <string>

namespace rscalib {

// Bad input from the caller: wrong sizes, out-of-domain times, degenerate data.
class InputError : public std::invalid_argument {
 public:
  explicit InputError(const std::string& what) : std::invalid_argument(what) {}
};

}  // namespace rscalib
