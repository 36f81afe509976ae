#include "core/util/thread_pool.h"

#include <pthread.h>

#include <algorithm>
#include <string>

namespace tessera {

void set_thread_name(const char* name) { pthread_setname_np(pthread_self(), std::string(name).substr(0, 15).c_str()); }

ThreadPool::ThreadPool(int threads, const char* name) {
  if (threads <= 0) threads = int(std::max(1u, std::thread::hardware_concurrency()));
  for (int i = 0; i < threads; ++i)
    threads_.emplace_back([this, name = std::string(name)] {
      set_thread_name(name.c_str());
      std::unique_lock<std::mutex> lock(mu_);
      while (true) {
        work_.wait(lock, [this] { return stopping_ || !jobs_.empty(); });
        if (jobs_.empty()) return;  // stopping, and nothing left
        std::function<void()> job = std::move(jobs_.front());
        jobs_.pop_front();
        ++running_;
        lock.unlock();
        job();
        lock.lock();
        --running_;
        if (jobs_.empty() && running_ == 0) idle_.notify_all();
      }
    });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  work_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void ThreadPool::run(std::function<void()> job) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    jobs_.push_back(std::move(job));
  }
  work_.notify_one();
}

void ThreadPool::wait() {
  std::unique_lock<std::mutex> lock(mu_);
  idle_.wait(lock, [this] { return jobs_.empty() && running_ == 0; });
}

}  // namespace tessera
