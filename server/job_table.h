// Every job and sequence the coordinator knows, by id, and the one count of what the live
// ones weigh (Load). Plain data: the coordinator's lock guards it.
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "server/job.h"
#include "server/request_error.h"

namespace tessera {

// What a frame with these settings weighs against --max-live-pixels: its pixels, and with
// AOVs as many more as their sums' memory is worth in films (72 bytes a pixel: 1.8 films),
// with half-buffers a film more (the second plane of sums), and where it may trace light
// paths (--light-tracer on or auto) their splat sums' worth (32 bytes a pixel and plane).
inline int64_t live_pixels_of(const RenderSettings& s) {
  const auto films = [](int64_t bytes) {
    return (bytes + int64_t(sizeof(PixelSums)) - 1) / int64_t(sizeof(PixelSums));
  };
  const int64_t area = s.effective_window().area() * int64_t(s.sum_planes());
  int64_t pixels = area;
  if (s.aovs) pixels += films(s.effective_window().area() * int64_t(sizeof(AovSums)));
  if (s.light_tracer != RenderSettings::LightTracer::kOff) pixels += films(area * int64_t(sizeof(SplatSums)));
  return pixels;
}

// What the live work weighs, counted in one place for admission (one client's share),
// for starting frames (films in memory) and for autoscalers (what is left).
struct Load {
  int64_t live_pixels = 0;         // of every live frame's film (40 bytes a pixel)
  uint64_t tasks_ready = 0;        // ready tasks of live jobs, and each sequence's next frame's first pass
  uint64_t samples_remaining = 0;  // not merged yet, frames not started included
  // The same for one client (Load::of): its live jobs, a sequence counting as one.
  size_t client_jobs = 0;
  uint64_t client_scene_bytes = 0, client_samples_remaining = 0;
};

class JobTable {
 public:
  // 64 random bits in hex, used by no job or sequence: unguessable, so one client cannot
  // name another's job by counting.
  std::string new_id();
  uint64_t next_seq() { return next_seq_++; }
  void saw_seq(uint64_t seq) { next_seq_ = std::max(next_seq_, seq + 1); }  // restored jobs

  Job& add(std::shared_ptr<Job> job);
  Sequence& add(std::shared_ptr<Sequence> sequence);
  // A job (a still or a frame) or a sequence (its frames stay until removed too) is
  // forgotten: a deleted job's. Returns what was removed (null if none).
  std::shared_ptr<Job> remove_job(const std::string& id);
  std::shared_ptr<Sequence> remove_sequence(const std::string& id);
  // A job made anew (a requeue's, its plan read back) in place of the one with its id.
  void replace(std::shared_ptr<Job> job);
  // A frame that ended DONE, whose image and final checkpoint are on disk and whose end is
  // recorded, leaves memory: its sequence keeps its samples and who merged into it
  // (Sequence::left). Nothing happens to any other job. True if it left.
  bool let_go(const Job& frame);
  // A frame that left memory, named by its own id or by its sequence's and its number:
  // its sequence and index.
  struct LeftFrame {
    const Sequence* sequence = nullptr;
    size_t index = 0;
    std::string id() const { return sequence->frame_job_id(index); }
  };
  std::optional<LeftFrame> left_frame(const std::string& id, std::optional<int> frame = std::nullopt) const;

  // Whether `id` names a job, a sequence or a frame that left memory here (else it is
  // archived, archive.h, or unknown).
  bool knows(const std::string& id) const { return find_job(id) || find_sequence(id) || left_frame(id); }
  Job* find_job(const std::string& id) const;  // null if none
  Sequence* find_sequence(const std::string& id) const;
  std::shared_ptr<Sequence> shared_sequence(const std::string& id) const;
  std::shared_ptr<Job> shared(const std::string& id) const;
  // Throws RequestError (kNotFound) naming the id.
  Job& job(const std::string& id) const;
  // The owner of the job or sequence `id` that `requester` would `verb` (cancel, requeue,
  // ...): allowed to its owner, or to anyone with `any` (an admin, or no access tokens); a
  // frame changes only with its sequence. Throws RequestError (kNotFound,
  // kPermissionDenied, kFailedPrecondition for a frame) saying which.
  const std::string& check_change(const std::string& id, const std::string& requester, bool any,
                                  const char* verb) const;
  // Its parts: `owner`'s job refused to another `requester` unless `any`; a frame refused.
  static void check_owner(const std::string& id, const std::string& owner, const std::string& requester, bool any,
                          const char* verb);
  static RequestError frame_refusal(const std::string& id, const std::string& sequence, const char* verb);
  // The job of `id`, or of its frame `frame` when `id` is a sequence; throws RequestError
  // saying what is missing (a frame not named, not one of its frames, not started).
  Job& frame_job(const std::string& id, std::optional<int> frame) const;

  const std::map<std::string, std::shared_ptr<Job>>& jobs() const { return jobs_; }
  const std::map<std::string, std::shared_ptr<Sequence>>& sequences() const { return sequences_; }
  // Stills and sequences (not frames) in submission order: up to `n` ids after submission
  // number `after_seq`, and their count.
  std::vector<std::string> page(uint64_t after_seq, size_t n) const;
  size_t listed() const { return listed_.size(); }

  // The scenes every job and sequence names (ended ones' too: kept until deleted).
  std::set<std::string> scene_hashes() const;
  // Whether a job's folder name is a job's, a sequence's, or a frame's of a sequence here.
  bool names(const std::string& folder) const;

  // The whole load, and `owner`'s part of it; reservations count as live jobs.
  Load load(const std::string& owner = "") const;

  // Work admitted but not yet in the table (a submit's scene being checked, a requeue's
  // films being read: outside the lock), counted by load() as one live job of `owner` so
  // that requests racing each other cannot pass the limits together. Returns a token for
  // release(), which is called when the job is added or the request fails.
  uint64_t reserve(const std::string& owner, int64_t pixels, uint64_t samples, uint64_t scene_bytes);
  void release(uint64_t token) { reserved_.erase(token); }

 private:
  struct Reservation {
    std::string owner;
    int64_t pixels = 0;
    uint64_t samples = 0, scene_bytes = 0;
  };
  std::map<uint64_t, Reservation> reserved_;
  uint64_t next_reservation_ = 1;
  std::map<std::string, std::shared_ptr<Job>> jobs_;  // stills and frames
  std::map<std::string, std::shared_ptr<Sequence>> sequences_;
  std::map<uint64_t, std::string> listed_;  // stills and sequences by submission number
  uint64_t next_seq_ = 1;
  std::mt19937_64 ids_{std::random_device{}()};
};

}  // namespace tessera
