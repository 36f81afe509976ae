// A parallel for over [0, count) on plain std::threads (internal to core/denoise).
//
// Indices are handed out from a shared counter, so which thread runs an index depends on
// scheduling; what an index computes must not (each writes only its own pixels, and no sum
// crosses indices), which keeps the denoiser's output the same bits for any thread count.
#pragma once

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

namespace tessera {
namespace nfor {

// body(index, thread) with thread in [0, threads): per-thread scratch can be indexed by it.
// The first exception a body throws is rethrown here once every thread has stopped.
template <typename Body>
void parallel_for(int count, int threads, const Body& body) {
  threads = std::max(1, std::min(threads, count));
  std::atomic<int> next{0};
  std::vector<std::exception_ptr> errors(static_cast<size_t>(threads));
  auto run = [&](int thread) {
    try {
      for (int i = next++; i < count; i = next++) body(i, thread);
    } catch (...) {
      errors[size_t(thread)] = std::current_exception();
      next = count;
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(run, t);
  run(0);
  for (std::thread& t : pool) t.join();
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace nfor
}  // namespace tessera
