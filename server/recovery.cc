#include "server/recovery.h"

#include "core/util/log.h"
#include "server/data_marker.h"
#include "server/sequence_scheduler.h"

namespace tessera {

void Recovery::restore(double now, Effects& fx) {
  p_.store.forget_merges();  // worker ids of the earlier run
  for (const StoredJob& row : p_.store.jobs()) {
    if (!row.unreadable.empty()) {
      keep(row, row.unreadable, fx);
      continue;
    }
    if (!job_live(row.state)) {  // (ended, not yet archived when the earlier run stopped)
      p_.store.discard_partial_writes(row.meta.id);
      try {
        Ended e = load_ended(row, p_.store, now);
        if (e.job && row.state == v1::JobStatus::DONE) with_final_image(row, e.job, now);
        adopt(p_.jobs, e);
        if (e.job && e.job->plan.has_film() && p_.snapshots.final_snapshot(*e.job, now)) fx.writes.push_back(e.job);
        ++p_.counters.jobs_restored;
      } catch (const WireError& e) {  // checked at submit: only a damaged database gets here
        keep(row, std::string("stored settings: ") + e.what(), fx);
      }
    } else if (row.frames.empty())
      restore_job(row, now, fx);
    else
      restore_sequence(row, now, fx);
  }
}

// A DONE job's end is recorded once its checkpoint holds the whole film, whether or not its
// final image was written (a full disk at its end: in memory the write is retried on
// fetch). Where the image on disk is not that final one, its film is read back from the
// checkpoint and the image written again (final_snapshot, in restore); the job leaves memory
// once it is. It was taken as written: the first fetch served the unfinished image as final
// and the archive deleted the checkpoint, the film's only whole copy.
void Recovery::with_final_image(const StoredJob& row, std::shared_ptr<Job>& job, double now) const {
  if (!p_.image_passes || p_.image_passes(row.meta.id) == job->plan.frame_passes_done()) return;
  auto whole = std::make_shared<Job>(row.meta, from_proto(row.meta.settings), row.state);
  try {
    const std::optional<double> elapsed = p_.store.read_checkpoint(row.meta.id, whole->plan, true, &whole->splats);
    if (!elapsed || !whole->plan.done()) return;  // (nothing whole to write it from: the image stays as it is)
  } catch (const DataFolderError&) {
    throw;  // (a start stops on it: nothing is taken for missing or rendered again)
  } catch (const std::exception& e) {
    spdlog::warn("job {}: its final image is not on disk and its checkpoint cannot be read: {}", row.meta.id, e.what());
    return;
  }
  spdlog::warn("job {}: its final image is not on disk; written again from its checkpoint", row.meta.id);
  whole->error = row.error;
  whole->submitted = now;
  whole->ended_at = row.ended_at;
  whole->started = now - row.elapsed;
  whole->finished_at = now;
  whole->written = {0, 0, 1, whole->plan.merges()};
  whole->end_recorded = true;
  job = std::move(whole);
}

void Recovery::keep(const StoredJob& row, const std::string& why, Effects& fx) {
  spdlog::error(
      "job {}: its row in the job database cannot be read ({}); it is not taken up, and its files "
      "(jobs/{}) and scene are kept until the row is mended or the job deleted",
      row.meta.id, why, row.meta.id);
  fx.event("job.unreadable", row.meta.id, "", why);
  kept_.push_back(row);
}

void Recovery::as_ended(Job& job, double now, double elapsed) {
  job.started = now - elapsed;
  job.finished_at = now;
  job.snaps.image_frame_passes = job.plan.frame_passes_done();
  job.compact();  // (restored without a film; a plan without a checkpoint has its own)
  job.written = {1, job.plan.merges(), 1, job.plan.merges()};
  job.end_recorded = true;
}

Recovery::Ended Recovery::load_ended(const StoredJob& row, const JobStore& store, double now) {
  const RenderSettings settings = from_proto(row.meta.settings);
  Ended e;
  if (row.frames.empty()) {
    e.job = std::make_shared<Job>(row.meta, settings, row.state);
    try {
      store.read_checkpoint(row.meta.id, e.job->plan, false);  // (its counts: the film stays on disk)
    } catch (const DataFolderError&) {
      throw;
    } catch (const std::exception& ex) {
      spdlog::warn("job {}: {}; its counts are lost, its image is kept", row.meta.id, ex.what());
      e.job = std::make_shared<Job>(row.meta, settings, row.state);  // the damaged read left its plan unusable
    }
    e.job->error = row.error;
    e.job->submitted = now;
    e.job->ended_at = row.ended_at;
    as_ended(*e.job, now, row.elapsed);
    return e;
  }
  Sequence& s = *(e.sequence = std::make_shared<Sequence>(row.meta, settings, row.frames, row.state));
  s.error = row.error;
  s.submitted = now;
  s.ended_at = row.ended_at;
  double elapsed = 0;
  for (size_t i = 0; i < s.frames.size(); ++i) {  // a frame that started has a checkpoint
    std::shared_ptr<Job> job = SequenceScheduler::make_frame(s, i);
    store.discard_partial_writes(job->id());  // (a frame whose first checkpoint a crash cut short too)
    std::optional<double> cp;
    try {
      if (!(cp = store.read_checkpoint(job->id(), job->plan, false))) continue;
    } catch (const DataFolderError&) {
      throw;
    } catch (const std::exception& ex) {
      spdlog::warn("job {}: {}; taken as never rendered", job->id(), ex.what());
      continue;
    }
    const bool done = job->plan.done();
    JobLifecycle::restore(*job, done ? v1::JobStatus::DONE : v1::JobStatus::CANCELLED);
    job->submitted = now;
    as_ended(*job, now, *cp);
    elapsed = std::max(elapsed, *cp);
    ++s.frames_started;
    if (done) {  // left memory, as JobTable::let_go leaves it
      ++s.frames_done;
      if (s.left.empty()) s.left.resize(s.frames.size());
      s.left[i] = job->plan.samples_merged();
    } else {
      s.jobs[i] = std::move(job);  // kept for a requeue
    }
  }
  s.end_recorded = true;
  s.started = now - elapsed;
  s.finished_at = now;
  return e;
}

void Recovery::adopt(JobTable& jobs, const Ended& e) {
  if (e.job) {
    jobs.saw_seq(e.job->meta.seq);
    jobs.add(e.job);
    return;
  }
  jobs.saw_seq(e.sequence->meta.seq);
  jobs.add(e.sequence);
  for (const std::shared_ptr<Job>& j : e.sequence->jobs)
    if (j) jobs.add(j);
}

void Recovery::resume(JobLifecycle& lifecycle, Job& j, double elapsed, bool checkpointed, double now) {
  const bool rendered = j.plan.merges() > 0 || elapsed > 0;
  lifecycle.requeue(j, rendered);
  if (rendered) j.started = now - elapsed;
  if (rendered && j.started_at == 0) j.started_at = wall_seconds() - elapsed;  // about: its render time
  j.snaps.last_checkpoint = now;
  j.snaps.checkpoint_merges = j.plan.merges();
  if (checkpointed) j.written.checkpoints = 1, j.written.checkpoint_merges = j.plan.merges();
}

void Recovery::restore_job(const StoredJob& row, double now, Effects& fx) {
  const std::string& id = row.meta.id;
  RenderSettings settings;
  try {
    settings = from_proto(row.meta.settings);
  } catch (const WireError& e) {  // checked at submit: only a damaged database gets here
    keep(row, std::string("stored settings: ") + e.what(), fx);
    return;
  }
  p_.jobs.saw_seq(row.meta.seq);
  auto shared = std::make_shared<Job>(row.meta, settings, row.state);
  double elapsed = row.elapsed;
  bool checkpointed = false;
  try {
    if (const std::optional<double> e = p_.store.read_checkpoint(id, shared->plan, true, &shared->splats)) {
      checkpointed = true;
      elapsed = *e;
    }
  } catch (const DataFolderError&) {
    throw;  // (a start stops on it: nothing is taken for missing or rendered again)
  } catch (const std::exception& e) {
    spdlog::warn("job {}: {}; its samples are rendered again", id, e.what());
    shared = std::make_shared<Job>(row.meta, settings, row.state);  // the damaged read left its plan unusable
  }
  Job& j = p_.jobs.add(shared);
  j.error = row.error;
  j.submitted = now;
  ++p_.counters.jobs_restored;
  p_.store.discard_partial_writes(id);
  std::string lost;  // why it cannot go on
  try {
    j.meta.scene_bytes = p_.restore_scene(j.meta.scene_hash);
  } catch (const DataFolderError&) {
    throw;  // (a start stops on it: nothing is taken for missing or rendered again)
  } catch (const std::exception& e) {
    lost = e.what();
  }
  resume(p_.lifecycle, j, elapsed, checkpointed, now);
  if (!lost.empty()) {
    j.error = "cannot go on after the coordinator restarted: " + lost;
    p_.lifecycle.end(j, v1::JobStatus::FAILED, now, fx);
  } else if (j.plan.done()) {  // the crash came between its last checkpoint and recording its end
    p_.lifecycle.end(j, v1::JobStatus::DONE, now, fx);
  }
  if (!j.live() && p_.snapshots.final_snapshot(j, now)) fx.writes.push_back(shared);
}

void Recovery::restore_sequence(const StoredJob& row, double now, Effects& fx) {
  RenderSettings settings;
  try {
    settings = from_proto(row.meta.settings);
  } catch (const WireError& e) {  // checked at submit: only a damaged database gets here
    keep(row, std::string("stored settings: ") + e.what(), fx);
    return;
  }
  p_.jobs.saw_seq(row.meta.seq);
  Sequence& s = p_.jobs.add(std::make_shared<Sequence>(row.meta, settings, row.frames, row.state));
  s.error = row.error;
  s.submitted = now;
  ++p_.counters.jobs_restored;
  std::string lost;
  try {
    s.meta.scene_bytes = p_.restore_scene(s.meta.scene_hash);
  } catch (const DataFolderError&) {
    throw;  // (a start stops on it: nothing is taken for missing or rendered again)
  } catch (const std::exception& e) {
    lost = e.what();
  }
  double elapsed = 0;
  bool all_done = true;
  for (size_t i = 0; i < s.frames.size(); ++i) {
    const std::string id = s.frame_job_id(i);
    std::optional<double> cp;  // its render seconds
    std::shared_ptr<Job> job;
    try {
      // A frame that started has a checkpoint (or is rendered again from the start). Its
      // film only where it is needed: a frame still rendering, or one done whose image on
      // disk does not hold every pass (written again below). Every done frame's film was
      // read, and held until its image was written again: a long sequence's restart took
      // a film per finished frame at once.
      p_.store.discard_partial_writes(id);  // (a frame whose first checkpoint a crash cut short too)
      const auto read = [&](bool film) {
        job = SequenceScheduler::make_frame(s, i);
        return cp = p_.store.read_checkpoint(id, job->plan, film, &job->splats);
      };
      if (read(false) && s.live()) {
        const bool done = job->plan.done();
        const std::optional<uint32_t> image = p_.image_passes ? p_.image_passes(id) : std::nullopt;
        if (!done || image != job->plan.frame_passes_done()) read(true);
      }
      if (!cp) {
        all_done = false;
        continue;
      }
    } catch (const DataFolderError&) {
      throw;  // (a start stops on it: nothing is taken for missing or rendered again)
    } catch (const std::exception& e) {
      spdlog::warn("job {}: {}; its samples are rendered again", id, e.what());
      all_done = false;
      continue;
    }
    Job& j = p_.jobs.add(job);
    s.jobs[i] = job;
    ++s.frames_started;
    j.submitted = now;
    elapsed = std::max(elapsed, *cp);
    j.written.checkpoints = 1;
    j.written.checkpoint_merges = j.plan.merges();
    all_done &= j.plan.done();
    s.frames_done += j.plan.done();
    if (s.live() && !j.plan.done()) {
      p_.lifecycle.restore(j, j.plan.merges() > 0 ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED);
      j.started = now - *cp;
      j.snaps.last_checkpoint = now;
      j.snaps.checkpoint_merges = j.plan.merges();
      ++s.live_frames;
    } else if (s.live() && j.plan.has_film()) {  // done: its image is written again in case it was not
      p_.lifecycle.restore(j, v1::JobStatus::DONE);
      j.started = now - *cp;
      j.finished_at = now;
      if (p_.snapshots.final_snapshot(j, now)) fx.writes.push_back(job);
    } else {
      p_.lifecycle.restore(j, j.plan.done() ? v1::JobStatus::DONE : v1::JobStatus::CANCELLED);
      as_ended(j, now, *cp);
      p_.jobs.let_go(j);  // a DONE frame leaves memory; a cancelled one stays for a requeue
    }
  }
  if (!lost.empty()) {
    s.error = "cannot go on after the coordinator restarted: " + lost;
    p_.lifecycle.end(s, v1::JobStatus::FAILED, now, fx);
  } else if (all_done) {
    p_.lifecycle.end(s, v1::JobStatus::DONE, now, fx);
  } else {
    s.started = now - elapsed;
    p_.lifecycle.restore(s, elapsed > 0 ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED);
    while (s.next < s.jobs.size() && s.frame_started(s.next)) ++s.next;
  }
}

}  // namespace tessera
