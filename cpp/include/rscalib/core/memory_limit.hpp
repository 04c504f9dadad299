#pragma once
// Sizes are checked against the machine before allocating: a request for more memory than the
// machine has is bad input (InputError naming the number), not an out-of-memory kill later.
#include <cstdio>
#include <string>

#if defined(__unix__) || defined(__APPLE__)
#include <unistd.h>
#endif

#include "rscalib/core/error.hpp"

namespace rscalib {

// Physical memory of this machine in bytes; 0 when the platform cannot tell.
inline double PhysicalMemoryBytes() {
#if defined(_SC_PHYS_PAGES) && defined(_SC_PAGESIZE)
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page_bytes = sysconf(_SC_PAGESIZE);
  if (pages > 0 && page_bytes > 0) return static_cast<double>(pages) * page_bytes;
#endif
  return 0.0;
}

// Throws InputError "<what> needs N GB, more than the M GB of memory of this machine" when `bytes`
// (a double, so products of counts cannot overflow) exceeds the physical memory.
inline void CheckMemory(double bytes, const std::string& what) {
  double limit = PhysicalMemoryBytes();
  if (limit <= 0.0) limit = 1e15;  // unknown: refuse only the impossible
  if (bytes <= limit) return;
  char text[160];
  std::snprintf(text, sizeof(text),
                " needs %.3g GB, more than the %.3g GB of memory of this machine", bytes / 1e9,
                limit / 1e9);
  throw InputError(what + text);
}

}  // namespace rscalib
