// Scenes the coordinator holds loaded at once, at most (--max-scene-loads). Each can take
// gigabytes within the loaders' budgets (four 8192 x 8192 textures in 1.1 MB of upload:
// 5.3 GB for 16 s when textures were floats), so submits in parallel, each within its
// caller's stream slots, could together exhaust the machine's memory and have the
// coordinator killed. A turn covers a load and what holds the scene after it (a submit's
// check of its settings, the referee's render: SceneStore::in_turn). Past the bound a turn
// waits, and turns are had in the order they were asked for (a steady stream of submits
// cannot keep one waiting for good); a submit's wait ends when its client goes away (its
// CancelScope: core/util/cancel.h), as its load would, and leaves the line.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>

#include "core/util/cancel.h"

namespace tessera {

// The default --max-scene-loads on a machine with `memory_bytes`: one load per 16 GiB, 1 to
// 4. Films may take half the memory (live_pixel_default); a load within the loaders'
// budgets can take several GB (textures 1 GiB, meshopt views 4 GiB, morph targets 1 GiB,
// the meshes of 100 M triangles; a glTF load at most 8 GiB together, kMaxGltfLoadBytes),
// so about 8 GiB a load in the other half.
inline size_t scene_load_default(uint64_t memory_bytes) { return std::clamp<size_t>(size_t(memory_bytes >> 34), 1, 4); }

class SceneLoads {
 public:
  explicit SceneLoads(size_t at_once) : at_once_(std::max<size_t>(1, at_once)) {}

  // f(), once fewer than `at_once` turns are running. Throws what f throws, or Cancelled
  // while it waits.
  template <class F>
  auto in_turn(F&& f) const {
    const Turn turn(*this);
    return f();
  }
  size_t running() const {
    std::lock_guard<std::mutex> lock(mu_);
    return running_;
  }
  size_t waiting() const {
    std::lock_guard<std::mutex> lock(mu_);
    return line_.size();
  }

 private:
  class Turn {
   public:
    explicit Turn(const SceneLoads& loads) : loads_(loads) {
      std::unique_lock<std::mutex> lock(loads_.mu_);
      const uint64_t me = loads_.next_ticket_++;
      loads_.line_.push_back(me);
      while (loads_.running_ >= loads_.at_once_ || loads_.line_.front() != me) {
        loads_.turn_.wait_for(lock, std::chrono::milliseconds(50));
        lock.unlock();
        try {
          throw_if_cancelled();  // (not under the lock: it may ask gRPC)
        } catch (...) {
          lock.lock();
          loads_.line_.erase(std::find(loads_.line_.begin(), loads_.line_.end(), me));
          lock.unlock();
          loads_.turn_.notify_all();  // the next in line may be first now
          throw;
        }
        lock.lock();
      }
      loads_.line_.pop_front();
      ++loads_.running_;
      lock.unlock();
      loads_.turn_.notify_all();  // the next in line, where there is room for it too
    }
    ~Turn() {
      {
        std::lock_guard<std::mutex> lock(loads_.mu_);
        --loads_.running_;
      }
      loads_.turn_.notify_all();
    }
    Turn(const Turn&) = delete;
    Turn& operator=(const Turn&) = delete;

   private:
    const SceneLoads& loads_;
  };
  const size_t at_once_;
  mutable std::mutex mu_;
  mutable std::condition_variable turn_;
  mutable size_t running_ = 0;
  mutable uint64_t next_ticket_ = 0;
  mutable std::deque<uint64_t> line_;  // tickets of the turns waiting, in order
};

}  // namespace tessera
