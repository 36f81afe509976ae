// A job: a scene, its frame plan, and what the coordinator knows of its progress; a
// sequence: a job per frame. Plain data, guarded by the coordinator's lock. Their states
// change in one place, JobLifecycle.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/render/frame_plan.h"
#include "server/clock.h"
#include "server/frame_splats.h"
#include "server/job_meta.h"

namespace tessera {

// The tiles a status lists (with_tiles): [from, from + count) of the frame's, those that
// exist. GetJob lists all; /api/jobs/<id> a page at a time.
struct TileRange {
  uint32_t from = 0, count = std::numeric_limits<uint32_t>::max();
  uint32_t end(uint32_t tiles) const { return from >= tiles ? tiles : from + std::min(count, tiles - from); }
};
// The same for a sequence's frames (with_frames): /api/jobs/<id> a page at a time.
using FrameRange = TileRange;

struct Job {
  using State = v1::JobStatus::State;
  Job(JobMeta meta, const RenderSettings& settings, State state = v1::JobStatus::QUEUED)
      : meta(std::move(meta)),
        plan(settings),
        splats(settings, uint32_t(plan.tiles().size())),
        tile_lease(plan.tiles().size(), 0),
        tile_resets(plan.tiles().size(), 0),
        state_(state) {}

  JobMeta meta;
  const std::string& id() const { return meta.id; }
  // A frame of a sequence: the sequence's id and the frame's place in its list (empty for a
  // job of its own). Such a job has no row in the job database: its sequence has.
  std::string sequence;
  uint32_t frame_index = 0;
  FramePlan plan;
  FrameSplats splats;  // light paths' (frame_splats.h); none unless the frame traces them
  // Times results were taken back from the film (a liar's: Verifier::quarantine): a
  // checkpoint written across one is not kept.
  uint64_t resets = 0;
  std::vector<uint64_t> tile_lease;  // the live task id of each tile, 0 = none
  // Times each tile was taken back (as `resets`). A lease records its tile's count: a result
  // leased before the tile was taken back is refused, since it may build on what was taken
  // back (a run's base sums, an adaptive pass's mask from them).
  std::vector<uint32_t> tile_resets;
  // The most passes one task may run (a worker on a slow link asks for runs): halved when a
  // run's splats passed what a result may carry (ResultIntake::shorten_runs).
  uint32_t max_run = UINT32_MAX;
  // Tiles leased a second time at the frame's end (Dispatcher): tile -> that lease's task
  // id. Whichever result comes first is merged and both leases end.
  std::map<uint32_t, uint64_t> tile_backup;
  std::string error;
  std::string image_error;       // the last image write's failure; empty once one succeeds
  std::string checkpoint_error;  // the same for checkpoints
  // Workers (WorkerInfo::identity) that could not render one of its tasks: how often, and
  // until when they are not given its tasks (JobLifecycle::task_failed).
  struct Failures {
    uint32_t count = 0;
    double until = 0;
  };
  std::map<std::string, Failures> failed_on;
  bool resting(const std::string& worker, double now) const {
    const auto it = failed_on.find(worker);
    return it != failed_on.end() && now < it->second.until;
  }
  // While the job is live: its latest task failure and what would fail the job, shown in
  // its status (a farm of one worker waits for another; the user is told why).
  std::string failure_note;
  // Verification: the tiles each worker's results were merged into (a tile once per
  // pass), to render again if the worker is found lying; checks not yet decided (the job
  // ends only when none is left).
  std::map<uint64_t, std::vector<uint32_t>> merged_by;
  // Tiles of a CANCELLED or FAILED job that hold a worker's results who was quarantined
  // after the job ended: a requeue renders them again (JobControl::finish_requeue).
  std::set<uint32_t> tainted;
  uint32_t pending_checks = 0;
  double submitted = 0, started = 0, finished_at = 0;  // the coordinator's Clock
  double started_at = 0, ended_at = 0;                 // wall clock, for users (0: not known)

  // Snapshots (Snapshotter): progressive images and checkpoints, written band by band by
  // one writer at a time; requests while it writes are marked due and it writes again.
  struct Snapshots {
    uint32_t image_frame_passes = 0;  // frame passes in the last image begun
    double last_image = -1e9;
    double last_checkpoint = 0;      // when the last checkpoint was begun
    uint64_t checkpoint_merges = 0;  // the film version it began at
    double write_seconds = 0;        // how long the last write took
    bool writing = false;            // a writer is at work on this job
    bool image_due = false, checkpoint_due = false;
  } snaps;
  // What is on disk (an image's or checkpoint's film version: the film's at the write's
  // start, exact for an ended job, whose film no longer changes).
  struct Written {
    uint64_t images = 0, image_merges = 0;
    uint64_t checkpoints = 0, checkpoint_merges = 0;
  } written;
  std::atomic<bool> end_recorded{false};  // the job database has its end
  // JobControl: a requeue or delete of it is under way; it is being deleted (no image or
  // checkpoint of it is begun again). Archive: its row is taking its last status.
  bool changing = false, removed = false, archiving = false;

  State state() const { return state_; }
  bool live() const { return job_live(state_); }
  // What clients are told: an end only once it is durable (the final checkpoint and the
  // database record on disk; for a frame, its final checkpoint), RUNNING until then however
  // finished. A client that saw DONE can then never meet the job live again after a crash.
  bool ended_durably() const { return !live() && end_recorded; }
  State reported_state() const { return live() || end_recorded ? state_ : v1::JobStatus::RUNNING; }
  // `now` for the elapsed time; `workers` with live leases on it.
  v1::JobStatus status(double now, uint32_t workers, bool with_tiles, TileRange range = {}) const;
  // An ended job whose image and checkpoint hold its whole film keeps only its counts
  // (FramePlan::compact), no lease table, and each worker's merged tiles once (a liar
  // found later flags it by them).
  void compact();

 private:
  friend class JobLifecycle;  // the one writer of state_
  State state_;
};

// Whether none of these jobs has a snapshot writer at work (a delete, a requeue, a
// stopping coordinator wait for that).
inline bool none_writing(const std::vector<std::shared_ptr<Job>>& jobs) {
  for (const std::shared_ptr<Job>& j : jobs)
    if (j->snaps.writing) return false;
  return true;
}

// A sequence: one job per frame, each made when the scheduler first needs its tiles (so a
// long sequence holds the films of only the frames being rendered), in frame order. Its
// frames are ordinary jobs to the scheduler, leases, checkpoints and images; the sequence
// keeps the order, the scene, the database row and the end.
struct Sequence {
  using State = v1::JobStatus::State;
  Sequence(JobMeta meta, const RenderSettings& settings, std::vector<int> frames, State state = v1::JobStatus::QUEUED)
      : meta(std::move(meta)),
        settings(settings),
        frames(std::move(frames)),
        jobs(this->frames.size()),
        state_(state) {}

  JobMeta meta;
  const std::string& id() const { return meta.id; }
  RenderSettings settings;  // every frame's, but for its number
  std::vector<int> frames;
  std::vector<std::shared_ptr<Job>> jobs;  // per frame: its job once started (also in JobTable)
  // Frames that ended DONE and left memory (JobTable::let_go: their image and final
  // checkpoint on disk, their end recorded): the samples each merged, by frame index (sized
  // at the first to leave), and the workers whose results they hold, with how many tiles
  // (a liar found later flags the sequence). A long sequence holds only its live frames.
  std::vector<std::optional<uint64_t>> left;
  std::map<uint64_t, uint32_t> left_merged_by;
  size_t next = 0;                // frames before this one have started (later ones may have, after a restart)
  uint32_t frames_started = 0;    // jobs that are not null
  uint32_t live_frames = 0;       // started and not ended
  uint32_t frames_done = 0;       // DONE
  uint64_t changes = 0;           // merges into its frames and frame ends: watchers wait on it
  std::shared_ptr<Job> prepared;  // frames[next]'s job, made outside the coordinator's lock
  std::string error;
  double submitted = 0, started = 0, finished_at = 0;  // the coordinator's Clock
  double started_at = 0, ended_at = 0;                 // wall clock, for users (0: not known)
  bool end_recording = false, end_recorded = false;
  bool changing = false, removed = false, archiving = false;  // as Job's

  // One frame's counts, as its plan will have them, before any frame has started.
  uint64_t frame_samples() const { return uint64_t(settings.effective_window().area()) * uint64_t(settings.spp); }
  uint32_t frame_tiles() const { return uint32_t(settings.tile_count()); }
  std::string frame_job_id(size_t i) const { return frame_id(meta.id, frames[i]); }
  static std::string frame_id(const std::string& sequence, int frame) {
    return sequence + "-f" + std::to_string(frame);
  }
  // The parts of a frame's own id (frame_id): its sequence's id and the frame; nothing if
  // `id` is not one.
  static std::optional<std::pair<std::string, int>> split_frame_id(const std::string& id);
  bool frame_left(size_t i) const { return i < left.size() && left[i].has_value(); }
  bool frame_started(size_t i) const { return jobs[i] || frame_left(i); }
  uint64_t samples_merged() const;

  State state() const { return state_; }
  bool live() const { return job_live(state_); }
  bool ended_durably() const { return !live() && end_recorded; }  // as Job's
  State reported_state() const { return live() || end_recorded ? state_ : v1::JobStatus::RUNNING; }
  // `workers`: distinct workers with live leases on any of its frames.
  // With frames, those in `range` (and current_frame_job, of them all).
  v1::JobStatus status(double now, uint32_t workers, bool with_frames, FrameRange range = {}) const;

 private:
  friend class JobLifecycle;
  State state_;
};

}  // namespace tessera
