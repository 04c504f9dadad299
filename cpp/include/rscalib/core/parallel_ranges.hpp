#pragma once
// A loop of independent iterations cut into contiguous ranges, one per thread (the calling thread
// takes the first): each iteration writes only its own outputs, so the result is the same for
// every thread count. An exception thrown in any range is rethrown in the caller once all have
// ended (a C++ exception must not escape a std::thread: it would abort the interpreter).
#include <algorithm>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace rscalib {

// fn(begin, end) over [0, count), on at most num_threads threads and with at least
// min_per_thread iterations each (thread start-up costs ~20 us).
template <typename Fn>
void ParallelRanges(std::size_t count, int num_threads, std::size_t min_per_thread, Fn&& fn) {
  const std::size_t by_size = count / std::max<std::size_t>(1, min_per_thread);
  const std::size_t threads =
      std::max<std::size_t>(1, std::min<std::size_t>(std::max(1, num_threads), by_size));
  if (threads == 1) {
    fn(std::size_t{0}, count);
    return;
  }
  std::vector<std::exception_ptr> errors(threads);
  const auto run = [&](std::size_t t) {
    try {
      fn(count * t / threads, count * (t + 1) / threads);
    } catch (...) {
      errors[t] = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (std::size_t t = 1; t < threads; ++t) pool.emplace_back(run, t);
  run(0);
  for (std::thread& thread : pool) thread.join();
  for (const std::exception_ptr& error : errors)
    if (error) std::rethrow_exception(error);
}

}  // namespace rscalib
