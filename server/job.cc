#include "server/job.h"

#include <algorithm>
#include <cmath>
#include <optional>

namespace tessera {

namespace {

// Wall-clock times (seconds since 1970) as Timestamps; 0 (not known) leaves one unset, and
// a live job has no end.
void set_times(v1::JobStatus& s, double submitted, double started, double ended) {
  const auto put = [](google::protobuf::Timestamp* ts, double t) {
    ts->set_seconds(int64_t(std::floor(t)));
    ts->set_nanos(std::min(999999999, int32_t((t - std::floor(t)) * 1e9)));
  };
  if (submitted > 0) put(s.mutable_submitted_at(), submitted);
  if (started > 0) put(s.mutable_started_at(), started);
  if (ended > 0 && !job_live(s.state())) put(s.mutable_ended_at(), ended);
}

}  // namespace

void Job::compact() {
  plan.compact();
  splats.release();
  std::vector<uint64_t>().swap(tile_lease);
  std::vector<uint32_t>().swap(tile_resets);
  tile_backup.clear();
  for (auto& [worker, tiles] : merged_by) {
    std::sort(tiles.begin(), tiles.end());
    tiles.erase(std::unique(tiles.begin(), tiles.end()), tiles.end());
    tiles.shrink_to_fit();
  }
}

v1::JobStatus Job::status(double now, uint32_t workers, bool with_tiles, TileRange range) const {
  v1::JobStatus s;
  s.set_id(meta.id);
  s.set_name(meta.name);
  s.set_state(reported_state());
  // A job whose image cannot be written still renders (the film is in memory and writes
  // are retried with the next snapshot); the user is told why its image is missing.
  std::string e = error;
  auto add = [&](const char* what, const std::string& why) {
    if (!why.empty()) e += (e.empty() ? "" : "; ") + std::string(what) + why;
  };
  add("image not written: ", image_error);
  add("checkpoint not written: ", checkpoint_error);
  if (live()) add("", failure_note);
  s.set_error(e);
  s.set_samples_done(plan.samples_merged());
  s.set_samples_total(plan.samples_total());
  s.set_tiles_done(plan.tiles_done());
  s.set_tiles_total(plan.tile_count());
  s.set_passes_total(uint32_t(plan.passes().size()));
  s.set_frame_passes_done(plan.frame_passes_done());
  s.set_priority(meta.priority);
  const double elapsed = started > 0 ? (live() ? now : finished_at) - started : 0;
  s.set_elapsed_seconds(elapsed);
  s.set_owner(meta.owner);
  set_times(s, meta.submitted_at, started_at, ended_at);
  const double f = plan.fraction_done();
  if (live() && f > 0) s.set_eta_seconds(elapsed * (1 - f) / f);
  s.set_active_workers(workers);
  *s.mutable_settings() = meta.settings;
  s.set_sequence(sequence);
  if (with_tiles)
    for (uint32_t i = range.from; i < range.end(plan.tile_count()); ++i) {
      const TileProgress p = plan.tile_progress(i);  // (an ended job's: as its frame's)
      v1::TileProgress* t = s.add_tiles();
      *t->mutable_rect() = to_proto(plan.tile_rect(i));
      t->set_passes_done(p.passes_done);
      t->set_samples(p.passes_done ? plan.passes()[p.passes_done - 1].second : 0);
      t->set_relative_error(p.relative_error);
      t->set_finished(p.finished);
    }
  return s;
}

std::optional<std::pair<std::string, int>> Sequence::split_frame_id(const std::string& id) {
  const size_t f = id.rfind("-f");
  if (f == std::string::npos || f == 0) return std::nullopt;
  try {
    size_t used = 0;
    const int frame = std::stoi(id.substr(f + 2), &used);
    if (used != id.size() - f - 2) return std::nullopt;
    return std::make_pair(id.substr(0, f), frame);
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

uint64_t Sequence::samples_merged() const {
  uint64_t n = 0;
  for (const auto& j : jobs)
    if (j) n += j->plan.samples_merged();
  for (const auto& l : left) n += l.value_or(0);
  return n;
}

v1::JobStatus Sequence::status(double now, uint32_t workers, bool with_frames, FrameRange range) const {
  v1::JobStatus s;
  s.set_id(meta.id);
  s.set_name(meta.name);
  s.set_state(reported_state());
  s.set_priority(meta.priority);
  s.set_owner(meta.owner);
  *s.mutable_settings() = meta.settings;
  s.set_frames_total(uint32_t(frames.size()));
  s.set_passes_total(uint32_t(settings.passes().size()));
  uint64_t done = 0, total = 0;
  uint32_t tiles_done = 0, frames_done = 0;
  std::string e = error;
  const uint32_t first = range.from, end = range.end(uint32_t(frames.size()));
  std::optional<size_t> rendering, latest;  // (current_frame_job: rendering, else started last)
  for (size_t i = 0; i < frames.size(); ++i) {
    const Job* j = jobs[i].get();
    const bool gone = frame_left(i);  // DONE, its end recorded, out of memory
    const uint64_t fd = j ? j->plan.samples_merged() : gone ? *left[i] : 0;
    const uint64_t ft = j ? j->plan.samples_total() : gone ? fd : frame_samples();
    done += fd;
    total += ft;
    if (gone) {
      tiles_done += frame_tiles();
      ++frames_done;
    } else if (j) {
      tiles_done += j->plan.tiles_done();
      frames_done += j->reported_state() == v1::JobStatus::DONE;
      // (A live frame's failure note too: why the sequence waits, as a still's status says.)
      for (const std::string* why : {&j->image_error, &j->checkpoint_error, j->live() ? &j->failure_note : nullptr})
        if (why && !why->empty()) e += (e.empty() ? "" : "; ") + ("frame " + std::to_string(frames[i]) + ": ") + *why;
    }
    if (j && j->reported_state() == v1::JobStatus::RUNNING && !rendering) rendering = i;
    if (j || gone) latest = i;
    if (!with_frames || i < first || i >= end) continue;
    v1::FrameStatus* f = s.add_frames();
    f->set_frame(frames[i]);
    f->set_state(j        ? j->reported_state()
                 : gone   ? v1::JobStatus::DONE
                 : live() ? v1::JobStatus::QUEUED
                          : v1::JobStatus::CANCELLED);
    f->set_samples_done(fd);
    f->set_samples_total(ft);
    f->set_frame_passes_done(j ? j->plan.frame_passes_done() : gone ? s.passes_total() : 0);
    f->set_tiles_done(j ? j->plan.tiles_done() : gone ? frame_tiles() : 0);
    if (j || gone) f->set_job_id(frame_job_id(i));
  }
  if (with_frames && (rendering || latest)) s.set_current_frame_job(frame_job_id(rendering ? *rendering : *latest));
  s.set_error(e);
  s.set_samples_done(done);
  s.set_samples_total(total);
  s.set_tiles_done(tiles_done);
  s.set_tiles_total(uint32_t(std::min<uint64_t>(UINT32_MAX, uint64_t(frame_tiles()) * frames.size())));
  s.set_frames_done(frames_done);
  s.set_frame_passes_done(reported_state() == v1::JobStatus::DONE ? s.passes_total() : 0);
  s.set_active_workers(workers);
  const double elapsed = started > 0 ? (live() ? now : finished_at) - started : 0;
  s.set_elapsed_seconds(elapsed);
  set_times(s, meta.submitted_at, started_at, ended_at);
  const double f = total ? double(done) / double(total) : 0;
  if (live() && f > 0) s.set_eta_seconds(elapsed * (1 - f) / f);
  return s;
}

}  // namespace tessera
