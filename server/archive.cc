#include "server/archive.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/wire_format_lite.h>

#include <algorithm>
#include <climits>

#include "server/request_error.h"

namespace tessera {

namespace {

void count_merged(const Job& j, std::map<uint64_t, uint32_t>& into) {
  for (const auto& [worker, tiles] : j.merged_by) into[worker] += uint32_t(tiles.size());
}

std::vector<MergedInto> merged_list(const std::map<uint64_t, uint32_t>& by_worker) {
  std::vector<MergedInto> out;
  for (const auto& [worker, tiles] : by_worker) out.push_back({worker, tiles});
  return out;
}

// The frame `frame` of an archived sequence's status: its place (throws as frame_job does).
int frame_place(const v1::JobStatus& s, int frame) {
  for (int i = 0; i < s.frames_size(); ++i)
    if (s.frames(i).frame() == frame) return i;
  throw RequestError(RequestError::Code::kNotFound, "job " + s.id() + " has no frame " + std::to_string(frame));
}

// What clients see of a frame of an archived sequence (as left_frame_status).
v1::JobStatus frame_status(const v1::JobStatus& s, int i) {
  const v1::FrameStatus& f = s.frames(i);
  v1::JobStatus st;
  st.set_id(f.job_id());
  st.set_name(s.name() + " frame " + std::to_string(f.frame()));
  st.set_state(f.state());
  st.set_samples_done(f.samples_done());
  st.set_samples_total(f.samples_total());
  const uint32_t tiles = s.frames_total() ? s.tiles_total() / s.frames_total() : 0;
  st.set_tiles_done(f.tiles_done());
  st.set_tiles_total(tiles);
  st.set_passes_total(s.passes_total());
  st.set_frame_passes_done(f.frame_passes_done());
  st.set_priority(s.priority());
  st.set_owner(s.owner());
  *st.mutable_settings() = s.settings();
  st.mutable_settings()->set_frame(f.frame());
  st.set_sequence(s.id());
  return st;
}

}  // namespace

bool Archive::settled(const Job& j) {
  return !j.live() && j.end_recorded && !j.plan.has_film() && !j.snaps.writing && !j.changing && !j.removed &&
         !j.archiving && j.pending_checks == 0;
}

bool Archive::settled(const Sequence& s) {
  if (s.live() || !s.end_recorded || s.end_recording || s.changing || s.removed || s.archiving || s.prepared)
    return false;
  return std::all_of(s.jobs.begin(), s.jobs.end(), [](const std::shared_ptr<Job>& j) { return !j || settled(*j); });
}

std::vector<Archival> Archive::due(double now, size_t limit) {
  std::vector<Archival> out;
  for (const auto& [id, s] : jobs_.sequences()) {
    if (out.size() >= limit) return out;
    if (!settled(*s)) continue;
    std::map<uint64_t, uint32_t> merged = s->left_merged_by;
    for (const std::shared_ptr<Job>& j : s->jobs)
      if (j) count_merged(*j, merged);
    s->archiving = true;
    std::vector<std::string> done;
    if (s->state() == v1::JobStatus::DONE)
      for (size_t i = 0; i < s->frames.size(); ++i) done.push_back(s->frame_job_id(i));
    out.push_back({id, s->status(now, 0, true).SerializeAsString(), merged_list(merged), done, nullptr, s});
  }
  for (const auto& [id, j] : jobs_.jobs()) {
    if (out.size() >= limit) return out;
    if (!j->sequence.empty() || !settled(*j)) continue;
    std::map<uint64_t, uint32_t> merged;
    count_merged(*j, merged);
    j->archiving = true;
    std::vector<std::string> done;
    if (j->state() == v1::JobStatus::DONE) done.push_back(id);
    out.push_back({id, j->status(now, 0, false).SerializeAsString(), merged_list(merged), done, j, nullptr});
  }
  return out;
}

void Archive::done(const Archival& a, bool archived) {
  if (const std::shared_ptr<Sequence>& s = a.sequence) {
    s->archiving = false;
    if (!archived || jobs_.find_sequence(a.id) != s.get() || !settled(*s)) return;
    for (const std::shared_ptr<Job>& j : s->jobs)
      if (j) jobs_.remove_job(j->id());
    jobs_.remove_sequence(a.id);
    return;
  }
  a.job->archiving = false;
  if (archived && jobs_.find_job(a.id) == a.job.get() && settled(*a.job)) jobs_.remove_job(a.id);
}

// ---- reading archived jobs ----

namespace {

// A serialized message without field `field`'s entries, copied field by field (the others'
// bytes as they are). Empty if the bytes do not read as a message.
std::string without_field(const std::string& bytes, int field) {
  namespace pb = google::protobuf;
  pb::io::ArrayInputStream raw(bytes.data(), int(bytes.size()));
  pb::io::CodedInputStream in(&raw);
  in.SetTotalBytesLimit(INT_MAX);
  std::string out;
  {
    pb::io::StringOutputStream sink(&out);
    pb::io::CodedOutputStream os(&sink);
    for (uint32_t tag; (tag = in.ReadTag()) != 0;) {
      const bool skip = pb::internal::WireFormatLite::GetTagFieldNumber(tag) == field;
      if (!(skip ? pb::internal::WireFormatLite::SkipField(&in, tag)
                 : pb::internal::WireFormatLite::SkipField(&in, tag, &os)))
        return {};
    }
  }
  return out;
}

}  // namespace

v1::JobStatus archived_status(const StoredJob& row, bool with_frames) {
  v1::JobStatus s;
  if (!(with_frames ? s.ParseFromString(row.summary)
                    : s.ParseFromString(without_field(row.summary, v1::JobStatus::kFramesFieldNumber)))) {
    // (a damaged row: what the columns say)
    s.Clear();
    s.set_id(row.meta.id);
    s.set_name(row.meta.name);
    s.set_owner(row.meta.owner);
    *s.mutable_settings() = row.meta.settings;
    s.set_frames_total(uint32_t(row.frames.size()));
  }
  s.set_state(row.state);
  s.set_error(row.error);
  s.set_priority(row.meta.priority);
  return s;
}

void add_archived_tiles(v1::JobStatus& s, TileRange range) {
  if (s.frames_total() > 0) return;  // a sequence: its frames have the tiles
  RenderSettings settings;
  try {
    settings = from_proto(s.settings());
  } catch (const std::exception&) {  // (a damaged row: no map)
    return;
  }
  const auto passes = settings.passes();
  const bool done = s.tiles_done() == s.tiles_total();
  const uint32_t passes_done =
      done ? uint32_t(passes.size()) : std::min<uint32_t>(s.frame_passes_done(), passes.size());
  const std::vector<Rect> tiles = frame_tiles(settings);  // as FramePlan cuts them
  for (uint32_t i = range.from; i < range.end(uint32_t(tiles.size())); ++i) {
    v1::TileProgress* t = s.add_tiles();
    *t->mutable_rect() = to_proto(tiles[i]);
    t->set_passes_done(passes_done);
    t->set_samples(passes_done ? passes[passes_done - 1].second : 0);
    t->set_finished(done);
  }
}

std::optional<v1::JobStatus> archived_status(const JobStore& store, const std::string& id) {
  if (const std::optional<StoredJob> row = store.job(id)) {
    if (row->summary.empty()) return std::nullopt;
    return archived_status(*row);
  }
  const auto parts = Sequence::split_frame_id(id);
  if (!parts) return std::nullopt;
  const std::optional<StoredJob> row = store.job(parts->first);
  if (!row || row->summary.empty() || row->frames.empty()) return std::nullopt;
  const v1::JobStatus s = archived_status(*row);
  for (int i = 0; i < s.frames_size(); ++i)
    if (s.frames(i).frame() == parts->second && !s.frames(i).job_id().empty()) return frame_status(s, i);
  return std::nullopt;
}

std::optional<StoredJob> archived_for_change(const JobStore& store, const std::string& id, const std::string& requester,
                                             bool any, const char* verb) {
  std::optional<StoredJob> row = store.job(id);
  if (row && !row->summary.empty()) {
    JobTable::check_owner(id, row->meta.owner, requester, any, verb);
    return row;
  }
  if (row) return std::nullopt;  // in memory (or a submit not yet acknowledged)
  if (const std::optional<v1::JobStatus> frame = archived_status(store, id)) {
    JobTable::check_owner(id, frame->owner(), requester, any, verb);
    throw JobTable::frame_refusal(id, frame->sequence(), verb);
  }
  return std::nullopt;
}

std::optional<std::string> archived_image(const JobStore& store, const std::string& id, std::optional<int> frame,
                                          ImageStreamHeader* header) {
  std::optional<v1::JobStatus> s = archived_status(store, id);
  if (!s) return std::nullopt;
  if (s->frames_total() > 0) {  // a sequence: one of its frames
    if (!frame)
      throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " is a sequence of " +
                                                                   std::to_string(s->frames_total()) +
                                                                   " frames: name one (fetch --frame N, or --all)");
    const int i = frame_place(*s, *frame);
    if (s->frames(i).job_id().empty())
      throw RequestError(RequestError::Code::kFailedPrecondition, "job " + id + ": frame " + std::to_string(*frame) +
                                                                      " was never rendered (the job ended first)");
    s = frame_status(*s, i);
  } else if (frame && s->settings().frame() != *frame) {
    throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " has no frame " + std::to_string(*frame));
  }
  header->frame_passes_done = s->frame_passes_done();
  header->final = true;  // ended durably: its image holds its whole film
  return s->id();
}

}  // namespace tessera
