#include "server/worker_lifecycle.h"

#include <cstdio>

#include "core/util/text.h"
#include "server/request_error.h"

namespace tessera {

v1::RegisterResponse WorkerLifecycle::register_worker(const v1::RegisterRequest& req, const std::string& principal,
                                                      bool enrolled, double now, Effects& fx) {
  if (req.version() != kProtocolVersion)
    throw RequestError(RequestError::Code::kInvalidArgument,
                       "protocol version " + std::to_string(req.version()) + " not supported");
  if (enrolled)  // one credential, one worker: a restarted one replaces its last registration
    for (const WorkerInfo& old : p_.workers.list(now))
      if (old.enrolled && old.principal == principal) unregister(old.id, now, fx);
  if (p_.workers.size() >= options_.max_workers) forget_silent(now, fx);
  if (p_.workers.size() >= options_.max_workers)
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "the coordinator has its " + std::to_string(options_.max_workers) + " workers (--max-workers)");
  if (!principal.empty() && p_.workers.count_principal(principal) >= options_.max_workers_per_token) {
    forget_silent(now, fx);
    if (p_.workers.count_principal(principal) >= options_.max_workers_per_token)
      throw RequestError(RequestError::Code::kResourceExhausted, "worker token '" + principal + "' has its " +
                                                                     std::to_string(options_.max_workers_per_token) +
                                                                     " registered workers (--max-workers-per-token)");
  }
  std::string secret;
  WorkerInfo& w = p_.workers.add(req.name(), req.threads(), now, &secret);
  w.host = peer_text(req.host(), WorkerRegistry::kMaxTextBytes);
  w.principal = principal;
  w.enrolled = enrolled;
  w.probation = options_.verify_fraction > 0 ? options_.verify_first : 0;
  fx.events.push_back({0, 0, "worker.registered", "", w.name, principal,
                       "threads " + std::to_string(w.threads) + (enrolled ? ", its own credential" : "")});
  v1::RegisterResponse r;
  r.set_worker_id(w.id);
  r.set_worker_secret(secret);
  r.set_heartbeat_interval_ms(uint32_t(options_.heartbeat_seconds * 1000));
  r.set_lease_ms(uint32_t(options_.lease_seconds * 1000));
  r.set_max_leases(options_.max_leases_per_worker);
  return r;
}

void WorkerLifecycle::check_worker(uint64_t worker, const std::string& secret) const {
  const WorkerInfo* w = p_.workers.find(worker);
  if (!w)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "unknown worker " + std::to_string(worker) + "; register again");
  if (!p_.workers.secret_matches(*w, secret))
    throw RequestError(RequestError::Code::kPermissionDenied,
                       "worker " + std::to_string(worker) +
                           ": the request does not carry that worker's secret (only the process that registered it may "
                           "act for it)");
}

std::vector<uint64_t> WorkerLifecycle::heartbeat(uint64_t worker, const std::vector<uint64_t>& tasks, double round_trip,
                                                 double now) {
  if (WorkerInfo* w = p_.workers.find(worker)) {
    w->last_seen = now;
    if (round_trip > 0) w->round_trip = round_trip;
  }
  std::vector<uint64_t> refused;
  for (uint64_t id : tasks)
    if (!p_.leasing.renew(id, worker, now)) refused.push_back(id);
  return refused;
}

void WorkerLifecycle::release(uint64_t worker, uint64_t task, const std::string& error, double now, Effects& fx) {
  const Lease* l = p_.leases.live(task);
  if (!l || l->worker != worker) return;
  const std::string job_id = l->job;
  const bool refused = l->refused;  // its failure already counted (ResultIntake::refuse)
  p_.leasing.end(task, true, now);
  ++p_.counters.leases_released;
  fx.changed = true;
  if (error.empty() || refused) return;
  Job* job = p_.jobs.find_job(job_id);
  if (!job) return;
  const WorkerInfo* w = p_.workers.find(worker);
  if (!w) return;  // (a caller is registered; end_overrun may end a forgotten worker's lease)
  p_.lifecycle.task_failed(*job, *w, error, now, fx);
}

void WorkerLifecycle::unregister(uint64_t worker, double now, Effects& fx) {
  const size_t held = p_.leasing.end_worker(worker, now);
  p_.counters.leases_released += held;
  if (const WorkerInfo* w = p_.workers.find(worker))
    fx.events.push_back(
        {0, 0, "worker.unregistered", "", w->name, w->principal,
         std::to_string(w->tasks_done) + " tasks done, " + std::to_string(held) + " leases given back"});
  p_.workers.remove(worker);
  fx.changed = true;
}

size_t WorkerLifecycle::end_overrun(double now, Effects& fx) {
  if (!(options_.max_task_seconds > 0)) return 0;
  char bound[32];
  std::snprintf(bound, sizeof bound, "%g", options_.max_task_seconds);
  size_t ended = 0;
  for (const uint64_t id : p_.leases.granted_before(now - options_.max_task_seconds)) {
    // Gone already where an earlier one's failure failed its job (every lease of the job
    // ends with it; a sequence's other frames are cancelled).
    const Lease* l = p_.leases.live(id);
    if (!l) continue;
    const uint64_t worker = l->worker;
    const std::string why =
        "a task (tile " + std::to_string(l->tile) + ", pass " + std::to_string(l->pass) +
        ") ran past the coordinator's bound on a task's time, from its lease to its result: " + bound +
        " s (--max-task-seconds)";
    release(worker, id, why, now, fx);
    ++ended;
  }
  return ended;
}

void WorkerLifecycle::forget_silent(double now, Effects& fx) {
  for (const WorkerInfo& w : p_.workers.forget_silent(now, options_.worker_timeout_seconds)) {
    fx.events.push_back({0, 0, "worker.lost", "", w.name, w.principal,
                         "silent for " + std::to_string(int64_t(now - w.last_seen)) + " s"});
    fx.changed = true;
  }
}

}  // namespace tessera
