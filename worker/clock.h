// Time in the worker: steady seconds (speed, idle time, heartbeats), and how often its
// threads look at the stop flag.
#pragma once

#include <chrono>

namespace tessera::worker {

inline double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// How often the lease keeper and the fetcher look at the stop flag (set by a signal): each
// look wakes a thread, which on a small machine takes a core from a render thread.
constexpr std::chrono::milliseconds kStopPoll{100};

}  // namespace tessera::worker
