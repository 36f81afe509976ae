// Cooperative cancellation of long work on the current thread: a scene check whose client
// has gone away, or any load while the process is stopping. Work polls
// throw_if_cancelled() at its natural steps (a node, a mesh primitive, a texture); the
// caller that can be cancelled holds a CancelScope around it. Without a scope (tessera
// render, a worker) nothing is ever cancelled, and a poll costs one thread-local load.
#pragma once

#include <chrono>
#include <functional>
#include <stdexcept>

namespace tessera {

class Cancelled : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// While it lives, throw_if_cancelled() on this thread throws Cancelled once `cancelled`
// returns true (or stop_all_scoped_work() was called). `cancelled` is asked at most every
// `interval` seconds (asking gRPC whether a call is cancelled takes a lock: asked at every
// node of a 2 M-node graph it made the check 8 times slower). Scopes nest: the inner one
// rules.
class CancelScope {
 public:
  explicit CancelScope(std::function<bool()> cancelled, double interval = 0.01);
  ~CancelScope();
  CancelScope(const CancelScope&) = delete;
  CancelScope& operator=(const CancelScope&) = delete;

 private:
  std::function<bool()> cancelled_;
  std::chrono::steady_clock::duration interval_;
  mutable std::chrono::steady_clock::time_point next_ask_{};
  const CancelScope* outer_;
  friend void throw_if_cancelled();
};

// Throws Cancelled if the thread's scope says so. No scope: returns.
void throw_if_cancelled();

// Every scope, on every thread, cancels from now on (a process told to stop).
void stop_all_scoped_work();

}  // namespace tessera
