// What the coordinator keeps across a crash. A seam: SqliteJobStore is the real one, under
// the data folder; MemoryJobStore keeps the same in memory for tests.
//   coordinator.db         SQLite in WAL mode: every job's settings, owner, scene and state,
//                          and the run generation (task ids of one run never meet another's)
//   jobs/<id>/checkpoint   the job's film and frame plan (checkpoint.h), replaced atomically
// A job row is written when a submit is acknowledged and when the job ends; a job's end is
// recorded only once its final checkpoint is on disk, so a DONE row always has its whole
// film. Leases are not kept: they last seconds, a restart hands their tasks out again, and
// keeping them would cost a synchronous write per task. docs/architecture.md has the why.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/util/mutex.h"
#include "server/checkpoint.h"
#include "server/job_meta.h"

struct sqlite3;

namespace tessera {

struct StoredJob {
  JobMeta meta;  // (scene_bytes is not stored: a restart counts the bundle again)
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  double elapsed = 0;  // render seconds, once the job has ended
  // A sequence's frames (its frames' jobs have no rows: each is found by its checkpoint).
  std::vector<int> frames;
};

// A checkpoint being written: CheckpointEncoder's pieces in order, then commit() puts it in
// place (durably, replacing the last one); destroyed before commit() it leaves nothing.
class CheckpointFile {
 public:
  virtual ~CheckpointFile() = default;
  virtual void append(const std::string& bytes) = 0;
  virtual void commit() = 0;
};

class JobStore {
 public:
  virtual ~JobStore() = default;
  // Counts this run: 1 for the first run on a data folder, then 2, ...
  virtual uint64_t next_generation() = 0;
  // Durable when it returns (the submit is acknowledged after it). Throws std::runtime_error.
  virtual void add(const StoredJob& job) = 0;
  virtual void end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) = 0;
  virtual std::vector<StoredJob> jobs() const = 0;  // in submission order
  virtual void ping() const = 0;                    // a query; throws std::runtime_error if it fails
  // A new checkpoint of the job. Throws std::runtime_error naming the file.
  virtual std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const = 0;
  // Reads the job's checkpoint into `plan` (checkpoint.h's read_checkpoint) and returns its
  // render seconds; nothing when the job has none. Throws std::runtime_error when it is
  // damaged or does not fit (the plan is then unusable). Without `with_film`, progress only.
  virtual std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan,
                                                bool with_film = true) const = 0;
  // Removes what a crash cut short (temporary files of the job's checkpoint and image).
  virtual void discard_partial_writes(const std::string&) const {}
};

class SqliteJobStore : public JobStore {
 public:
  // Opens (or creates) <data_dir>/coordinator.db. Throws std::runtime_error.
  explicit SqliteJobStore(const std::string& data_dir);
  ~SqliteJobStore() override;
  SqliteJobStore(const SqliteJobStore&) = delete;
  SqliteJobStore& operator=(const SqliteJobStore&) = delete;

  uint64_t next_generation() override;
  void add(const StoredJob& job) override;
  void end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) override;
  std::vector<StoredJob> jobs() const override;
  void ping() const override;
  // Written to a temporary file, synced, renamed into place.
  std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const override;
  std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan, bool with_film = true) const override;
  void discard_partial_writes(const std::string& id) const override;
  std::string checkpoint_path(const std::string& id) const;

  // Test seam: runs between a checkpoint's temporary file being written and its rename.
  std::function<void()> before_checkpoint_rename;

 private:
  void exec(const char* sql) const;
  std::string dir_;
  sqlite3* db_ = nullptr;
  mutable Mutex mu_;  // one statement at a time on db_
};

// The same in memory, for unit tests: no disk. Checkpoints are kept encoded, so a test
// can damage or remove one.
class MemoryJobStore : public JobStore {
 public:
  uint64_t next_generation() override;
  void add(const StoredJob& job) override;
  void end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) override;
  std::vector<StoredJob> jobs() const override;
  void ping() const override;
  std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const override;
  std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan, bool with_film = true) const override;
  std::optional<std::string> checkpoint_bytes(const std::string& id) const;
  void set_checkpoint_bytes(const std::string& id, std::optional<std::string> bytes);  // nullopt: remove
  bool fail_writes = false;  // every write throws, as a full disk would

 private:
  mutable Mutex mu_;
  uint64_t generation_ = 0;
  std::vector<StoredJob> rows_ TESSERA_GUARDED_BY(mu_);
  mutable std::map<std::string, std::string> checkpoints_ TESSERA_GUARDED_BY(mu_);
};

// The plan's whole checkpoint, band by band (tests, and plans written outside a coordinator).
void write_checkpoint(const JobStore& store, const std::string& id, const FramePlan& plan, double elapsed);

}  // namespace tessera
