#include "server/leasing.h"

#include "core/util/invariant.h"

namespace tessera {
namespace {
// What the worker was given last (the live page shows it).
void note_given(WorkerInfo& worker, const Job& job, const TileTask& task, bool backup) {
  worker.last_job = job.id();
  worker.last_tile = task.tile;
  worker.last_pass = task.pass;
  worker.last_backup = backup;
}
}  // namespace

Lease Leasing::lease_of(const Job& job, const TileTask& task, const WorkerInfo& worker, double now) const {
  Lease l{job.id(), task.tile, task.pass, worker.id, now + lease_seconds_, nullptr, 0, now, task.pass_count};
  l.tile_resets = job.tile_resets[task.tile];
  return l;
}

uint64_t Leasing::grant(Job& job, const TileTask& task, WorkerInfo& worker, double now) {
  const uint64_t id = leases_.grant(lease_of(job, task, worker, now));
  job.tile_lease[task.tile] = id;
  note_given(worker, job, task, false);
  ++worker.leases;
  ++counters_.tasks_dispatched;
  return id;
}

uint64_t Leasing::grant_backup(Job& job, const TileTask& task, WorkerInfo& worker, double now) {
  TESSERA_INVARIANT(job.tile_lease[task.tile] != 0 && !job.tile_backup.count(task.tile),
                    "a backup of tile " + std::to_string(task.tile) + " that is not leased once");
  const uint64_t id = leases_.grant(lease_of(job, task, worker, now));
  job.tile_backup[task.tile] = id;
  note_given(worker, job, task, true);
  ++worker.leases;
  ++counters_.tasks_dispatched;
  ++counters_.backup_leases;
  return id;
}

void Leasing::end_tile(Job& job, uint32_t tile, double now) {
  if (auto b = job.tile_backup.find(tile); b != job.tile_backup.end()) end(b->second, false, now);
  if (job.tile_lease[tile]) end(job.tile_lease[tile], false, now);
}

uint64_t Leasing::grant_check(uint64_t check, WorkerInfo& worker, double now) {
  Check* c = checks_.find(check);
  TESSERA_INVARIANT(c && c->lease == 0, "check " + std::to_string(check) + " is not waiting for a worker");
  Lease l{c->job, c->tile, c->pass, worker.id, now + lease_seconds_, nullptr};
  l.check = check;
  l.granted = now;
  c->lease = leases_.grant(std::move(l));
  ++worker.leases;
  ++counters_.tasks_dispatched;
  return c->lease;
}

void Leasing::ended(uint64_t id, const Lease& l, bool requeue, double now) {
  if (l.check) {  // a check waits for another worker
    if (Check* c = checks_.find(l.check); c && c->lease == id) {
      c->lease = 0;
      c->since = now;
    }
  } else if (Job* job = jobs_.find_job(l.job); job && l.tile < job->tile_lease.size()) {  // (an ended job has none)
    const auto backup = job->tile_backup.find(l.tile);
    if (backup != job->tile_backup.end() && backup->second == id) {
      job->tile_backup.erase(backup);  // the first lease goes on
    } else if (job->tile_lease[l.tile] == id) {
      if (backup != job->tile_backup.end()) {  // the backup goes on alone
        job->tile_lease[l.tile] = backup->second;
        job->tile_backup.erase(backup);
      } else {
        job->tile_lease[l.tile] = 0;
        if (requeue) job->plan.put_back(l.tile);
      }
    }
  }
  if (WorkerInfo* w = workers_.find(l.worker)) {
    if (w->leases > 0) --w->leases;
    if (l.probation) ++w->probation;  // its result was not merged: the next task is checked instead
  }
}

void Leasing::end(uint64_t id, bool requeue, double now) {
  if (const std::optional<Lease> l = leases_.end(id)) ended(id, *l, requeue, now);
}

size_t Leasing::expire(double now) {
  const auto expired = leases_.expire(now);
  for (const auto& [id, l] : expired) ended(id, l, true, now);
  counters_.leases_expired += expired.size();
  return expired.size();
}

size_t Leasing::end_worker(uint64_t worker, double now) {
  const std::vector<uint64_t> held = leases_.held_by(worker);
  for (uint64_t id : held) end(id, true, now);
  return held.size();
}

void Leasing::end_job(Job& job, double now) {
  for (uint64_t lease : checks_.erase_job(job.id())) end(lease, false, now);  // undecided checks: moot now
  for (uint32_t tile = 0; tile < job.tile_lease.size(); ++tile) end_tile(job, tile, now);
  leases_.forget_job(job.id());
}

}  // namespace tessera
