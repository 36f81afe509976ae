// A coordinator started on a data folder an earlier run used takes up every job where its
// last checkpoint left it. An ended job comes back with its counts and image (no film in
// memory); a live one with its plan restored from the checkpoint (FramePlan::restore; a
// damaged or missing checkpoint means it starts over) and its scene checked again from its
// bundle (a lost scene fails it). A sequence's frames are found by their checkpoints: one
// that has none had not started, or starts again. Jobs found done, or unable to go on, end
// here, their images and database rows written through the Effects.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "server/job_lifecycle.h"
#include "server/job_store.h"
#include "server/snapshotter.h"

namespace tessera {

class Recovery {
 public:
  struct Parts {
    JobStore& store;
    JobTable& jobs;
    JobLifecycle& lifecycle;
    const Snapshotter& snapshots;
    CoordinatorCounters& counters;
    // Makes a scene kept by the earlier run usable again; returns its bundle's bytes.
    // Throws (naming the problem) when it is missing or damaged.
    std::function<uint64_t(const std::string& hash)> restore_scene;
    // The frame passes the job's final image on disk holds (its "frame_passes" attribute,
    // where its "final" one says it was written at the job's end: a job waiting on its
    // checks writes an image of every pass before, not denoised); nothing where it has
    // none or it cannot be read. Unset: never known (every done frame
    // of a live sequence is then written again, its film read for it).
    std::function<std::optional<uint32_t>(const std::string& job)> image_passes = {};
  };
  explicit Recovery(Parts parts) : p_(std::move(parts)) {}
  // Every row but the archived ones (archive.h: they stay on disk until asked for).
  void restore(double now, Effects& fx);
  // An ended job's row as it is on disk, not yet in any table: counts from its checkpoints,
  // no film; a sequence with its frames that did not end DONE (those that did have left
  // memory: Sequence::left). A start's ended rows, and an archived job a requeue brings
  // back. Reads from disk: call it without the coordinator's lock. Throws WireError for
  // settings that cannot be read (only a damaged database has them).
  struct Ended {
    std::shared_ptr<Job> job;            // a still,
    std::shared_ptr<Sequence> sequence;  // or a sequence
  };
  static Ended load_ended(const StoredJob& row, const JobStore& store, double now);
  // Rows restore() could not take up (settings or frames a damaged database cannot give
  // back): not in memory, their files and scenes kept (a start's clean-up removed them).
  const std::vector<StoredJob>& kept() const { return kept_; }
  static void adopt(JobTable& jobs, const Ended& e);  // into the table
  // A job whose plan was read back from its checkpoint goes on (a restart's, a requeue's):
  // live again, RUNNING if it rendered before, its checkpoint counted as on disk.
  static void resume(JobLifecycle& lifecycle, Job& job, double elapsed, bool checkpointed, double now);

 private:
  void keep(const StoredJob& row, const std::string& why, Effects& fx);
  void restore_job(const StoredJob& row, double now, Effects& fx);
  void with_final_image(const StoredJob& row, std::shared_ptr<Job>& job, double now) const;
  void restore_sequence(const StoredJob& row, double now, Effects& fx);
  // An ended job as it is on disk: image and checkpoint written, end recorded, no film.
  static void as_ended(Job& job, double now, double elapsed);

  Parts p_;
  std::vector<StoredJob> kept_;
};

}  // namespace tessera
