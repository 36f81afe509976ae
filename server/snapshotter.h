// Progressive images and checkpoints, in bounded memory. A job's film is never copied
// whole: its writer copies one band (a row of tiles, FramePlan::copy_band) at a time under
// the coordinator's lock and encodes it outside, into the image (ImageSink) and the
// checkpoint (JobStore) at once. Each job has at most one writer: a request while it
// writes only marks what is due (Snapshotter::request), and the writer looks again before
// it stops, so a snapshot that cannot keep up is merged into the next, never queued.
//
// Snapshotter runs under the coordinator's lock: when images and checkpoints are due,
// what a write is to do (next), and its outcome (written). SnapshotWriter does the write
// without the lock.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "server/checkpoint.h"
#include "server/counters.h"
#include "server/image_sink.h"
#include "server/job.h"
#include "server/job_store.h"

namespace tessera {

// What one write of a job is to do, decided under the lock as it begins.
struct SnapshotPlan {
  bool image = false, checkpoint = false;  // neither: nothing is due, the writer stops
  bool ended = false;                      // the job had ended: its film no longer changes
  uint64_t merges = 0;                     // the film version as it began
  uint64_t resets = 0;                     // Job::resets as it began
  bool checkpoint_on_disk = false;         // a checkpoint of that version is on disk already
  double elapsed = 0;                      // render seconds
  ImageMetadata meta;
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
};

struct SnapshotOutcome {
  enum Result { kSkipped, kWritten, kFailed };  // skipped: the film was gone
  Result image = kSkipped, checkpoint = kSkipped;
  std::string image_why, checkpoint_why;  // for clients: no server path
  double seconds = 0;
  bool end_recorded = false;  // this write recorded the job's end
};

class Snapshotter {
 public:
  // Writing takes at most 1/kWriteShare of the time: a large frame's images take long
  // enough to write that the intervals alone would let writing crowd out merging.
  static constexpr double kWriteShare = 20;
  Snapshotter(double image_interval, double checkpoint_interval)
      : image_interval_(image_interval), checkpoint_interval_(checkpoint_interval) {}

  // Marks an image and/or a checkpoint of the job due. True: no write of it is under way,
  // and the caller is now its writer (it calls Coordinator::write after the lock). False:
  // the writer at work takes it too.
  bool request(Job& job, bool image, bool checkpoint) const;
  // After a merge into a live job: a progressive image (a frame pass more than the last
  // one, the interval passed) and/or a checkpoint (the interval passed) requested when due.
  bool after_merge(Job& job, double now) const;
  // The final image and checkpoint of a job that has ended.
  bool final_snapshot(Job& job, double now) const;
  // A checkpoint of a live job that has merged since its last one.
  bool checkpoint_if_changed(Job& job, double now) const;
  // The writer's next write: what is due, now no longer due. Nothing due: the writer stops.
  SnapshotPlan next(Job& job, double now) const;
  // Whether the image on disk is the one to fetch: any image of a live job, the whole film
  // (version `merges`) of an ended one.
  static bool image_current(const Job& job, bool live, uint64_t merges);
  // A write's outcome: what is on disk, timings, errors, counts; an ended job that disk
  // holds whole gives its film up.
  void written(Job& job, const SnapshotPlan& plan, const SnapshotOutcome& out, CoordinatorCounters& counters) const;

 private:
  double image_interval_, checkpoint_interval_;
};

class SnapshotWriter {
 public:
  struct Hooks {
    std::function<void(const std::string& hash)> release_scene;  // a job's end is recorded: its use ends
    std::function<void()> before_image_write;                    // a test seam
    std::string data_dir;                                        // named "<data>" in messages
  };
  SnapshotWriter(ImageSink& sink, JobStore& store, Hooks hooks)
      : sink_(sink), store_(store), hooks_(std::move(hooks)) {}
  // Writes the plan's image and/or checkpoint, band by band through `copy_band` (which
  // takes the coordinator's lock for one band, copies its film and splat rows, and says
  // false once the film is gone). `locked` runs a step under that lock: a checkpoint of a
  // frame with splats freezes them after the bands (frame_splats.h) and copies their rows
  // band by band; a checkpoint begun before results were taken back (Job::resets) is not
  // kept. Without `locked` (tests), no splats are written.
  // Records an ended job's end once durable (a DONE one's once its whole film is in a
  // checkpoint). Never throws: failures are in the outcome (and logged).
  SnapshotOutcome write(Job& job, const SnapshotPlan& plan,
                        const std::function<bool(uint32_t band, BandCopy* out)>& copy_band,
                        const std::function<void(const std::function<void()>&)>& locked = {}) const;
  // Records a sequence's end (its frames' are on disk) and drops its use of its scene;
  // false (logged) when the record failed.
  bool record_end(const RowEnd& row, const std::string& scene_hash) const;

 private:
  ImageSink& sink_;
  JobStore& store_;
  // The checkpoint's splat section (under `locked`'s steps); false when it cannot be kept.
  bool write_splats(Job& job, const SnapshotPlan& plan, CheckpointEncoder& encoder,
                    const std::function<void(const std::function<void()>&)>& locked) const;
  Hooks hooks_;
};

// The message with the data folder's path replaced by "<data>": clients see it.
std::string without_dir(std::string message, const std::string& dir);

}  // namespace tessera
