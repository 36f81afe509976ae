// What the coordinator keeps across a crash, under its data folder:
//   coordinator.db         SQLite in WAL mode: every job's settings, owner, scene and state,
//                          and the run generation (task ids of one run never meet another's)
//   jobs/<id>/checkpoint   the job's film and frame plan, replaced atomically every few seconds
//   scenes/<hash>/         the unpacked scene of each live job (SceneStore)
// A job row is written when a submit is acknowledged and when the job ends; a job's end is
// recorded only once its final checkpoint is on disk, so a DONE row always has its whole
// film. Leases are not kept: they last seconds, a restart hands their tasks out again, and
// keeping them would cost a synchronous write per task. docs/architecture.md has the why.
#pragma once

#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/render/frame_plan.h"
#include "wire.h"

struct sqlite3;

namespace tessera {

struct StoredJob {
  std::string id, name, owner, scene_hash, main_file;
  int32_t priority = 0;
  uint64_t seq = 0;
  v1::RenderSettings settings;
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  double elapsed = 0;  // render seconds, once the job has ended
  // A sequence's frames (its frames' jobs have no rows: each is found by its checkpoint).
  std::vector<int> frames;
};

struct Checkpoint {
  PlanState state;
  Film film{Rect{}};
  double elapsed = 0;  // render seconds when it was taken
};

class JobStore {
 public:
  // Opens (or creates) <data_dir>/coordinator.db. Throws std::runtime_error.
  explicit JobStore(const std::string& data_dir);
  ~JobStore();
  JobStore(const JobStore&) = delete;
  JobStore& operator=(const JobStore&) = delete;

  // Counts this run: 1 for the first run on a data folder, then 2, ...
  uint64_t next_generation();
  // Durable when it returns (the submit is acknowledged after it). Throws std::runtime_error.
  void add(const StoredJob& job);
  void end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed);
  std::vector<StoredJob> jobs() const;  // in submission order
  void ping() const;                    // a query; throws std::runtime_error if it fails

  // Replaces the job's checkpoint: written to a temporary file, synced, renamed into place.
  // Throws std::runtime_error naming the file.
  void write_checkpoint(const std::string& id, const PlanState& state, const Film& film, double elapsed) const;
  // Nothing when the job has none; throws std::runtime_error when it is damaged. Without
  // `with_film` the film is left empty (its bytes are checksummed, not decoded).
  std::optional<Checkpoint> read_checkpoint(const std::string& id, bool with_film = true) const;
  std::string checkpoint_path(const std::string& id) const;

  // Test seam: runs between a checkpoint's temporary file being written and its rename.
  std::function<void()> before_checkpoint_rename;

 private:
  void exec(const char* sql) const;
  std::string dir_;
  sqlite3* db_ = nullptr;
  mutable std::mutex mu_;  // one statement at a time on db_
};

// A checkpoint's bytes, and back (the file format; exposed for tests and the fuzzer).
std::string encode_checkpoint(const PlanState& state, const Film& film, double elapsed);
// Throws std::runtime_error unless the bytes are a whole, undamaged checkpoint. Without
// `with_film`, Checkpoint::film stays empty.
Checkpoint decode_checkpoint(const std::string& bytes, bool with_film = true);

}  // namespace tessera
