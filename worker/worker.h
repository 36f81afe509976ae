// The worker loop: register, pull a task, render it with every core, return the sums,
// repeat. Reconnects with back-off when the coordinator goes away; stops cleanly (giving
// its lease back) when asked to.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "core/render/tile_renderer.h"
#include "core/scene/scene.h"
#include "wire.h"

namespace tessera {

struct WorkerOptions {
  std::string coordinator = "127.0.0.1:7878";
  int threads = 0;  // 0: every core
  std::string cache_dir = "tessera-cache";
  std::string name;
  bool verbose = false;
};

class Worker {
 public:
  explicit Worker(WorkerOptions options);
  ~Worker();
  // Works until `stop` becomes true; then abandons any task (releasing its lease) and
  // returns. Network failures are retried forever with back-off.
  void run(const std::atomic<bool>& stop);
  uint64_t tasks_done() const { return tasks_done_; }

 private:
  bool register_worker(const std::atomic<bool>& stop);
  const TileRenderer& renderer_for(const v1::Task& task);
  const Scene& scene_for(const std::string& hash);
  // Renders the task's tile with every thread; returns false if aborted.
  bool render(const v1::Task& task, std::vector<PixelSums>* sums, TileStats* stats, const std::atomic<bool>& abort);
  void sleep_backoff(const std::atomic<bool>& stop);
  std::optional<v1::Task> fetch_task(grpc::Status* status, uint32_t* retry_ms);
  bool submit(const v1::TaskResult& result, const std::atomic<bool>& stop);  // retries
  void release(uint64_t task_id);

  WorkerOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::TesseraWorker::Stub> stub_;
  uint64_t worker_id_ = 0;
  uint32_t heartbeat_ms_ = 2000;
  double backoff_ = 0.1;
  std::map<std::string, std::unique_ptr<Scene>> scenes_;  // by content hash
  std::string renderer_key_;
  std::unique_ptr<TileRenderer> renderer_;
  uint64_t tasks_done_ = 0;
};

}  // namespace tessera
