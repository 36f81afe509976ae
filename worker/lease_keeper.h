// A worker's lease keeper: a thread that sleeps until the next heartbeat, renews every held
// lease in one Heartbeat and drops the tasks the coordinator refuses (cancelled or given to
// another worker). It also watches the stop flag, set by a signal, and then abandons the
// unfinished work at once.
#pragma once

#include <atomic>
#include <thread>

#include "worker/link.h"
#include "worker/task_queue.h"

namespace tessera::worker {

class LeaseKeeper {
 public:
  // Starts the thread ("leases").
  LeaseKeeper(const Link& link, TaskQueue& queue, const std::atomic<bool>& stop);
  // Returns once the queue has stopped.
  ~LeaseKeeper();

 private:
  void keep_leases();
  void heartbeat();

  const Link& link_;
  TaskQueue& queue_;
  const std::atomic<bool>& stop_;
  std::thread thread_;  // last: it uses the members above
};

}  // namespace tessera::worker
