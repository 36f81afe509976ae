// A mutex the compiler checks. Data is declared TESSERA_GUARDED_BY the mutex that protects
// it and functions that need the mutex held TESSERA_REQUIRES it; clang's -Wthread-safety
// then proves every access happens with the lock held, and a violation fails the clang
// build (deploy/fuzz.sh builds the server with clang, -Werror=thread-safety). The same
// idea as Envoy's Thread::MutexBasicLockable and abseil's annotations; other compilers
// see plain std::mutex.
#pragma once

#include <chrono>
#include <condition_variable>
#include <mutex>

#if defined(__clang__)
#define TESSERA_TSA(x) __attribute__((x))
#else
#define TESSERA_TSA(x)
#endif
#define TESSERA_CAPABILITY(x) TESSERA_TSA(capability(x))
#define TESSERA_SCOPED_CAPABILITY TESSERA_TSA(scoped_lockable)
#define TESSERA_GUARDED_BY(x) TESSERA_TSA(guarded_by(x))
#define TESSERA_PT_GUARDED_BY(x) TESSERA_TSA(pt_guarded_by(x))
#define TESSERA_ACQUIRED_BEFORE(...) TESSERA_TSA(acquired_before(__VA_ARGS__))
#define TESSERA_REQUIRES(...) TESSERA_TSA(requires_capability(__VA_ARGS__))
#define TESSERA_EXCLUDES(...) TESSERA_TSA(locks_excluded(__VA_ARGS__))
#define TESSERA_ACQUIRE(...) TESSERA_TSA(acquire_capability(__VA_ARGS__))
#define TESSERA_RELEASE(...) TESSERA_TSA(release_capability(__VA_ARGS__))

namespace tessera {

class TESSERA_CAPABILITY("mutex") Mutex {
 public:
  void lock() TESSERA_ACQUIRE() { m_.lock(); }
  void unlock() TESSERA_RELEASE() { m_.unlock(); }

 private:
  friend class CondVar;
  std::mutex m_;
};

// Holds a Mutex for its scope.
class TESSERA_SCOPED_CAPABILITY MutexLock {
 public:
  explicit MutexLock(Mutex& m) TESSERA_ACQUIRE(m) : m_(m) { m_.lock(); }
  ~MutexLock() TESSERA_RELEASE() { m_.unlock(); }
  MutexLock(const MutexLock&) = delete;
  MutexLock& operator=(const MutexLock&) = delete;

 private:
  Mutex& m_;
};

// A condition variable over a Mutex. A wait releases the mutex and takes it again before it
// returns, so to the analysis the caller holds it throughout; the caller loops on its
// condition (wakeups may be spurious), evaluated where the analysis sees the lock held.
class CondVar {
 public:
  // False once `deadline` has passed.
  bool wait_until(Mutex& m, std::chrono::steady_clock::time_point deadline) TESSERA_REQUIRES(m) {
    std::unique_lock<std::mutex> lock(m.m_, std::adopt_lock);
    const bool in_time = cv_.wait_until(lock, deadline) == std::cv_status::no_timeout;
    lock.release();  // still held: the caller's scope unlocks it
    return in_time;
  }
  void notify_all() { cv_.notify_all(); }

 private:
  std::condition_variable cv_;
};

inline std::chrono::steady_clock::time_point deadline_in(double seconds) {
  return std::chrono::steady_clock::now() +
         std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
}

}  // namespace tessera
