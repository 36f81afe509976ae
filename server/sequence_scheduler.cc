#include "server/sequence_scheduler.h"

namespace tessera {

std::shared_ptr<Job> SequenceScheduler::make_frame(const Sequence& s, size_t index) {
  RenderSettings settings = s.settings;
  settings.frame = s.frames[index];
  // Its tasks carry only what this frame takes from a camera path (the whole path is the
  // sequence's, up to 1 MiB: every task of every frame carried it).
  settings.keep_frames_camera_only();
  JobMeta meta = s.meta;
  meta.id = s.frame_job_id(index);
  meta.name = s.meta.name + " frame " + std::to_string(s.frames[index]);
  meta.settings = to_proto(settings);
  auto job = std::make_shared<Job>(std::move(meta), settings);
  job->sequence = s.id();
  job->frame_index = uint32_t(index);
  return job;
}

size_t SequenceScheduler::next_unstarted(const Sequence& s) {
  size_t i = s.next;
  while (i < s.frames.size() && s.frame_started(i)) ++i;
  return i;
}

Job* SequenceScheduler::start_next(Sequence& s, double now, Effects& fx) {
  s.next = next_unstarted(s);
  if (s.next == s.frames.size() || !s.live()) return nullptr;
  std::shared_ptr<Job> job = std::move(s.prepared);
  if (!job || job->frame_index != s.next) job = make_frame(s, s.next);  // (none made in time: here)
  job->submitted = job->snaps.last_checkpoint = now;
  Job& j = jobs_.add(job);
  s.jobs[s.next++] = std::move(job);
  ++s.frames_started;
  ++s.live_frames;
  lifecycle_.start(s, now, fx);
  if (j.plan.done()) lifecycle_.finish_if_done(j, now, fx);  // nothing to render (cannot happen today)
  return &j;
}

std::vector<std::pair<std::shared_ptr<Sequence>, size_t>> SequenceScheduler::to_prepare(int64_t max_live_pixels) const {
  std::vector<std::pair<std::shared_ptr<Sequence>, size_t>> out;
  int64_t live_pixels = -1;  // counted when first needed
  for (const auto& [id, s] : jobs_.sequences()) {
    const size_t i = next_unstarted(*s);
    if (!s->live() || s->prepared || i >= s->frames.size()) continue;
    if (s->live_frames > 0) {
      if (live_pixels < 0) live_pixels = jobs_.load().live_pixels;
      const int64_t pixels = live_pixels_of(s->settings);
      if (live_pixels + pixels > max_live_pixels) continue;
      live_pixels += pixels;
    }
    out.emplace_back(s, i);
  }
  return out;
}

void SequenceScheduler::offer(Sequence& s, size_t index, std::shared_ptr<Job> job) {
  if (s.live() && !s.prepared && next_unstarted(s) == index) s.prepared = std::move(job);
}

}  // namespace tessera
