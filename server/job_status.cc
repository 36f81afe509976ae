#include "server/job_status.h"

#include <algorithm>
#include <set>
#include <string>

#include "core/util/text.h"
#include "server/request_error.h"

namespace tessera {

namespace {

v1::JobStatus sequence_status(const Sequence& s, const LeaseTable& leases, double now, bool with_frames,
                              FrameRange range = {}) {
  std::set<std::string> live;  // its live frames: a worker on several counts once
  for (const auto& j : s.jobs)
    if (j && j->live()) live.insert(j->id());
  return s.status(now, leases.workers_on(live), with_frames, range);
}

}  // namespace

v1::JobStatus job_status(const JobTable& jobs, const LeaseTable& leases, const std::string& id, bool with_tiles,
                         double now, TileRange range, FrameRange frames) {
  if (const Sequence* s = jobs.find_sequence(id)) return sequence_status(*s, leases, now, true, frames);
  if (!jobs.find_job(id))
    if (const auto gone = jobs.left_frame(id)) return left_frame_status(*gone->sequence, gone->index);
  const Job& job = jobs.job(id);
  return job.status(now, leases.workers_on(id), with_tiles, range);
}

v1::JobStatus left_frame_status(const Sequence& s, size_t i) {
  v1::JobStatus st;
  st.set_id(s.frame_job_id(i));
  st.set_name(s.meta.name + " frame " + std::to_string(s.frames[i]));
  st.set_state(v1::JobStatus::DONE);
  st.set_samples_done(*s.left[i]);
  st.set_samples_total(*s.left[i]);
  st.set_tiles_done(s.frame_tiles());
  st.set_tiles_total(s.frame_tiles());
  st.set_passes_total(uint32_t(s.settings.passes().size()));
  st.set_frame_passes_done(st.passes_total());
  st.set_priority(s.meta.priority);
  st.set_owner(s.meta.owner);
  RenderSettings frame = s.settings;
  frame.frame = s.frames[i];
  *st.mutable_settings() = to_proto(frame);
  st.set_sequence(s.id());
  return st;
}

void page_frames(v1::JobStatus& s, FrameRange range) {
  if (s.current_frame_job().empty()) {
    const v1::FrameStatus* current = nullptr;
    for (const v1::FrameStatus& f : s.frames())
      if (f.state() == v1::JobStatus::RUNNING) {
        current = &f;
        break;
      } else if (!f.job_id().empty()) {
        current = &f;
      }
    if (current) s.set_current_frame_job(current->job_id());
  }
  const int end = int(range.end(uint32_t(s.frames_size())));
  if (end < s.frames_size()) s.mutable_frames()->DeleteSubrange(end, s.frames_size() - end);
  s.mutable_frames()->DeleteSubrange(0, std::min(int(range.from), s.frames_size()));
}

void keep_changed_frames(v1::JobStatus& s, std::vector<std::string>& sent) {
  std::vector<std::string> now(size_t(s.frames_size()));
  for (int i = 0; i < s.frames_size(); ++i) now[size_t(i)] = s.frames(i).SerializeAsString();
  if (!sent.empty() && sent.size() == now.size()) {
    google::protobuf::RepeatedPtrField<v1::FrameStatus> changed;
    for (size_t i = 0; i < now.size(); ++i)
      if (now[i] != sent[i]) changed.Add()->Swap(s.mutable_frames(int(i)));
    s.mutable_frames()->Swap(&changed);
    s.set_frames_changed_only(true);
  }
  sent = std::move(now);
}

JobProgress job_progress(const JobTable& jobs, const std::string& id) {
  if (const Sequence* s = jobs.find_sequence(id)) return {s->samples_merged(), s->changes, s->ended_durably()};
  if (!jobs.find_job(id))
    if (const auto gone = jobs.left_frame(id)) return {*gone->sequence->left[gone->index], 0, true};
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

v1::JobStatus job_summary(const JobTable& jobs, const LeaseTable& leases, const std::string& id, double now) {
  if (const Sequence* s = jobs.find_sequence(id)) return sequence_status(*s, leases, now, false);
  return job_status(jobs, leases, id, false, now);
}

std::vector<v1::JobStatus> job_list(const JobTable& jobs, const LeaseTable& leases, double now) {
  std::vector<v1::JobStatus> statuses;  // stills and sequences; frames are in their sequences
  for (const std::string& id : jobs.page(0, jobs.listed())) statuses.push_back(job_summary(jobs, leases, id, now));
  return statuses;
}

uint64_t page_after(const std::string& page_token) {
  if (page_token.empty()) return 0;  // from the first job
  size_t used = 0;
  uint64_t after = 0;
  try {
    after = std::stoull(page_token, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != page_token.size())
    throw RequestError(RequestError::Code::kInvalidArgument, "bad page_token '" + utf8_prefix(page_token, 64) + "'");
  return after;
}

}  // namespace tessera
