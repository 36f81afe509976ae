// A fixed set of threads that run queued jobs: the render threads of `tessera render` and
// of a worker. Threads are made once, not per pass or per task.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tessera {

class ThreadPool {
 public:
  // threads <= 0: one per core. `name` names the threads (15 characters at most, as in
  // top -H and /proc/<pid>/task/*/comm).
  explicit ThreadPool(int threads, const char* name = "render");
  // Finishes every queued job, then joins.
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  void run(std::function<void()> job);
  // Blocks until every job queued so far has finished.
  void wait();
  int size() const { return int(threads_.size()); }

 private:
  std::mutex mu_;
  std::condition_variable work_, idle_;
  std::deque<std::function<void()>> jobs_;
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

// Names the calling thread (truncated to 15 characters).
void set_thread_name(const char* name);

}  // namespace tessera
