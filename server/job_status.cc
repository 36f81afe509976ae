#include "server/job_status.h"

#include <algorithm>

namespace tessera {

v1::JobStatus job_status(const JobTable& jobs, const LeaseTable& leases, const std::string& id, bool with_tiles,
                         double now) {
  if (const Sequence* s = jobs.find_sequence(id)) {
    std::map<std::string, uint32_t> workers;  // per live frame
    for (const auto& j : s->jobs)
      if (j && j->live()) workers[j->id()] = leases.workers_on(j->id());
    return s->status(now, workers, true);
  }
  const Job& job = jobs.job(id);
  return job.status(now, leases.workers_on(id), with_tiles);
}

JobProgress job_progress(const JobTable& jobs, const std::string& id) {
  if (const Sequence* s = jobs.find_sequence(id)) return {s->samples_merged(), s->changes, s->ended_durably()};
  const Job& j = jobs.job(id);
  return {j.plan.samples_merged(), j.plan.samples_merged(), j.ended_durably()};
}

QueueDepth queue_depth(const JobTable& jobs, const LeaseTable& leases, double thread_speed) {
  const Load load = jobs.load();
  QueueDepth q;
  q.tasks_leased = leases.live_count();
  q.tasks_ready = load.tasks_ready;
  q.samples_remaining = load.samples_remaining;
  q.samples_per_thread_second = thread_speed > 0 ? thread_speed : QueueDepth::kAssumedThreadSpeed;
  q.core_seconds_remaining = double(q.samples_remaining) / q.samples_per_thread_second;
  return q;
}

std::vector<v1::JobStatus> job_list(const JobTable& jobs, const LeaseTable& leases, double now) {
  std::vector<std::pair<uint64_t, v1::JobStatus>> out;  // stills and sequences; frames are in their sequences
  for (const auto& [id, job] : jobs.jobs())
    if (job->sequence.empty()) out.emplace_back(job->meta.seq, job_status(jobs, leases, id, false, now));
  for (const auto& [id, s] : jobs.sequences()) out.emplace_back(s->meta.seq, job_status(jobs, leases, id, false, now));
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<v1::JobStatus> statuses;
  for (auto& [seq, st] : out) statuses.push_back(std::move(st));
  return statuses;
}

}  // namespace tessera
