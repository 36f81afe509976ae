// The worker: register, keep a few tasks leased, render them with every core, return the
// sums, repeat. Reconnects with back-off when the coordinator goes away; stops cleanly
// (giving its leases back) when asked to.
//
// The pipeline, so that no render thread ever waits for the network; its parts meet in one
// TaskQueue (worker/task_queue.h) and reach the coordinator through one Link (link.h):
//   fetcher (the thread that calls run(); fetcher.h)  leases tasks while the queued work is
//       below about `lookahead_seconds` plus two round trips of this worker's measured
//       speed (its window of work in flight, lookahead.h);
//       loads each task's scene and builds its renderer (scene_cache.h) before queuing it.
//   render pool (`threads` persistent threads; render_pool.h)  take rows of the queued
//       tasks, front task first, one row at a time.
//   sender (sender.h)  encodes finished tasks (zstd) and submits them, with retries, up
//       to four calls at once (a far link's round trip does not hold results back).
//   lease keeper (lease_keeper.h)  renews every held lease each heartbeat interval; a
//       lease the coordinator refuses (job cancelled, task reassigned) is dropped at once.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "access.h"
#include "rpc.h"
#include "tessera.grpc.pb.h"

namespace tessera {

namespace worker {
struct Link;
class TaskQueue;
class Fetcher;
}  // namespace worker

struct WorkerOptions {
  std::string coordinator = "127.0.0.1:7878";
  int threads = 0;  // 0: every core
  std::string cache_dir = "tessera-cache";
  // The scene cache's bound on disk, in GiB (0: none): least recently used scenes go first
  // (SceneCacheBounds). A farm running for months kept every scene it had ever fetched.
  double cache_max_gib = 20;
  // Kept renderers (and their scenes) are dropped, oldest first, while the process's
  // resident memory is above this many GiB (0: no bound; tessera-worker sets half the
  // machine's memory unless given).
  double max_memory_gib = 0;
  std::string name;
  bool verbose = false;            // log connection events (main.cc: the log level)
  double lookahead_seconds = 0.3;  // queued work to keep, at the measured speed
  // Leases held at once, at most; 0: as many as the window asks for, up to the
  // coordinator's bound on one worker (RegisterResponse.max_leases).
  int max_tasks = 0;
  // Passes of a tile a task holds where the job allows runs (no -a, no noise target); 0:
  // as the link needs: a task's render covering a far link's round trip (lookahead.h),
  // more once results outrun the link (worker/upload_budget.h).
  int passes_per_task = 0;
  Access access;  // token and TLS
  // An enrolment token (role enrol): the worker enrols under `name` for a credential of its
  // own, and again whenever the coordinator no longer knows that credential. Empty: it
  // works with access.token.
  std::string enrol_token;
  // For the verification tests only (a hidden flag): every result's sums scaled by 0.8
  // (plausible, and wrong), as a broken or dishonest machine would send them.
  bool lie = false;
  // Leave (cleanly, as on SIGTERM) after this long without a task; 0: never. For batch
  // allocations (Slurm) that should end when the queue is empty.
  double exit_when_idle_seconds = 0;
};

class Worker {
 public:
  // Connects to options.coordinator (with the token and TLS of options.access).
  explicit Worker(WorkerOptions options);
  // Talks to the coordinator through `stub` instead: tests drive a worker with a fake
  // coordinator in the process.
  Worker(WorkerOptions options, std::shared_ptr<v1::TesseraWorker::StubInterface> stub);
  ~Worker();
  // Works until `stop` becomes true; then abandons unfinished tasks (releasing their
  // leases), sends the finished ones, and returns. Network failures are retried forever.
  // Returns false if the coordinator refused this worker (a bad token, another protocol).
  bool run(const std::atomic<bool>& stop);
  uint64_t tasks_done() const;

 private:
  // Registers, retrying with back-off; false if stopped, refused, or idle past
  // --exit-when-idle-seconds while the coordinator cannot be reached.
  bool register_worker(const std::atomic<bool>& stop);
  // Enrols (options_.enrol_token) for a credential of this worker's own: the status of the call.
  grpc::Status enrol();
  // Leases and queues work until `stop`, --exit-when-idle-seconds, or a refused registration;
  // registers again when the coordinator has forgotten this worker.
  void fetch(const std::atomic<bool>& stop);

  WorkerOptions options_;
  std::unique_ptr<worker::Link> link_;
  Backoff backoff_{Backoff::kWorkerFirstSeconds};
  std::unique_ptr<worker::TaskQueue> queue_;
  std::unique_ptr<worker::Fetcher> fetcher_;  // its scenes and renderers are kept across reconnections
  double last_contact_ = 0;                   // its last registration or GetTask that got through
  double last_work_ = 0;                      // when it last held or was given a task (--exit-when-idle-seconds)
  bool refused_ = false;                      // registration refused: retrying cannot help
  bool tls_hinted_ = false;                   // the TLS hint (tls_hint) was logged
  // Registering again after a GetTask the coordinator refused: backed off across attempts
  // until a GetTask gets through (registering resets backoff_; a refusal every time made a
  // register-refuse loop at 10 a second).
  Backoff rejoin_{Backoff::kWorkerFirstSeconds};
  double unreachable_since_ = 0, unreachable_said_ = 0;  // steady seconds; 0: reached
  bool enrolled_ = false;                                // holds a credential of its own (enrol_token)
};

}  // namespace tessera
