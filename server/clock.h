// Time source: a seam, so that tests drive leases and timeouts with a fake clock.
#pragma once

#include <chrono>

namespace tessera {

// The wall clock, seconds since 1970: what users are shown (a job's submit, start and end
// times); durations and deadlines use a Clock.
inline double wall_seconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

class Clock {
 public:
  virtual ~Clock() = default;
  virtual double now() const = 0;  // seconds
};

class SteadyClock : public Clock {
 public:
  double now() const override {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }
};

}  // namespace tessera
