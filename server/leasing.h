// Leases and their bookkeeping on every side: the tile notes its live lease, the worker how
// many it holds, a check which lease renders it. Every lease is granted and ended here, so
// those counts cannot drift apart. Runs under the coordinator's lock.
#pragma once

#include <cstdint>

#include "server/check_book.h"
#include "server/counters.h"
#include "server/job_table.h"
#include "server/lease_table.h"
#include "server/worker_registry.h"

namespace tessera {

class Leasing {
 public:
  Leasing(LeaseTable& leases, JobTable& jobs, WorkerRegistry& workers, CheckBook& checks, CoordinatorCounters& counters,
          double lease_seconds)
      : leases_(leases),
        jobs_(jobs),
        workers_(workers),
        checks_(checks),
        counters_(counters),
        lease_seconds_(lease_seconds) {}

  // A task of the job's tile for the worker, until now + the lease period.
  uint64_t grant(Job& job, const TileTask& task, WorkerInfo& worker, double now);
  // A second lease of a tile already leased (its task from FramePlan::retake), for
  // another worker at the frame's end.
  uint64_t grant_backup(Job& job, const TileTask& task, WorkerInfo& worker, double now);
  // Ends every live lease of the tile (its result was merged, or the tile starts over).
  void end_tile(Job& job, uint32_t tile, double now);
  // The check's task for the worker (not the one whose result it checks).
  uint64_t grant_check(uint64_t check, WorkerInfo& worker, double now);
  // Extends a live lease of this worker; false if it is not live or not the worker's.
  bool renew(uint64_t id, uint64_t worker, double now) { return leases_.renew(id, worker, now + lease_seconds_); }
  // Ends a live lease, kept known so a late result is recognised. With `requeue` its tile
  // is ready again (its result never came); a check's waits for another worker.
  void end(uint64_t id, bool requeue, double now);
  // Ends every lease past its deadline, requeued; returns how many.
  size_t expire(double now);
  // Ends every lease the worker holds, requeued; returns how many.
  size_t end_worker(uint64_t worker, double now);
  // The job has ended: its tiles' leases end (not requeued) and all its leases are forgotten.
  void end_job(Job& job, double now);

 private:
  // A task's lease for the worker, from now (its tile's resets recorded).
  Lease lease_of(const Job& job, const TileTask& task, const WorkerInfo& worker, double now) const;
  void ended(uint64_t id, const Lease& lease, bool requeue, double now);

  LeaseTable& leases_;
  JobTable& jobs_;
  WorkerRegistry& workers_;
  CheckBook& checks_;
  CoordinatorCounters& counters_;
  double lease_seconds_;
};

}  // namespace tessera
