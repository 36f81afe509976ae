// A job: a scene, its frame plan, and what the coordinator knows of its progress.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "core/render/frame_plan.h"
#include "wire.h"

namespace tessera {

struct Job {
  Job(std::string id, const RenderSettings& settings) : id(std::move(id)), plan(settings) {}

  std::string id, name, scene_hash;
  // A frame of a sequence: the sequence's id and the frame's place in its list (empty for a
  // job of its own). Such a job has no row in the job database: its sequence has.
  std::string sequence;
  uint32_t frame_index = 0;
  std::string owner;         // the submitting token's name
  uint64_t scene_bytes = 0;  // its bundle's, counted against the owner's limit
  int32_t priority = 0;
  uint64_t seq = 0;  // submission order
  v1::RenderSettings settings_proto;
  FramePlan plan;
  std::vector<uint64_t> tile_lease;  // the live task id of each tile, 0 = none
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  std::string image_error;       // the last image write's failure; empty once one succeeds
  std::string checkpoint_error;  // the same for checkpoints
  std::set<uint64_t> failed_on;  // workers that could not render one of its tasks
  // Verification: the tiles each worker's results were merged into (a tile once per
  // pass), to render again if the worker is found lying; checks not yet decided (the job
  // ends only when none is left).
  std::map<uint64_t, std::vector<uint32_t>> merged_by;
  uint32_t pending_checks = 0;
  double submitted = 0, started = 0, finished_at = 0;

  // Progressive images: a snapshot is taken under the coordinator's lock, written outside.
  uint32_t image_frame_passes = 0;  // frame passes in the last image taken
  double last_image = -1e9;
  double image_write_seconds = 0;  // how long the last write took
  uint64_t image_seq = 0;          // snapshots taken
  // A film to copy the next snapshot into: its pages are already mapped, so the copy under
  // the coordinator's lock is a memory copy, not thousands of page faults (231 ms for a
  // fresh 1920x1080 film here, against a few for a reused one).
  std::unique_ptr<Film> spare_film;
  double last_checkpoint = 0;           // when the last snapshot with a checkpoint was taken
  double checkpoint_write_seconds = 0;  // how long the last checkpoint write took
  uint64_t checkpoint_merges = 0;       // the film version of the last checkpoint taken
  std::mutex write_mu;                  // one writer at a time; guards the five below
  uint64_t written_seq = 0;             // newest snapshot whose image was written (0: none yet)
  uint64_t written_merges = 0;          // the film version it holds
  uint64_t checkpoint_seq = 0;          // newest snapshot whose checkpoint was written
  uint64_t checkpoint_written_merges = 0;
  std::atomic<bool> end_recorded{false};  // the job database has its end (also read under mu_)

  bool live() const { return state == v1::JobStatus::QUEUED || state == v1::JobStatus::RUNNING; }
  // `now` for the elapsed time; `workers` with live leases on it.
  v1::JobStatus status(double now, uint32_t workers, bool with_tiles) const;
};

// A sequence: one job per frame, each made when the scheduler first needs its tiles (so a
// long sequence holds the films of only the frames being rendered), in frame order. Its
// frames are ordinary jobs to the scheduler, leases, checkpoints and images; the sequence
// keeps the order, the scene, the database row and the end.
struct Sequence {
  std::string id, name, owner, scene_hash;
  uint64_t scene_bytes = 0;
  int32_t priority = 0;
  uint64_t seq = 0;
  RenderSettings settings;  // every frame's, but for its number
  v1::RenderSettings settings_proto;
  std::vector<int> frames;
  std::vector<Job*> jobs;         // per frame: its job once started (the coordinator owns it)
  size_t next = 0;                // frames before this one have started
  uint32_t live_frames = 0;       // started and not ended
  uint32_t frames_done = 0;       // DONE
  uint64_t changes = 0;           // merges into its frames and frame ends: watchers wait on it
  std::unique_ptr<Job> prepared;  // frames[next]'s job, made outside the coordinator's lock
  // One frame's counts, as its plan will have them, before any frame has started.
  uint64_t frame_samples() const { return uint64_t(settings.effective_window().area()) * uint64_t(settings.spp); }
  uint32_t frame_tiles() const { return uint32_t(settings.tile_count()); }
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  double submitted = 0, started = 0, finished_at = 0;
  bool end_recording = false, end_recorded = false;

  bool live() const { return state == v1::JobStatus::QUEUED || state == v1::JobStatus::RUNNING; }
  std::string frame_job_id(size_t i) const { return id + "-f" + std::to_string(frames[i]); }
  uint64_t samples_merged() const;
  // `workers`: with live leases on each frame's job (by id).
  v1::JobStatus status(double now, const std::map<std::string, uint32_t>& workers, bool with_frames) const;
};

}  // namespace tessera
