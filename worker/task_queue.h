// The leased tasks on their way through a worker, under one mutex: the fetcher queues
// them, the render threads take their rows and hand back sums, the sender takes the
// finished ones, the lease keeper renews and drops them. The queue also measures the
// worker's speed, which sizes the fetcher's requests (lookahead.h).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <vector>

#include "core/math/rect.h"
#include "core/render/film.h"
#include "core/render/tile_renderer.h"
#include "tessera.grpc.pb.h"
#include "worker/lookahead.h"
#include "worker/scene_cache.h"
#include "worker/upload_budget.h"

namespace tessera::worker {

// A leased task: its renderer, its rows handed out and done, its sums so far.
struct Held {
  v1::Task task;
  std::shared_ptr<const PreparedRenderer> prepared;
  Rect rect;
  const uint8_t* mask = nullptr;  // into task.active; null: every pixel
  int next_row = 0, rows_done = 0;
  std::vector<std::pair<uint32_t, uint32_t>> passes;  // its sample ranges (task_passes())
  std::vector<PixelSums> base;                        // a run's sums so far (task_base()); or empty
  std::vector<PixelSums> sums;                        // rect-sized
  std::vector<AovSums> aovs;                          // rect-sized for a job with AOVs; else empty
  // A frame that traces light paths: the task's splats, a record per pass (its rows'
  // entries gathered, normalized by the sender); else empty.
  std::vector<SplatRecord> splats;
  TileStats stats;
  std::atomic<bool> cancel{false};
  double first_row = 0, last_row = 0;  // steady seconds
  double busy = 0;                     // thread-seconds spent on it

  double row_samples(int row) const;  // camera samples in a row (for queue sizing)
};

class TaskQueue {
 public:
  // passes_per_task > 0: every task a run of that many passes where the job allows
  // (--passes-per-task); 0: as the link needs (upload_budget.h).
  explicit TaskQueue(Lookahead lookahead, uint32_t passes_per_task = 0)
      : lookahead_(lookahead), budget_(lookahead.threads, passes_per_task) {}

  // The fetcher's side.
  // Waits up to `timeout` until more work is wanted (lookahead.h); what to ask for then,
  // or nothing (stopping, or enough still queued).
  std::optional<LeaseRequest> wait_for_room(std::chrono::milliseconds timeout);
  // Queues a task's rows, behind those of the same or higher priority (Task.priority: the
  // window may hold several jobs' tasks); the task must have its renderer and rect-sized
  // sums. False (and nothing queued) if a heartbeat found it refused while it was prepared.
  bool add(std::shared_ptr<Held> task);
  // Between GetTask and add(): a task leased and being prepared (its scene fetched and
  // loaded, which can take longer than a lease: it expired, and a failure after that went
  // uncounted) is heartbeaten from the start, and given back at a stop as a held one is.
  void preparing(uint64_t task_id);
  // Its preparation failed or was skipped (it is released): forgotten.
  void not_prepared(uint64_t task_id);
  bool holds_tasks() const;
  // Cancels and forgets every held task (the coordinator no longer knows its leases).
  void drop_all();

  // The render threads' side.
  struct Row {
    std::shared_ptr<Held> task;
    int row = 0;  // within task->rect
  };
  // The next row to render, of the front task; blocks; nothing once stopping.
  std::optional<Row> next_row();
  // A row's sums, rendered from t0 to t1 (steady seconds). After a task's last row, the
  // task measures the speed and goes to the sender (unless it was cancelled).
  void row_done(const Row& row, const std::vector<PixelSums>& sums, const TileStats& stats, double t0, double t1,
                const std::vector<AovSums>* aovs = nullptr, const std::vector<SplatRecord>* splats = nullptr);

  // The sender's side.
  struct Batch {
    std::deque<std::shared_ptr<Held>> tasks;
    double busy_thread_seconds = 0;  // rendering, summed over threads, until now
  };
  // Blocks until a task is finished; then, while rows are still queued, lets results
  // gather for up to `linger`. Every finished task; none once stopping with none left.
  Batch take_finished(std::chrono::milliseconds linger);
  // The batch was submitted (`ok`) or given up (its leases expire; others render them).
  void sent(const Batch& batch, bool ok);
  // A SubmitResults call answered: the upload budget (upload_budget.h) learns the link.
  void note_upload(const UploadBudget::Call& call);
  uint64_t tasks_done() const { return tasks_done_; }

  // The lease keeper's side.
  std::vector<uint64_t> held_ids() const;
  // Cancels and forgets the tasks the coordinator refused (cancelled, reassigned), unless
  // they are finished: those results are sent anyway.
  void drop_unfinished(const std::vector<uint64_t>& refused);
  // Sleeps for up to `timeout`, waking early when stopped; whether stopped.
  bool wait_stopped(std::chrono::milliseconds timeout);

  // Abandons unfinished work at once (renders look at their task's cancel flag per pixel)
  // and wakes every part; finished tasks are still sent.
  void stop();
  bool stopping() const;
  // What is still held once the parts have stopped (unfinished leases); forgets it.
  std::vector<uint64_t> take_held();

  QueueLoad load() const;
  // The coordinator's bound on this worker's leases (at registration), and its own
  // --max-leases if lower (0: none).
  void set_max_leases(size_t coordinator_bound, size_t own_cap);
  // One GetTask's time on the link (its call time less the coordinator's long poll); the
  // window follows its smoothed value.
  void note_round_trip(double seconds);

 private:
  QueueLoad load_locked() const;
  void drop_locked(uint64_t task_id);

  const Lookahead lookahead_;
  mutable std::mutex mu_;  // guards everything below
  std::condition_variable work_, more_, outbox_cv_, stopped_cv_;
  std::map<uint64_t, std::shared_ptr<Held>> held_;  // leased and not yet submitted
  std::set<uint64_t> preparing_, refused_;          // leased, not yet added; refused meanwhile
  std::deque<std::shared_ptr<Held>> queue_;         // with rows not yet handed out
  std::deque<std::shared_ptr<Held>> outbox_;        // finished, to submit
  uint64_t queued_rows_ = 0;
  double queued_samples_ = 0;
  double busy_thread_seconds_ = 0;
  double samples_per_thread_second_ = 0;  // measured, smoothed
  double pass_samples_ = 0;               // camera samples in a task's pass, smoothed
  double round_trip_ = 0;                 // measured, smoothed; 0 until measured
  double min_round_trip_ = 0;             // the shortest measured; 0 until measured
  size_t max_leases_ = kDefaultMaxLeases;
  UploadBudget budget_;
  bool stopping_ = false;
  std::atomic<uint64_t> tasks_done_{0};
};

}  // namespace tessera::worker
