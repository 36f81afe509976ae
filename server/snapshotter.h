// Progressive images and checkpoints. A snapshot copies a job's film (and, for a
// checkpoint, its plan's state) under the coordinator's lock: Snapshotter decides when one
// is due and takes it. SnapshotWriter writes it outside the lock, one writer per job
// (Job::write_mu), newest wins; then Snapshotter::written applies the outcome under the
// lock again (timings, errors, the film kept for the next copy).
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "server/counters.h"
#include "server/image_sink.h"
#include "server/job.h"
#include "server/job_store.h"

namespace tessera {

// A film to write outside the lock: the image, the checkpoint, or both. One taken after
// the job ended also records the end in the job database, once its checkpoint is on disk.
struct ImageSnapshot {
  std::shared_ptr<Job> job;
  std::unique_ptr<Film> film;  // null: nothing to write (an ended job's film was released)
  ImageMetadata meta;
  uint64_t seq = 0;     // Job::Snapshots::taken when it was taken
  uint64_t merges = 0;  // the film version copied
  bool image = true, checkpoint = true;
  PlanState plan;
  double elapsed = 0;
  bool ended = false;
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
};

struct SnapshotOutcome {
  enum Result { kSkipped, kWritten, kFailed };  // skipped: a newer one was written first
  Result image = kSkipped, checkpoint = kSkipped;
  std::string image_why, checkpoint_why;  // for clients: no server path
  double image_seconds = 0, checkpoint_seconds = 0;
  bool release_film = false;  // the job ended and disk holds all of it
};

class Snapshotter {
 public:
  // Writing takes at most 1/kWriteShare of the time: a large frame's images take long
  // enough to write that the intervals alone would let writing crowd out merging.
  static constexpr double kWriteShare = 20;
  Snapshotter(double image_interval, double checkpoint_interval)
      : image_interval_(image_interval), checkpoint_interval_(checkpoint_interval) {}

  ImageSnapshot take(const std::shared_ptr<Job>& job, bool image, bool checkpoint, double now) const;
  // After a merge into a live job: a snapshot when a progressive image (a frame pass more
  // than the last one, the interval passed) or a checkpoint (the interval passed) is due.
  std::optional<ImageSnapshot> after_merge(const std::shared_ptr<Job>& job, double now) const;
  // The final image and checkpoint of a job that just ended DONE.
  ImageSnapshot final_snapshot(const std::shared_ptr<Job>& job, double now) const;
  // A checkpoint of a live job that has merged since its last one (nullopt otherwise).
  std::optional<ImageSnapshot> checkpoint_if_changed(const std::shared_ptr<Job>& job, double now) const;
  // What the write did: timings and errors recorded, counted; the film kept for the next
  // snapshot of a live job, released for an ended one that disk holds whole.
  void written(ImageSnapshot& snap, const SnapshotOutcome& out, CoordinatorCounters& counters) const;

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
  SnapshotWriter(ImageSink& sink, JobStore& store, Hooks hooks) : sink_(sink), store_(store), hooks_(std::move(hooks)) {}
  // Writes what is newer than what is on disk; records an ended job's end once durable
  // (a DONE one's once its whole film is in a checkpoint). Never throws: failures are in
  // the outcome (and logged), and retried by the next snapshot.
  SnapshotOutcome write(ImageSnapshot& snap) const;
  // Whether the image on disk is the one to fetch: any image of a live job, the whole film
  // (version `merges`) of an ended one.
  static bool image_current(Job& job, bool live, uint64_t merges);
  // Reads it (as EXR and/or PNG) into `out` if it is current; false if not.
  bool read_image(Job& job, bool live, uint64_t merges, bool exr, bool png, v1::Image* out) const;

 private:
  ImageSink& sink_;
  JobStore& store_;
  Hooks hooks_;
};

// The message with the data folder's path replaced by "<data>": clients see it.
std::string without_dir(std::string message, const std::string& dir);

}  // namespace tessera
