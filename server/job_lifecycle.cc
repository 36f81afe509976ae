#include "server/job_lifecycle.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/util/invariant.h"
#include "core/util/text.h"
#include "server/request_error.h"

namespace tessera {

namespace {
const char* end_word(v1::JobStatus::State state) {
  return state == v1::JobStatus::DONE ? "done" : state == v1::JobStatus::FAILED ? "failed" : "cancelled";
}
}  // namespace

void JobLifecycle::start(Job& job, double now, Effects& fx) {
  if (job.state_ != v1::JobStatus::QUEUED) return;
  job.state_ = v1::JobStatus::RUNNING;
  job.started = now;
  if (job.started_at == 0) job.started_at = wall_seconds();
  if (job.sequence.empty()) fx.event("job.started", job.id(), "", "");  // (a frame: its sequence started)
}

void JobLifecycle::start(Sequence& s, double now, Effects& fx) {
  if (s.state_ != v1::JobStatus::QUEUED) return;
  s.state_ = v1::JobStatus::RUNNING;
  s.started = now;
  if (s.started_at == 0) s.started_at = wall_seconds();
  fx.event("job.started", s.id(), "", "");
}

void JobLifecycle::end(Job& job, Job::State state, double now, Effects& fx) {
  TESSERA_INVARIANT(job.live() && !job_live(state), "job " + job.id() + " ended twice, or into a live state");
  job.state_ = state;
  job.finished_at = now;
  job.ended_at = wall_seconds();
  job.pending_checks = 0;
  leasing_.end_job(job, now);
  if (job.sequence.empty()) fx.event(std::string("job.") + end_word(state), job.id(), "", job.error);
  // Its scene is dropped, from memory and disk, once its end is on disk (SnapshotWriter)
  // and no live job uses it: a crash before then finds the job live and its scene there.
  // A sequence holds the scene for its frames until its own end is recorded.
  if (!job.sequence.empty()) frame_ended(job, now, fx);
  fx.changed = true;
}

void JobLifecycle::frame_ended(Job& job, double now, Effects& fx) {
  Sequence* sp = jobs_.find_sequence(job.sequence);
  TESSERA_INVARIANT(sp, "frame " + job.id() + " has no sequence");
  Sequence& s = *sp;
  if (job.state() != v1::JobStatus::CANCELLED)  // (cancelled with its sequence, which says so)
    fx.event(std::string("frame.") + end_word(job.state()), s.id(), "",
             "frame " + std::to_string(s.frames[job.frame_index]) + (job.error.empty() ? "" : ": " + job.error));
  if (s.live_frames > 0) --s.live_frames;
  fx.sequence_ends.push_back(s.id());  // (recorded once every frame's end is)
  if (!s.live()) return;               // the sequence ended first and ends its frames itself
  if (job.state() == v1::JobStatus::FAILED) {
    s.error = "frame " + std::to_string(s.frames[job.frame_index]) + ": " + job.error;
    end(s, v1::JobStatus::FAILED, now, fx);
    return;
  }
  ++s.changes;
  if (job.state() == v1::JobStatus::DONE && ++s.frames_done == s.frames.size())  // O(1): long sequences end often
    end(s, v1::JobStatus::DONE, now, fx);
}

void JobLifecycle::end(Sequence& s, Sequence::State state, double now, Effects& fx) {
  TESSERA_INVARIANT(s.live() && !job_live(state), "sequence " + s.id() + " ended twice, or into a live state");
  s.state_ = state;
  s.finished_at = now;
  s.ended_at = wall_seconds();
  s.prepared.reset();
  fx.event(std::string("job.") + end_word(state), s.id(), "", s.error);
  for (const std::shared_ptr<Job>& j : s.jobs)
    if (j && j->live()) {
      end(*j, v1::JobStatus::CANCELLED, now, fx);
      if (snapshots_.final_snapshot(*j, now)) fx.writes.push_back(j);  // its image keeps what it rendered
    }
  fx.sequence_ends.push_back(s.id());
  fx.changed = true;
}

bool JobLifecycle::finish_if_done(Job& job, double now, Effects& fx) {
  if (!job.live() || !job.plan.done() || job.pending_checks > 0) return false;
  end(job, v1::JobStatus::DONE, now, fx);
  if (snapshots_.final_snapshot(job, now)) fx.writes.push_back(jobs_.shared(job.id()));
  return true;
}

void JobLifecycle::cancel(const std::string& id, const std::string& requester, bool any, double now, Effects& fx) {
  jobs_.check_change(id, requester, any, "cancel");
  if (Sequence* s = jobs_.find_sequence(id)) {
    if (s->live()) end(*s, v1::JobStatus::CANCELLED, now, fx);
    return;
  }
  Job& job = jobs_.job(id);
  if (!job.live()) return;
  end(job, v1::JobStatus::CANCELLED, now, fx);
  if (snapshots_.final_snapshot(job, now)) fx.writes.push_back(jobs_.shared(id));  // keep what was rendered
}

void JobLifecycle::task_failed(Job& job, const std::string& worker, const std::string& error, double now, Effects& fx) {
  if (!job.live()) return;
  ++counters_.tasks_failed;
  Job::Failures& f = job.failed_on[worker];
  // Once an incident: a worker's leases of the job all failing for one cause (its scene
  // does not load) rest it once, not twice as long for each.
  if (now >= f.until) ++f.count;
  const double rest =
      std::min(kMaxRestSeconds, kFirstRestSeconds * std::exp2(double(std::min<uint32_t>(f.count, 32) - 1)));
  f.until = now + rest;
  const std::string why = peer_text(error, 1024);  // (a worker's words: shown to users)
  if (job.failed_on.size() < kFailuresToFail) {    // maybe that worker's trouble: another tries
    char rest_text[32];
    std::snprintf(rest_text, sizeof rest_text, "%.0f", rest);
    job.failure_note = "a task failed on " + worker + ": " + why + " (the job fails once tasks fail on " +
                       std::to_string(kFailuresToFail) + " workers; " + std::to_string(job.failed_on.size()) +
                       " so far; that worker is not given its tasks for " + rest_text + " s)";
    return;
  }
  job.error = "tasks failed on " + std::to_string(job.failed_on.size()) + " workers: " + why;
  end(job, v1::JobStatus::FAILED, now, fx);
  if (snapshots_.final_snapshot(job, now)) fx.writes.push_back(jobs_.shared(job.id()));  // keep what was rendered
}

void JobLifecycle::task_failed(Job& job, const WorkerInfo& w, const std::string& error, double now, Effects& fx) {
  // An event for a worker's first failure on the job (the rest are counted): one worker
  // failing a job's tasks over and over pushed the farm's whole history (deletes,
  // quarantines) out of the event log, which keeps the newest kMaxEvents.
  if (job.live() && !job.failed_on.count(w.identity()))
    fx.events.push_back({0, 0, "task.failed", job.sequence.empty() ? job.id() : job.sequence, w.name, w.principal,
                         peer_text(error, 1024)});
  task_failed(job, w.identity(), error, now, fx);
}

std::optional<RowEnd> JobLifecycle::sequence_end_due(const std::string& id) {
  Sequence* s = jobs_.find_sequence(id);
  if (!s || s->live() || s->end_recorded || s->end_recording || s->removed) return std::nullopt;
  if (s->state() == v1::JobStatus::DONE)
    for (size_t i = 0; i < s->frames.size(); ++i)
      if (!s->frame_left(i) && (!s->jobs[i] || !s->jobs[i]->end_recorded))
        return std::nullopt;  // a frame's final checkpoint is not on disk yet
  s->end_recording = true;
  return RowEnd{s->id(), s->state(), s->error, s->started > 0 ? s->finished_at - s->started : 0};
}

void JobLifecycle::sequence_end_recorded(const std::string& id, bool ok) {
  Sequence* s = jobs_.find_sequence(id);
  TESSERA_INVARIANT(s && s->end_recording, "sequence " + id + " was not being recorded");
  s->end_recording = false;
  s->end_recorded = ok;
}

}  // namespace tessera
