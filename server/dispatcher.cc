#include "server/dispatcher.h"

#include <algorithm>

#include "server/request_error.h"

namespace tessera {

v1::GetTaskResponse Dispatcher::get_task(uint64_t worker_id, uint32_t max_tasks, uint64_t max_samples, double now,
                                         Effects& fx, uint32_t max_passes) {
  v1::GetTaskResponse resp;
  if (p_.leasing.expire(now) > 0) fx.changed = true;
  if (p_.verifier.quarantined(worker_id))
    throw RequestError(RequestError::Code::kPermissionDenied,
                       "worker " + std::to_string(worker_id) +
                           " is quarantined: its results differed from the same tasks rendered elsewhere");
  WorkerInfo* w = p_.workers.find(worker_id);
  if (!w)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "unknown worker " + std::to_string(worker_id) + "; register again");
  w->last_seen = now;
  w->passes_per_task = std::clamp<uint32_t>(max_passes, 1, kMaxPassesPerTask);
  if (w->draining) {  // (it finishes what it holds; the heartbeat keeps those leases)
    resp.set_retry_after_ms(1000);
    return resp;
  }
  struct Source {
    int32_t priority;
    uint64_t seq;
    size_t frame;
    Job* job;
    Sequence* sequence;  // a sequence's frames to start
  };
  std::vector<Source> order;
  uint64_t outstanding = p_.leases.live_count() + p_.checks.waiting();  // out now or ready to go
  for (const auto& [id, job] : p_.jobs.jobs())
    if (job->live()) {
      order.push_back({job->meta.priority, job->meta.seq, job->frame_index, job.get(), nullptr});
      outstanding += job->plan.ready();
      outstanding -= std::min<uint64_t>(outstanding, job->tile_backup.size());  // a tile's second lease is no more work
    }
  for (const auto& [id, sq] : p_.jobs.sequences())
    if (sq->live() && sq->next < sq->frames.size()) {
      order.push_back({sq->meta.priority, sq->meta.seq, sq->frames.size(), nullptr, sq.get()});
      // As if the frames it may start were ready: a worker's share counts them.
      const uint64_t unstarted = sq->frames.size() - sq->frames_started;
      const uint32_t startable =
          SequenceScheduler::kMaxLiveFrames - std::min(SequenceScheduler::kMaxLiveFrames, sq->live_frames);
      outstanding += uint64_t(sq->frame_tiles()) * std::min<uint64_t>(unstarted, startable);
    }
  std::sort(order.begin(), order.end(), [](const Source& a, const Source& b) {
    if (a.priority != b.priority) return a.priority > b.priority;
    return a.seq != b.seq ? a.seq < b.seq : a.frame < b.frame;
  });
  const uint64_t threads = std::max<uint64_t>(1, p_.workers.threads());
  const uint64_t share = (outstanding * w->threads + threads - 1) / threads;
  const uint64_t bound = std::min<uint64_t>(share, max_leases_);
  const uint64_t unshared = bound > w->leases ? bound - w->leases : 0;
  max_tasks = uint32_t(std::min<uint64_t>(std::clamp<uint32_t>(max_tasks, 1, kMaxTasksPerRequest), unshared));
  p_.verifier.lease_checks(*w, max_tasks, now, resp);

  const bool verify = p_.verifier.active();
  uint64_t samples = 0;
  auto room = [&] { return uint32_t(resp.tasks_size()) < max_tasks && (max_samples == 0 || samples < max_samples); };
  auto take_from = [&](Job& job) {
    if (job.resting(w->identity(), now)) return;  // its task failed here lately (JobLifecycle::task_failed)
    while (room()) {
      std::optional<TileTask> t = job.plan.take(std::min(w->passes_per_task, job.max_run));
      if (!t) break;
      const uint64_t task_id = p_.leasing.grant(job, *t, *w, now);
      p_.lifecycle.start(job, now, fx);
      samples += add_task(job, *t, task_id, resp);
      if (verify) mark_for_check(*w, task_id, resp);
    }
  };
  int64_t live_pixels = -1;  // counted when first needed
  for (const Source& src : order) {
    if (src.job) {
      take_from(*src.job);
      continue;
    }
    // The worker has room and the sequence's started frames have no ready task: start the
    // next frame, within the limits on films in memory.
    Sequence& sq = *src.sequence;
    while (room() && SequenceScheduler::may_start(sq)) {
      if (live_pixels < 0) live_pixels = p_.jobs.load().live_pixels;
      // A prepared frame's films are counted already (JobTable::load): starting it adds none.
      const bool prepared = sq.prepared && sq.prepared->frame_index == SequenceScheduler::next_unstarted(sq);
      const int64_t pixels = prepared ? 0 : live_pixels_of(sq.settings);
      if (sq.live_frames > 0 && live_pixels + pixels > max_live_pixels_) break;
      Job* job = p_.sequences.start_next(sq, now, fx);
      if (!job) break;
      live_pixels += pixels;
      take_from(*job);
    }
  }
  if (resp.tasks_size() == 0 && max_tasks > 0) back_up(*w, max_tasks, max_samples, now, resp);
  if (resp.tasks_size() == 0) resp.set_retry_after_ms(200);
  return resp;
}

uint64_t Dispatcher::add_task(Job& job, const TileTask& t, uint64_t task_id, v1::GetTaskResponse& resp) const {
  v1::Task* task = resp.add_tasks();
  task->set_task_id(task_id);
  task->set_job_id(job.id());
  task->set_scene_hash(job.meta.scene_hash);
  *task->mutable_settings() = job.meta.settings;
  *task->mutable_tile() = to_proto(t.rect);
  task->set_pass(t.pass);
  if (t.pass_count > 1) task->set_pass_count(t.pass_count);
  if (!t.base.empty()) task->set_base_sums(encode_sums(t.base));
  task->set_sample_begin(t.sample_begin);
  task->set_sample_end(t.sample_end);
  task->set_priority(job.meta.priority);
  uint64_t pixels = uint64_t(t.rect.area());
  if (!t.active.empty()) {
    task->set_active(t.active.data(), t.active.size());
    pixels = uint64_t(std::count(t.active.begin(), t.active.end(), 1));
  }
  return pixels * (t.sample_end - t.sample_begin);
}

void Dispatcher::back_up(WorkerInfo& w, uint32_t max_tasks, uint64_t max_samples, double now,
                         v1::GetTaskResponse& resp) {
  struct Old {
    Job* job;
    uint32_t tile;
  };
  std::vector<Old> old;
  size_t looked = 0;
  for (const auto& [id, l] : p_.leases.live_leases()) {
    if (old.size() >= max_tasks || ++looked > kBackupScan) break;
    if (l.check || l.worker == w.id || now - l.granted < kBackupAfterSeconds) continue;
    Job* job = p_.jobs.find_job(l.job);
    if (!job || !job->live() || job->tile_lease[l.tile] != id || job->tile_backup.count(l.tile) ||
        job->resting(w.identity(), now))
      continue;
    old.push_back({job, l.tile});
  }
  uint64_t samples = 0;
  for (const Old& o : old) {
    if (max_samples > 0 && samples >= max_samples) break;
    if (const std::optional<TileTask> t = o.job->plan.retake(o.tile)) {
      const uint64_t task_id = p_.leasing.grant_backup(*o.job, *t, w, now);
      samples += add_task(*o.job, *t, task_id, resp);
      if (p_.verifier.active()) mark_for_check(w, task_id, resp);  // a backup may win: checked as any task
    }
  }
}

void Dispatcher::mark_for_check(WorkerInfo& w, uint64_t task_id, const v1::GetTaskResponse& resp) {
  // Checked: a worker's first tasks (probation), then a random fraction.
  const bool probation = w.probation > 0;
  if (!probation && !p_.verifier.pick()) return;
  Lease* lease = p_.leases.live(task_id);
  lease->task = std::make_shared<const v1::Task>(resp.tasks(resp.tasks_size() - 1));
  if (probation) {
    --w.probation;
    lease->probation = true;
  }
}

}  // namespace tessera
