#include "server/job_table.h"

#include <algorithm>
#include <cstdio>
#include <tuple>

#include "core/util/invariant.h"
#include "core/util/saturating.h"
#include "server/request_error.h"

namespace tessera {

std::string JobTable::new_id() {
  char buf[17];
  do std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)ids_());
  while (jobs_.count(buf) || sequences_.count(buf));
  return buf;
}

Job& JobTable::add(std::shared_ptr<Job> job) {
  TESSERA_INVARIANT(job && !jobs_.count(job->id()), "a job added twice");
  Job& j = *job;
  if (j.sequence.empty()) listed_[j.meta.seq] = j.id();
  jobs_[j.id()] = std::move(job);
  return j;
}

Sequence& JobTable::add(std::shared_ptr<Sequence> sequence) {
  TESSERA_INVARIANT(sequence && !sequences_.count(sequence->id()), "a sequence added twice");
  Sequence& s = *sequence;
  listed_[s.meta.seq] = s.id();
  sequences_[s.id()] = std::move(sequence);
  return s;
}

std::shared_ptr<Job> JobTable::remove_job(const std::string& id) {
  auto it = jobs_.find(id);
  if (it == jobs_.end()) return nullptr;
  std::shared_ptr<Job> job = std::move(it->second);
  jobs_.erase(it);
  if (job->sequence.empty()) listed_.erase(job->meta.seq);
  return job;
}

std::shared_ptr<Sequence> JobTable::remove_sequence(const std::string& id) {
  auto it = sequences_.find(id);
  if (it == sequences_.end()) return nullptr;
  std::shared_ptr<Sequence> s = std::move(it->second);
  sequences_.erase(it);
  listed_.erase(s->meta.seq);
  return s;
}

void JobTable::replace(std::shared_ptr<Job> job) {
  auto it = jobs_.find(job->id());
  TESSERA_INVARIANT(it != jobs_.end(), "job " + job->id() + " replaced but never added");
  it->second = std::move(job);
}

bool JobTable::let_go(const Job& frame) {
  if (frame.sequence.empty() || frame.state() != v1::JobStatus::DONE || !frame.end_recorded || frame.plan.has_film())
    return false;
  Sequence* s = find_sequence(frame.sequence);
  const size_t i = frame.frame_index;
  if (!s || i >= s->jobs.size() || s->jobs[i].get() != &frame) return false;
  if (s->left.empty()) s->left.resize(s->frames.size());
  s->left[i] = frame.plan.samples_merged();
  for (const auto& [worker, tiles] : frame.merged_by) s->left_merged_by[worker] += uint32_t(tiles.size());
  const std::string id = frame.id();
  s->jobs[i].reset();  // (frame is gone after these two)
  jobs_.erase(id);
  return true;
}

std::optional<JobTable::LeftFrame> JobTable::left_frame(const std::string& id, std::optional<int> frame) const {
  const Sequence* s = find_sequence(id);
  if (!s && !frame) {  // a frame's own id
    const auto parts = Sequence::split_frame_id(id);
    if (!parts) return std::nullopt;
    s = find_sequence(parts->first);
    frame = parts->second;
  }
  if (!s || !frame) return std::nullopt;
  const auto at = std::find(s->frames.begin(), s->frames.end(), *frame);
  const size_t i = size_t(at - s->frames.begin());
  if (at == s->frames.end() || !s->frame_left(i)) return std::nullopt;
  return LeftFrame{s, i};
}

std::vector<std::string> JobTable::page(uint64_t after_seq, size_t n) const {
  std::vector<std::string> out;
  for (auto it = listed_.upper_bound(after_seq); it != listed_.end() && out.size() < n; ++it) out.push_back(it->second);
  return out;
}

Job* JobTable::find_job(const std::string& id) const {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : it->second.get();
}

Sequence* JobTable::find_sequence(const std::string& id) const {
  auto it = sequences_.find(id);
  return it == sequences_.end() ? nullptr : it->second.get();
}

std::shared_ptr<Sequence> JobTable::shared_sequence(const std::string& id) const {
  auto it = sequences_.find(id);
  return it == sequences_.end() ? nullptr : it->second;
}

std::shared_ptr<Job> JobTable::shared(const std::string& id) const {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : it->second;
}

Job& JobTable::job(const std::string& id) const {
  Job* j = find_job(id);
  if (!j) throw RequestError(RequestError::Code::kNotFound, "no job '" + id + "'");
  return *j;
}

void JobTable::check_owner(const std::string& id, const std::string& owner, const std::string& requester, bool any,
                           const char* verb) {
  if (!any && owner != requester)
    throw RequestError(RequestError::Code::kPermissionDenied,
                       "job " + id + " belongs to '" + owner + "': a client may " + verb + " only its own jobs");
}

RequestError JobTable::frame_refusal(const std::string& id, const std::string& sequence, const char* verb) {
  return RequestError(RequestError::Code::kFailedPrecondition,
                      "job " + id + " is a frame of sequence " + sequence + ": " + verb + " the sequence");
}

const std::string& JobTable::check_change(const std::string& id, const std::string& requester, bool any,
                                          const char* verb) const {
  if (const Sequence* s = find_sequence(id)) {
    check_owner(id, s->meta.owner, requester, any, verb);
    return s->meta.owner;
  }
  const Job& j = job(id);
  check_owner(id, j.meta.owner, requester, any, verb);
  if (!j.sequence.empty()) throw frame_refusal(id, j.sequence, verb);
  return j.meta.owner;
}

Job& JobTable::frame_job(const std::string& id, std::optional<int> frame) const {
  const Sequence* s = find_sequence(id);
  if (!s) {
    Job& j = job(id);
    if (frame && j.plan.settings().frame != frame)
      throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " has no frame " + std::to_string(*frame));
    return j;
  }
  if (!frame)
    throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " is a sequence of " +
                                                                 std::to_string(s->frames.size()) +
                                                                 " frames: name one (fetch --frame N, or --all)");
  const auto at = std::find(s->frames.begin(), s->frames.end(), *frame);
  if (at == s->frames.end())
    throw RequestError(RequestError::Code::kNotFound, "job " + id + " has no frame " + std::to_string(*frame));
  Job* j = s->jobs[size_t(at - s->frames.begin())].get();
  if (!j)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + id + ": frame " + std::to_string(*frame) +
                           (s->live() ? " has not started yet" : " was never rendered (the job ended first)"));
  return *j;
}

std::set<std::string> JobTable::scene_hashes() const {
  std::set<std::string> out;
  for (const auto& [id, j] : jobs_) out.insert(j->meta.scene_hash);
  for (const auto& [id, s] : sequences_) out.insert(s->meta.scene_hash);
  return out;
}

bool JobTable::names(const std::string& folder) const {
  if (jobs_.count(folder) || sequences_.count(folder)) return true;
  const auto parts = Sequence::split_frame_id(folder);
  return parts && sequences_.count(parts->first);
}

Load JobTable::load(const std::string& owner) const {
  Load l;
  for (const auto& [id, j] : jobs_) {
    if (!j->live()) continue;
    const uint64_t left = j->plan.samples_left();
    l.live_pixels += live_pixels_of(j->plan.settings());
    l.tasks_ready += j->plan.ready();
    l.samples_remaining += left;
    if (j->meta.owner != owner) continue;
    l.client_samples_remaining += left;
    if (!j->sequence.empty()) continue;  // its sequence counts as the job
    ++l.client_jobs;
    l.client_scene_bytes += j->meta.scene_bytes;
  }
  for (const auto& [id, s] : sequences_) {
    if (!s->live()) continue;
    // A frame made ahead (at submit, or on the reaper's tick) holds its films already.
    if (s->prepared) l.live_pixels += live_pixels_of(s->settings);
    // Frames not started: after a restart these need not be the ones past `next`.
    const uint64_t unstarted = saturating_mul(s->frame_samples(), s->frames.size() - s->frames_started);
    l.samples_remaining = saturating_add(l.samples_remaining, unstarted);
    if (s->next < s->frames.size()) l.tasks_ready += s->frame_tiles();  // the next frame's first pass
    if (s->meta.owner != owner) continue;
    ++l.client_jobs;
    l.client_scene_bytes += s->meta.scene_bytes;
    l.client_samples_remaining = saturating_add(l.client_samples_remaining, unstarted);
  }
  for (const auto& [token, r] : reserved_) {
    l.live_pixels += r.pixels;
    l.samples_remaining = saturating_add(l.samples_remaining, r.samples);
    if (r.owner != owner) continue;
    ++l.client_jobs;
    l.client_scene_bytes += r.scene_bytes;
    l.client_samples_remaining = saturating_add(l.client_samples_remaining, r.samples);
  }
  return l;
}

uint64_t JobTable::reserve(const std::string& owner, int64_t pixels, uint64_t samples, uint64_t scene_bytes) {
  const uint64_t token = next_reservation_++;
  reserved_[token] = {owner, pixels, samples, scene_bytes};
  return token;
}

}  // namespace tessera
