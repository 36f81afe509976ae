// A worker's render threads: persistent, each taking the queue's next row (front task
// first, one row at a time), so every thread stays busy and a task's rows spread over all
// of them. No static split: no thread ends a task early while another still works on it.
#pragma once

#include "core/util/thread_pool.h"
#include "worker/task_queue.h"

namespace tessera::worker {

class RenderPool {
 public:
  // Starts `threads` render threads on `queue`.
  RenderPool(TaskQueue& queue, int threads);
  // Joins them: call queue.stop() first.
  ~RenderPool() = default;

 private:
  void render_loop();

  TaskQueue& queue_;
  ThreadPool pool_;  // last: its threads use queue_
};

}  // namespace tessera::worker
