// A worker's fetcher: leases tasks while the queued work is below the lookahead
// (lookahead.h), fetches and loads each task's scene and builds its renderer (SceneCache)
// before queuing it, so that no render thread waits for the network.
#pragma once

#include <atomic>
#include <stdexcept>
#include <string>

#include "rpc.h"
#include "worker/link.h"
#include "worker/scene_cache.h"
#include "worker/task_queue.h"

namespace tessera::worker {

class Fetcher {
 public:
  // Scenes are cached under `cache_dir`, within `bound`; `backoff` is the worker's (reset by
  // a call that gets through, waited on after a task that cannot be rendered).
  Fetcher(const Link& link, TaskQueue& queue, const std::string& cache_dir, Backoff& backoff,
          SceneCache::Bounds bound = {});

  struct Leased {
    grpc::Status status;  // of GetTask; OK when nothing was asked for
    int tasks = 0;        // given by the coordinator
  };
  // Waits up to kStopPoll until the queue wants more work, then asks for it (the call
  // long-polls when there is none) and queues each task. A task this worker cannot render
  // (its scene will not load here) is given back with the error, after a back-off.
  Leased lease(const std::atomic<bool>& stop);
  // Thrown from a download at a stop.
  struct Stopped : std::runtime_error {
    Stopped() : std::runtime_error("the worker is stopping") {}
  };

 private:
  void enqueue(const v1::Task& task, const std::atomic<bool>& stop);
  // One FetchSceneChunks call (SceneCache::FetchChunks).
  grpc::Status fetch_scene(const v1::FetchSceneRequest& req, const SceneCache::Piece& piece) const;

  const Link& link_;
  TaskQueue& queue_;
  Backoff& backoff_;
  SceneCache scenes_;
  // The worker's stop, while lease() runs: a scene's download ends at a stop (SIGTERM waited
  // for a download of minutes), its task given back with the held ones, without an error.
  const std::atomic<bool>* stop_ = nullptr;
};

}  // namespace tessera::worker
