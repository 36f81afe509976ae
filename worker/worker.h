// The worker: register, keep a few tasks leased, render them with every core, return the
// sums, repeat. Reconnects with back-off when the coordinator goes away; stops cleanly
// (giving its leases back) when asked to.
//
// The pipeline, so that no render thread ever waits for the network:
//   fetcher (the thread that calls run())  leases tasks while the queued work is below
//       about `lookahead_seconds` of this worker's measured speed (and at least two rows
//       per thread); loads each task's scene and builds its renderer before queuing it.
//   render pool (`threads` persistent threads)  take rows of the queued tasks, front task
//       first, one row at a time: no static split, no thread ends a task early while
//       another still works on it.
//   sender  encodes finished tasks (zstd) and submits them, with retries.
//   lease keeper  renews every held lease each heartbeat interval; a lease the
//       coordinator refuses (job cancelled, task reassigned) is dropped at once.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "access.h"
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
  double lookahead_seconds = 0.3;  // queued work to keep, at the measured speed
  int max_tasks = 64;              // leases held at once, at most
  Access access;                   // token and TLS
  // For the verification tests only (a hidden flag): every result's sums scaled by 0.8
  // (plausible, and wrong), as a broken or dishonest machine would send them.
  bool lie = false;
  // Leave (cleanly, as on SIGTERM) after this long without a task; 0: never. For batch
  // allocations (Slurm) that should end when the queue is empty.
  double exit_when_idle_seconds = 0;
};

class Worker {
 public:
  explicit Worker(WorkerOptions options);
  ~Worker();
  // Works until `stop` becomes true; then abandons unfinished tasks (releasing their
  // leases), sends the finished ones, and returns. Network failures are retried forever.
  // Returns false if the coordinator refused this worker (a bad token, another protocol).
  bool run(const std::atomic<bool>& stop);
  uint64_t tasks_done() const { return tasks_done_; }

 private:
  struct Prepared;  // a scene and a renderer for one (scene, settings)
  struct Held;      // a leased task on its way through the pipeline

  // Registers, retrying with back-off; false if stopped, refused, or idle past
  // --exit-when-idle while the coordinator cannot be reached.
  bool register_worker(const std::atomic<bool>& stop);
  std::shared_ptr<const Prepared> prepare(const v1::Task& task);
  std::shared_ptr<Scene> scene_for(const std::string& hash);  // loaded once per content hash
  bool wants_more_locked() const;
  // Prepares a leased task and queues it for the render threads (or gives it back).
  void enqueue(const v1::Task& task, const std::atomic<bool>& stop);
  void render_loop();
  void send_loop();
  void keep_leases(const std::atomic<bool>& stop);
  void drop_locked(uint64_t task_id);                             // cancels a held task and forgets it
  void release(uint64_t task_id, const std::string& error = "");  // error: could not render it
  void sleep_backoff(const std::atomic<bool>& stop);

  WorkerOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::TesseraWorker::Stub> stub_;
  std::atomic<uint64_t> worker_id_{0};
  uint32_t heartbeat_ms_ = 2000;
  double backoff_ = 0.1;
  double registered_at_ = 0;
  double last_work_ = 0;  // when it last held or was given a task (--exit-when-idle)
  // Fetcher only.
  std::map<std::string, std::shared_ptr<Scene>> scenes_;  // by content hash
  std::map<std::string, std::shared_ptr<const Prepared>> prepared_;
  std::deque<std::string> prepared_order_;

  std::mutex mu_;  // guards everything below
  std::condition_variable work_, more_, outbox_cv_, stopped_cv_;
  std::map<uint64_t, std::shared_ptr<Held>> held_;  // leased and not yet submitted
  std::deque<std::shared_ptr<Held>> queue_;         // with rows not yet handed out
  std::deque<std::shared_ptr<Held>> outbox_;        // finished, to submit
  uint64_t queued_rows_ = 0;
  double queued_samples_ = 0;
  double busy_thread_seconds_ = 0;
  double samples_per_thread_second_ = 0;  // measured, smoothed
  bool stopping_ = false;
  bool refused_ = false;  // registration refused: retrying cannot help
  std::atomic<uint64_t> tasks_done_{0};
};

}  // namespace tessera
