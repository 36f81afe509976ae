// A worker's sender: threads that encode finished tasks' sums (byte planes, zstd) and
// submit every finished task in one SubmitResults call, with retries, along with the
// worker's busy and total render-thread seconds (its utilization). Up to kInFlight calls
// at once: on a far or narrow link a call waits a round trip for its answer, and results
// finished meanwhile go in the next call at once instead of waiting for it (stop-and-wait
// left a 10 Mbit/s link idle a round trip per batch).
#pragma once

#include <thread>
#include <vector>

#include "worker/link.h"
#include "worker/task_queue.h"

namespace tessera::worker {

// Results of these encoded sizes (in a batch's order) in SubmitResults calls of at most
// `max_call` bytes each (a larger one goes alone), none past `max_message` (`too_large`:
// no call can carry them).
struct CallPlan {
  std::vector<std::vector<size_t>> calls;
  std::vector<size_t> too_large;
};
CallPlan plan_calls(const std::vector<uint64_t>& sizes, uint64_t max_call, uint64_t max_message);

class Sender {
 public:
  static constexpr int kLingerMs = 50;                           // how long finished results may wait for company
  static constexpr int kAttempts = 5;                            // then the batch is dropped: its leases expire
  static constexpr int kInFlight = 4;                            // SubmitResults calls at once, at most
  static constexpr uint64_t kMaxCallBytes = uint64_t(64) << 20;  // a call's results, at most (one larger goes alone)

  struct Options {
    int threads = 1;   // render threads, for thread-seconds
    double since = 0;  // steady seconds the threads started counting (registration)
    bool lie = false;  // verification tests: every sum scaled by 0.8
  };
  // Starts the threads ("send").
  Sender(const Link& link, TaskQueue& queue, Options options);
  // Returns once the queue has stopped and everything finished was sent.
  ~Sender();

 private:
  void send_loop();
  // The batch's request: every result with the worker's thread-seconds until `now`.
  v1::ResultBatch encode(const TaskQueue::Batch& batch, double now) const;
  // Submits `results` (of `batch`'s tasks, in order), with retries; tells the queue.
  void submit(const TaskQueue::Batch& batch, const v1::ResultBatch& results);

  const Link& link_;
  TaskQueue& queue_;
  const Options options_;
  std::vector<std::thread> threads_;  // last: they use the members above
};

}  // namespace tessera::worker
