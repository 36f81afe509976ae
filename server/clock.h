// Time source: a seam, so that tests drive leases and timeouts with a fake clock.
#pragma once

#include <chrono>

namespace tessera {

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
