// Workers coming and going: registration (bounded per token; an enrolled worker's replaces
// its last, and starts on probation), heartbeats
// (renewing leases, refusing tasks no longer theirs), a task given back (with the error
// when the worker could not render it), and unregistering. Runs under the coordinator's lock.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "server/job_lifecycle.h"
#include "server/options.h"

namespace tessera {

class WorkerLifecycle {
 public:
  struct Parts {
    WorkerRegistry& workers;
    JobTable& jobs;
    LeaseTable& leases;
    Leasing& leasing;
    CheckBook& checks;
    JobLifecycle& lifecycle;
    CoordinatorCounters& counters;
  };
  WorkerLifecycle(Parts parts, const CoordinatorOptions& options) : p_(parts), options_(options) {}

  // `principal`: the worker's access token name, or with `enrolled` its own credential's
  // (one registration each: registering again ends the last, its leases back). Throws
  // RequestError.
  v1::RegisterResponse register_worker(const v1::RegisterRequest& request, const std::string& principal, bool enrolled,
                                       double now, Effects& fx);
  // Throws RequestError unless `secret` is the one worker `worker`'s registration was
  // given: kFailedPrecondition for an unknown worker (it registers again),
  // kPermissionDenied for a request under another worker's id.
  void check_worker(uint64_t worker, const std::string& secret) const;
  // Renews the worker's leases; returns the tasks it must not go on with.
  std::vector<uint64_t> heartbeat(uint64_t worker, const std::vector<uint64_t>& tasks, double round_trip, double now);
  // The worker gives a lease back; with an error, it could not render the task.
  void release(uint64_t worker, uint64_t task, const std::string& error, double now, Effects& fx);
  // The worker stops: its leases go back to their jobs and it is forgotten.
  void unregister(uint64_t worker, double now, Effects& fx);
  // Ends every lease held past --max-task-seconds, each a task failed on its worker.
  // Returns how many.
  size_t end_overrun(double now, Effects& fx);
  // Forgets workers silent for longer than the timeout (they register again if they return).
  void forget_silent(double now, Effects& fx);

 private:
  Parts p_;
  const CoordinatorOptions& options_;
};

}  // namespace tessera
