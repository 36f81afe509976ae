// The one writer of job and sequence states: QUEUED -> RUNNING at the first lease, then
// DONE, CANCELLED or FAILED. An end releases what the job held (leases, undecided checks)
// and reports a frame's end to its sequence; the slow part (its last image and checkpoint,
// the database row) goes into the Effects. Runs under the coordinator's lock.
#pragma once

#include <optional>
#include <string>

#include "server/effects.h"
#include "server/job_table.h"
#include "server/leasing.h"

namespace tessera {

class JobLifecycle {
 public:
  // Tasks of a job failed on this many different workers: the job fails.
  static constexpr size_t kFailuresToFail = 2;
  // A worker whose task of a job failed is not given the job's tasks for this long, twice as
  // long after each further failure, up to kMaxRestSeconds: it failed them over and over (it
  // waits a second or so after each), the job never failing where it was the only worker.
  static constexpr double kFirstRestSeconds = 30, kMaxRestSeconds = 3600;

  JobLifecycle(JobTable& jobs, Leasing& leasing, const Snapshotter& snapshots, CoordinatorCounters& counters)
      : jobs_(jobs), leasing_(leasing), snapshots_(snapshots), counters_(counters) {}

  // A job or sequence read back after a restart comes back in the state it was in.
  static void restore(Job& job, Job::State state) { job.state_ = state; }
  static void restore(Sequence& s, Sequence::State state) { s.state_ = state; }
  // A requeued job or sequence (JobControl) is live again: RUNNING once it has rendered.
  void requeue(Job& job, bool rendered) {
    job.state_ = rendered ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED;
    job.ended_at = 0;
  }
  void requeue(Sequence& s, bool rendered) {
    s.state_ = rendered ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED;
    s.ended_at = 0;
  }
  void start(Job& job, double now, Effects& fx);     // its first lease
  void start(Sequence& s, double now, Effects& fx);  // its first frame

  // Ends a live job: its leases and checks end; a frame's end goes to its sequence. The
  // caller asks for its last image and checkpoint (Snapshotter::final_snapshot).
  void end(Job& job, Job::State state, double now, Effects& fx);
  // Ends a live sequence; its live frames end CANCELLED, keeping what they rendered.
  void end(Sequence& s, Sequence::State state, double now, Effects& fx);
  // A live job whose plan is done and whose checks are all decided ends DONE, its final
  // image and checkpoint asked for. True if it ended.
  bool finish_if_done(Job& job, double now, Effects& fx);
  // Cancels a job or a sequence (finished frames stay as they are); only its owner may
  // unless `any`. Throws RequestError. Nothing happens to a job that has ended.
  void cancel(const std::string& id, const std::string& requester, bool any, double now, Effects& fx);
  // A worker (WorkerInfo::identity: an enrolled worker registering again is the same one)
  // could not render a task of the job: once tasks failed on kFailuresToFail different
  // workers, the job fails with the error, keeping its image; until then the worker rests
  // from the job's tasks (Job::resting).
  void task_failed(Job& job, const std::string& worker, const std::string& error, double now, Effects& fx);
  // The same for worker `w`, reported as a task.failed event naming it and the error.
  void task_failed(Job& job, const WorkerInfo& w, const std::string& error, double now, Effects& fx);

  // A sequence's end can be recorded when it has ended and, if DONE, every frame's final
  // checkpoint is on disk: then it is marked as being recorded and returned.
  std::optional<RowEnd> sequence_end_due(const std::string& id);
  void sequence_end_recorded(const std::string& id, bool ok);

 private:
  void frame_ended(Job& job, double now, Effects& fx);

  JobTable& jobs_;
  Leasing& leasing_;
  const Snapshotter& snapshots_;
  CoordinatorCounters& counters_;
};

}  // namespace tessera
