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

class Sender {
 public:
  static constexpr int kLingerMs = 50;  // how long finished results may wait for company
  static constexpr int kAttempts = 5;   // then the batch is dropped: its leases expire
  static constexpr int kInFlight = 4;   // SubmitResults calls at once, at most

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

  const Link& link_;
  TaskQueue& queue_;
  const Options options_;
  std::vector<std::thread> threads_;  // last: they use the members above
};

}  // namespace tessera::worker
