#include "server/job_control.h"

#include "core/util/invariant.h"
#include "core/util/log.h"
#include "core/util/saturating.h"
#include "server/recovery.h"
#include "server/request_error.h"

namespace tessera {

namespace {

RequestError busy(const std::string& id) {
  return RequestError(RequestError::Code::kFailedPrecondition,
                      "job " + id + " is being requeued or deleted by another request; try again");
}

const char* state_name(v1::JobStatus::State s) { return v1::JobStatus::State_Name(s).c_str(); }

}  // namespace

void JobControl::set_priority(const std::string& id, int32_t priority, Effects& fx) {
  if (Sequence* s = jobs_.find_sequence(id)) {
    s->meta.priority = priority;
    for (const std::shared_ptr<Job>& j : s->jobs)
      if (j) j->meta.priority = priority;
    if (s->prepared) s->prepared->meta.priority = priority;
  } else if (Job* j = jobs_.find_job(id)) {
    j->meta.priority = priority;
  }
  fx.event("job.priority", id, "", "priority " + std::to_string(priority));
  fx.changed = true;  // the dispatcher's order changed
}

// ---- delete ----

JobControl::Removal JobControl::begin_delete(const std::string& id, const std::string& requester, bool any, double now,
                                             Effects& fx) {
  jobs_.check_change(id, requester, any, "delete");
  if (archived_changing_.count(id)) throw busy(id);
  Removal r;
  r.id = id;
  if (std::shared_ptr<Sequence> s = jobs_.shared_sequence(id)) {
    if (s->changing || s->removed) throw busy(id);
    s->changing = s->removed = true;
    r.sequence = s;
    r.scene_hash = s->meta.scene_hash;
    for (size_t i = 0; i < s->frames.size(); ++i) {
      r.job_ids.push_back(s->frame_job_id(i));
      if (s->jobs[i]) r.jobs.push_back(s->jobs[i]);
    }
    for (const std::shared_ptr<Job>& j : r.jobs) j->removed = true;  // before the end: no last image
    s->prepared.reset();
    if (s->live()) lifecycle_.end(*s, v1::JobStatus::CANCELLED, now, fx);
    return r;
  }
  std::shared_ptr<Job> job = jobs_.shared(id);
  TESSERA_INVARIANT(job, "job " + id + " checked but missing");
  if (job->changing || job->removed) throw busy(id);
  job->changing = job->removed = true;
  r.scene_hash = job->meta.scene_hash;
  r.jobs.push_back(job);
  r.job_ids.push_back(id);
  if (job->live()) lifecycle_.end(*job, v1::JobStatus::CANCELLED, now, fx);
  return r;
}

JobControl::Removal JobControl::archived_removal(const StoredJob& row) {
  Removal r;
  r.id = row.meta.id;
  r.scene_hash = row.meta.scene_hash;
  if (row.frames.empty()) r.job_ids.push_back(r.id);
  for (const int f : row.frames) r.job_ids.push_back(Sequence::frame_id(r.id, f));
  return r;
}

void JobControl::begin_archived(const std::string& id) {
  if (!archived_changing_.insert(id).second) throw busy(id);
}

bool JobControl::quiet(const Removal& r) { return none_writing(r.jobs) && (!r.sequence || !r.sequence->end_recording); }

bool JobControl::holds_scene(const Removal& r) {
  // A still holds its scene until its end is recorded; a sequence, for its frames, until its own is.
  return r.sequence ? !r.sequence->end_recorded : !r.jobs.front()->end_recorded;
}

void JobControl::removed(const Removal& r, Effects& fx) {
  for (const std::shared_ptr<Job>& j : r.jobs) jobs_.remove_job(j->id());
  if (r.sequence) jobs_.remove_sequence(r.id);
  ++counters_.jobs_deleted;
  fx.event("job.deleted", r.id, "", "");
  fx.changed = true;
}

void JobControl::delete_failed(const Removal& r, double now, Effects& fx) {
  for (const std::shared_ptr<Job>& j : r.jobs) {
    j->removed = false;
    j->changing = false;
    if (!j->live() && snapshots_.final_snapshot(*j, now)) fx.writes.push_back(j);  // its end recorded as usual
  }
  if (r.sequence) {
    r.sequence->removed = r.sequence->changing = false;
    fx.sequence_ends.push_back(r.id);
  }
  fx.changed = true;
}

// ---- requeue ----

JobControl::Requeue JobControl::begin_requeue(const std::string& id, const std::string& requester, bool any) {
  jobs_.check_change(id, requester, any, "requeue");
  if (archived_changing_.count(id)) throw busy(id);
  Requeue q;
  q.id = id;
  const auto refuse_state = [&](v1::JobStatus::State state, bool durable) { refuse_requeue(id, state, durable); };
  if (std::shared_ptr<Sequence> s = jobs_.shared_sequence(id)) {
    refuse_state(s->state(), s->end_recorded);
    if (s->changing || s->removed) throw busy(id);
    s->changing = true;
    q.sequence = s;
    q.scene_hash = s->meta.scene_hash;
    for (const std::shared_ptr<Job>& j : s->jobs)  // (its frames change only with it)
      if (j && j->state() != v1::JobStatus::DONE) q.ended.push_back(j);
    return q;
  }
  std::shared_ptr<Job> job = jobs_.shared(id);
  refuse_state(job->state(), job->end_recorded);
  if (job->changing || job->removed) throw busy(id);
  job->changing = true;
  q.scene_hash = job->meta.scene_hash;
  q.ended.push_back(job);
  return q;
}

Admission JobControl::requeue_admission(const Requeue& q, std::string* owner) {
  Admission a;
  if (const Sequence* s = q.sequence.get()) {
    *owner = s->meta.owner;
    a.pixels = live_pixels_of(s->settings);
    a.samples =
        saturating_mul(s->frame_samples(), s->frames.size() - std::min<size_t>(s->frames.size(), s->frames_done));
    a.scene_bytes = s->meta.scene_bytes;
    return a;
  }
  const Job& j = *q.ended.front();
  *owner = j.meta.owner;
  a.pixels = live_pixels_of(j.plan.settings());
  a.samples = j.plan.samples_left();
  a.scene_bytes = j.meta.scene_bytes;
  return a;
}

void JobControl::refuse_requeue(const std::string& id, v1::JobStatus::State state, bool durable) {
  if (job_live(state))
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + id + " is " + state_name(state) + ": only a FAILED or CANCELLED job can be requeued");
  if (state == v1::JobStatus::DONE)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + id + " is DONE: its image is whole; only a FAILED or CANCELLED job can be requeued");
  if (!durable)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + id + " is still recording its end; try again in a moment");
}

void JobControl::requeue_failed(const Requeue& q) {
  if (q.sequence)
    q.sequence->changing = false;
  else
    q.ended.front()->changing = false;
}

void JobControl::finish_requeue(Requeue& q, double now, Effects& fx) {
  TESSERA_INVARIANT(q.fresh.size() == q.ended.size(), "requeue of " + q.id + " without its plans");
  double elapsed = 0;
  bool rendered = false;
  for (size_t i = 0; i < q.fresh.size(); ++i) {
    elapsed = std::max(elapsed, q.elapsed[i]);
    rendered |= q.elapsed[i] > 0 || q.fresh[i]->plan.merges() > 0;
  }
  if (Sequence* s = q.sequence.get()) {  // live again before its frames, which report their ends to it
    s->changing = false;
    s->error.clear();
    s->end_recorded = false;
    s->meta.scene_bytes = q.scene_bytes;
    s->live_frames += uint32_t(q.fresh.size());
    s->started = now - elapsed;
    lifecycle_.requeue(*s, rendered || s->frames_done > 0);
  }
  for (size_t i = 0; i < q.fresh.size(); ++i) {
    Job& j = *q.fresh[i];
    const Job& old = *q.ended[i];
    // Who merged what stays known (a worker caught later has its tiles rendered again), and
    // tiles of a worker caught while the job had ended are rendered again now (its
    // checkpoint holds them: a requeue finished DONE with a liar's results, unflagged).
    for (const auto& [worker, tiles] : old.merged_by)
      j.merged_by[worker].insert(j.merged_by[worker].end(), tiles.begin(), tiles.end());
    if (!old.tainted.empty()) {
      if (j.splats.any()) j.splats.reset();  // (every tile is tainted then)
      for (uint32_t t : old.tainted) j.plan.reset_tile(t);
    }
    j.submitted = old.submitted;
    j.meta.scene_bytes = q.scene_bytes;
    jobs_.replace(q.fresh[i]);
    if (q.sequence) q.sequence->jobs[j.frame_index] = q.fresh[i];
    Recovery::resume(lifecycle_, j, q.elapsed[i], q.checkpointed[i], now);
  }
  fx.event("job.requeued", q.id, "", std::to_string(q.fresh.size()) + (q.sequence ? " frames" : " job"));
  for (const std::shared_ptr<Job>& j : q.fresh) lifecycle_.finish_if_done(*j, now, fx);  // whole already
  if (Sequence* s = q.sequence.get(); s && s->live() && s->frames_done == s->frames.size())
    lifecycle_.end(*s, v1::JobStatus::DONE, now, fx);
  ++counters_.jobs_requeued;
  fx.changed = true;
}

// ---- the disk work ----

void load_requeue(JobControl::Requeue& q, JobStore& store, SceneStore& scenes, const std::string& data_dir) {
  try {
    q.scene_bytes = scenes.restore(q.scene_hash);  // a use of it, as a live job has
  } catch (const std::exception& e) {
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + q.id + " cannot be requeued: " + without_dir(e.what(), data_dir));
  }
  try {
    store.requeue(q.id);  // the commit point: a restart from here on takes the job up
  } catch (const std::exception& e) {
    scenes.release(q.scene_hash);
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "job " + q.id + " cannot be requeued: " + without_dir(e.what(), data_dir));
  }
  for (const std::shared_ptr<Job>& old : q.ended) {
    auto job = std::make_shared<Job>(old->meta, old->plan.settings());
    job->sequence = old->sequence;
    job->frame_index = old->frame_index;
    std::optional<double> elapsed;
    try {
      elapsed = store.read_checkpoint(job->id(), job->plan, true, &job->splats);
    } catch (const std::exception& e) {
      spdlog::warn("job {}: {}; its samples are rendered again", job->id(), e.what());
      job = std::make_shared<Job>(old->meta, old->plan.settings());  // the damaged read left its plan unusable
      job->sequence = old->sequence;
      job->frame_index = old->frame_index;
    }
    q.fresh.push_back(job);
    q.elapsed.push_back(elapsed.value_or(0));
    q.checkpointed.push_back(elapsed.has_value());
  }
}

uint64_t finish_removal(const JobControl::Removal& r, bool holds_scene, JobStore& store, ImageSink& sink,
                        SceneStore& scenes, const std::string& data_dir) {
  try {
    store.remove(r.id, r.job_ids);  // the commit point: from here on a restart finds no job
  } catch (const std::exception& e) {
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "job " + r.id + " cannot be deleted: " + without_dir(e.what(), data_dir));
  }
  uint64_t bytes = 0;
  for (const std::string& id : r.job_ids) try {
      bytes += sink.remove(id);
    } catch (const std::exception& e) {  // removed at the next start: no row names it
      spdlog::warn("job {}: deleted, but {}", r.id, e.what());
    }
  if (holds_scene) scenes.release(r.scene_hash);
  try {
    if (store.scene_users(r.scene_hash) == 0) bytes += scenes.remove_if_unused(r.scene_hash);
  } catch (const std::exception& e) {
    spdlog::warn("job {}: deleted, but its scene stays: {}", r.id, e.what());
  }
  return bytes;
}

}  // namespace tessera
