// What clients see of jobs: a job's or a sequence's status (JobStatus, with the workers
// holding leases on it) and the list of every job in submission order, frames inside their
// sequences. Runs under the coordinator's lock.
#pragma once

#include <string>
#include <vector>

#include "server/job_table.h"
#include "server/lease_table.h"

namespace tessera {

// What a watcher waits on: a job's (or sequence's) samples, a version that changes with
// every merge into it (a sequence's: O(1) however long it is), and whether its end is
// durable (what clients are told; Job::reported_state). Throws RequestError (kNotFound).
struct JobProgress {
  uint64_t samples = 0, version = 0;
  bool ended = false;
  bool operator==(const JobProgress&) const = default;
};
JobProgress job_progress(const JobTable& jobs, const std::string& id);
// What clients see of a frame that left memory (JobTable::let_go): DONE, its counts.
v1::JobStatus left_frame_status(const Sequence& s, size_t i);

// What is left to render, for autoscalers (Kubernetes HPA, Slurm scripts): tasks ready
// and leased, samples not yet merged (an upper bound with adaptive sampling), and those
// samples in core-seconds at the render speed per thread measured lately.
struct QueueDepth {
  uint64_t tasks_ready = 0, tasks_leased = 0, samples_remaining = 0;
  double samples_per_thread_second = 0;  // measured; kAssumedThreadSpeed before any result
  double core_seconds_remaining = 0;
  static constexpr double kAssumedThreadSpeed = 1e6;  // samples/s a thread, about ours on CS184 scenes
};
QueueDepth queue_depth(const JobTable& jobs, const LeaseTable& leases, double thread_speed);

// A watcher's next message (JobStatus.frames_changed_only): keeps in `s` only the frames
// that differ from `sent` (the frames the stream sent last, serialized), and makes `sent`
// the new list. The first message of a stream (`sent` empty) keeps every frame, as does one
// whose frame count changed.
void keep_changed_frames(v1::JobStatus& s, std::vector<std::string>& sent);

// Throws RequestError (kNotFound) for an unknown id. A sequence's frames: those in
// `frames` (every one by default).
v1::JobStatus job_status(const JobTable& jobs, const LeaseTable& leases, const std::string& id, bool with_tiles,
                         double now, TileRange range = {}, FrameRange frames = {});
// A sequence's status with every frame (an archived one's) cut to the frames in `range`,
// its current_frame_job set from them all first.
void page_frames(v1::JobStatus& s, FrameRange range);
// As a list shows it: no tiles, and a sequence's frames counted (frames_done, frames_total)
// but not listed (a list of sequences of 100,000 frames each was 12 MB a sequence, and the
// live page polls it every second; GetJob and WatchJob have them).
v1::JobStatus job_summary(const JobTable& jobs, const LeaseTable& leases, const std::string& id, double now);
std::vector<v1::JobStatus> job_list(const JobTable& jobs, const LeaseTable& leases, double now);
// A page of the list (ListJobsRequest): at most kMaxPage jobs, after the submission number
// its page_token gives. Throws RequestError (kInvalidArgument) for a token never given.
constexpr uint32_t kMaxPage = 1000;
uint64_t page_after(const std::string& page_token);

}  // namespace tessera
