// How much work a worker keeps leased: enough that its threads never run dry, about
// `seconds` of it at the measured speed beyond that, and at most `max_tasks` leases. A
// pure rule over the queue's load, so that tests can state it with numbers.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace tessera::worker {

// What the worker holds and has queued, and how fast it renders.
struct QueueLoad {
  size_t held = 0;                       // leased and not yet submitted
  uint64_t queued_rows = 0;              // rows not yet handed to a render thread
  double queued_samples = 0;             // camera samples in those rows
  double samples_per_thread_second = 0;  // measured (smoothed); 0 until a task finished
};

// A GetTask request's size: up to max_tasks tasks, stopping at max_samples (0: no limit).
struct LeaseRequest {
  uint32_t max_tasks = 0;
  uint64_t max_samples = 0;
};

struct Lookahead {
  int threads = 1;
  double seconds = 0.3;  // --lookahead
  int max_tasks = 64;    // --max-tasks

  // Whether to ask for more now: the threads are about to run dry (fewer than two rows per
  // thread queued), or, once the speed is known, less than half the lookahead is queued
  // (refilling at half, up to all of it, makes fewer and larger requests).
  bool wants_more(const QueueLoad& load) const {
    if (load.held >= size_t(max_tasks)) return false;
    if (load.queued_rows < 2 * uint64_t(threads)) return true;
    const double rate = load.samples_per_thread_second * threads;
    return rate > 0 && load.queued_samples < 0.5 * rate * seconds;
  }
  // As much work as the threads get through in the lookahead at the measured speed, less
  // what is queued; two tasks until there is a measurement. Only when wants_more().
  LeaseRequest request(const QueueLoad& load) const {
    const double rate = load.samples_per_thread_second * threads;
    const uint32_t room = uint32_t(max_tasks - int(load.held));
    if (rate <= 0) return {std::min(room, 2u), 0};
    return {room, uint64_t(std::max(1.0, rate * seconds - load.queued_samples))};
  }
};

}  // namespace tessera::worker
