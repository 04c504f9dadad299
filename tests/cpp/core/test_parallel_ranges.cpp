// rscalib::ParallelRanges: every index once, in contiguous ranges, whatever the thread count; an
// exception in any range reaches the caller instead of terminating the process.
#include "rscalib/core/parallel_ranges.hpp"

#include <atomic>
#include <cstddef>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace rscalib {
namespace {

TEST(ParallelRanges, VisitsEveryIndexOnceForAnyThreadCount) {
  for (int threads : {1, 2, 3, 8}) {
    for (std::size_t count : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{1000}}) {
      std::vector<int> visits(count, 0);
      std::atomic<int> ranges{0};
      ParallelRanges(count, threads, 1, [&](std::size_t begin, std::size_t end) {
        ASSERT_LE(begin, end);
        ++ranges;
        for (std::size_t i = begin; i < end; ++i) ++visits[i];
      });
      for (std::size_t i = 0; i < count; ++i) EXPECT_EQ(visits[i], 1) << threads << " " << count;
      EXPECT_LE(ranges.load(), std::max(1, threads));
    }
  }
}

TEST(ParallelRanges, KeepsSmallLoopsOnTheCallingThread) {
  int ranges = 0;  // not atomic: one range must mean no other thread
  ParallelRanges(100, 4, 64, [&](std::size_t begin, std::size_t end) {
    ++ranges;
    EXPECT_EQ(begin, 0u);
    EXPECT_EQ(end, 100u);
  });
  EXPECT_EQ(ranges, 1);
}

TEST(ParallelRanges, RethrowsAnExceptionFromAnyRange) {
  for (int threads : {1, 2, 4}) {
    EXPECT_THROW(ParallelRanges(1000, threads, 1,
                                [](std::size_t begin, std::size_t end) {
                                  if (begin <= 999 && 999 < end) throw std::runtime_error("last");
                                }),
                 std::runtime_error);
  }
}

}  // namespace
}  // namespace rscalib
