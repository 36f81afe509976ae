// Ended jobs leave memory, so that the coordinator's memory follows its live work and not
// its history. A job (a still, or a sequence with its frames) whose end is durable and whose
// image and final checkpoint hold its whole film (Job::compact) is archived:
//   1. due()       under the coordinator's lock, on the reaper's tick: its last status
//                  (JobStatus, no tiles) and which workers' results its tiles hold are taken,
//                  and it is marked `archiving`;
//   2. JobStore::archive, without the lock: its row keeps them (only an ended row takes
//                  them: a requeue or delete that got there first wins);
//   3. done()      under the lock: it leaves the JobTable, unless a requeue or delete began
//                  meanwhile.
// From then on what clients ask of it is read from its row (archived_status, archived_image);
// a worker found lying later flags it there (JobStore::flag_merged); a requeue brings it back
// into memory (Recovery::load_ended); a delete removes its row and files as for any job.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "server/image_stream.h"
#include "server/job_store.h"
#include "server/job_table.h"

namespace tessera {

struct Archival {
  std::string id, summary;
  std::vector<MergedInto> merged;
  // A DONE job's checkpoints (its own, or every frame's), removed once its row took it: its
  // images hold its films, and a DONE job is never requeued.
  std::vector<std::string> done_checkpoints;
  std::shared_ptr<Job> job;            // a still,
  std::shared_ptr<Sequence> sequence;  // or a sequence
};

class Archive {
 public:
  explicit Archive(JobTable& jobs) : jobs_(jobs) {}
  // Up to `limit` jobs ready to leave memory, each marked archiving.
  std::vector<Archival> due(double now, size_t limit = 64);
  // Its row took it (`archived`), or not: it leaves memory, or stays as it was.
  void done(const Archival& a, bool archived);
  // Whether it may leave memory now.
  static bool settled(const Job& j);
  static bool settled(const Sequence& s);

 private:
  JobTable& jobs_;
};

// What clients see of an archived job from its row: the summary, with the row's state,
// error and priority (a liar's flag or a priority set after it left memory).
// Without `with_frames` a sequence's frames are skipped unparsed (a list's: they were
// parsed, 100,000 a row, and dropped).
v1::JobStatus archived_status(const StoredJob& row, bool with_frames = true);
// The tile map GetJob shows, for an archived still or frame: as a compacted job's
// (FramePlan::tile_progress: every tile finished if the job is, else each at the passes the
// whole frame completed), from its settings.
void add_archived_tiles(v1::JobStatus& s, TileRange range = {});
// The same by id (a still, a sequence, or a frame of an archived sequence by its own id):
// nothing when no archived row names it.
std::optional<v1::JobStatus> archived_status(const JobStore& store, const std::string& id);
// The row of the archived job a request would change (`verb`: "delete", ...): nothing when
// no archived still or sequence is named `id`. Throws RequestError: another owner's job
// (kPermissionDenied, unless `any`), a frame of an archived sequence (kFailedPrecondition).
std::optional<StoredJob> archived_for_change(const JobStore& store, const std::string& id, const std::string& requester,
                                             bool any, const char* verb);
// An archived job's image (FetchImage): whose it is (a frame's own id) and its header;
// nothing when no archived row names it. Throws RequestError as JobTable::frame_job does
// (a sequence without a frame, a frame it lacks or never rendered).
std::optional<std::string> archived_image(const JobStore& store, const std::string& id, std::optional<int> frame,
                                          ImageStreamHeader* header);

}  // namespace tessera
