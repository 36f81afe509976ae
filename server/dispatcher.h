// Which tasks a worker gets (GetTask). Live jobs, frames of sequences among them, and
// sequences with frames still to start, by priority, then submission, then frame: a
// sequence's next frame comes after its started ones and before later jobs, so its first
// frames finish first and workers go from one frame to the next without waiting. Checks
// come first (they are few, and a job waits for them). A worker gets at most its share,
// by threads, of the work outstanding, less what it holds: on a small frame the first to
// ask cannot take every ready task while the others idle; and never more than the bound on
// one worker's leases (which the worker learns when it registers). Runs under the
// coordinator's lock.
//
// At a frame's end, when nothing is ready anywhere, a worker that would idle is given the
// oldest tiles others hold (for at least kBackupAfterSeconds) a second time: whichever
// result comes first is merged, with the same bits, and both leases end; so a far or slow
// worker never holds a frame's last tiles hostage.
#pragma once

#include <cstdint>

#include "server/sequence_scheduler.h"
#include "server/verifier.h"

namespace tessera {

class Dispatcher {
 public:
  static constexpr uint32_t kMaxTasksPerRequest = 256;
  static constexpr uint32_t kMaxPassesPerTask = 64;  // a run of passes in one task, at most
  // A frame's end: a worker that would get nothing renders again tiles that others have
  // held for at least this long (a far worker's window, a slow machine), the oldest first.
  static constexpr double kBackupAfterSeconds = 0.25;
  static constexpr size_t kBackupScan = 4096;  // live leases looked at per request, at most

  struct Parts {
    JobTable& jobs;
    LeaseTable& leases;
    Leasing& leasing;
    WorkerRegistry& workers;
    CheckBook& checks;
    Verifier& verifier;
    SequenceScheduler& sequences;
    JobLifecycle& lifecycle;
  };
  Dispatcher(Parts parts, int64_t max_live_pixels, uint32_t max_leases_per_worker)
      : p_(parts), max_live_pixels_(max_live_pixels), max_leases_(max_leases_per_worker) {}

  // Up to max_tasks tasks, stopping once they hold max_samples samples (0: no such limit);
  // always one if any is ready and the worker's share allows. Expires overdue leases
  // first. Throws RequestError for a quarantined or unknown worker.
  v1::GetTaskResponse get_task(uint64_t worker, uint32_t max_tasks, uint64_t max_samples, double now, Effects& fx,
                               uint32_t max_passes = 1);

 private:
  // The task of `t` for the worker, leased as `task_id`, into `resp`; its samples.
  uint64_t add_task(Job& job, const TileTask& t, uint64_t task_id, v1::GetTaskResponse& resp) const;
  // Backups (kBackupAfterSeconds) into `resp`, within the request's count and sample
  // limits as get_task's own tasks.
  void back_up(WorkerInfo& w, uint32_t max_tasks, uint64_t max_samples, double now, v1::GetTaskResponse& resp);
  // The task just added to `resp` (leased as `task_id`) is to be checked if the worker is on
  // probation or the verify fraction picks it (Verifier::pick).
  void mark_for_check(WorkerInfo& w, uint64_t task_id, const v1::GetTaskResponse& resp);

  Parts p_;
  int64_t max_live_pixels_;
  uint32_t max_leases_;  // per worker (CoordinatorOptions::max_leases_per_worker)
};

}  // namespace tessera
