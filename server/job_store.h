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

#include <array>
#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/util/mutex.h"
#include "server/checkpoint.h"
#include "server/data_marker.h"
#include "server/events.h"
#include "server/job_meta.h"

struct sqlite3;

namespace tessera {

struct StoredJob {
  JobMeta meta;  // (scene_bytes is not stored: a restart counts the bundle again)
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  double elapsed = 0;   // render seconds, once the job has ended
  double ended_at = 0;  // when its end was recorded (JobStore::wall), 0 while live
  // A sequence's frames (its frames' jobs have no rows: each is found by its checkpoint).
  std::vector<int> frames;
  // Archived (archive.h: an ended job kept only here): its last status, a JobStatus without
  // tiles whose state, error and priority the columns above override. Read by job() and
  // page(); empty for a job still in memory.
  std::string summary;
  // jobs() at a start: why the row's settings or frames could not be read (a damaged
  // database). Such a job is not taken up; its files and scene are kept (Recovery::kept).
  std::string unreadable;
};

// How many tiles of an archived job hold one worker's results: a worker found lying later
// flags the job (JobStore::flag_merged).
struct MergedInto {
  uint64_t worker = 0;
  uint32_t tiles = 0;
};

// A job row's end, to write (again: an ended job's error changed when a liar's tiles are in it).
struct RowEnd {
  std::string id;
  v1::JobStatus::State state = v1::JobStatus::QUEUED;
  std::string error;
  double elapsed = 0;
};

// A worker's own credential (credentials.h), kept so that a restart still knows it and
// its quarantine. Only the credential's SHA-256 is kept.
struct StoredCredential {
  std::string name;           // the worker's, unique
  std::string digest;         // SHA-256 of the credential, raw
  std::string enroller;       // the enrolment token's name
  double created = 0;         // wall seconds (JobStore::wall)
  double quarantined_at = 0;  // 0: not quarantined
  std::string why;            // the quarantine's reason
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
  // The jobs to take up at start, in submission order: every row but the archived ones.
  virtual std::vector<StoredJob> jobs() const = 0;

  // ---- archived jobs (archive.h) ----
  // The ended job `id` leaves memory: its last status (StoredJob::summary) and whose results
  // its tiles hold. Only an ended row takes it; false when none did (the job was requeued or
  // deleted meanwhile). Throws std::runtime_error.
  virtual bool archive(const std::string& id, const std::string& summary, const std::vector<MergedInto>& merged) = 0;
  // One row, with its summary if archived; nothing if there is no such row.
  virtual std::optional<StoredJob> job(const std::string& id) const = 0;
  // Up to `n` rows after submission number `after_seq`, in submission order (summaries of
  // archived ones included), and how many rows there are. For lists: a sequence's `frames`
  // may be left empty (its summary counts them; reading 100,000 frames a row for each of a
  // list's rows was most of a list's time).
  virtual std::vector<StoredJob> page(uint64_t after_seq, size_t n) const = 0;
  virtual uint64_t count() const = 0;
  // The `n` rows submitted last, in submission order (summaries included; `frames` as page's).
  virtual std::vector<StoredJob> newest(size_t n) const = 0;
  // Archived jobs' ids and scenes (what a start must keep on disk), and their number by state.
  virtual std::vector<std::pair<std::string, std::string>> archived_names() const = 0;
  virtual std::array<uint64_t, 5> archived_states() const = 0;
  // Worker `worker` was found lying: every archived job whose tiles hold its results (but
  // those in `skip`, flagged in memory) gets message(tiles, is a sequence) added to its error,
  // and the worker's records go. Throws std::runtime_error.
  virtual void flag_merged(uint64_t worker, const std::set<std::string>& skip,
                           const std::function<std::string(uint32_t tiles, bool sequence)>& message) = 0;
  // At start: the records of which worker merged into what (worker ids of an earlier run
  // mean nothing now).
  virtual void forget_merges() = 0;

  // The job's row is gone (durably) when it returns, then the checkpoints of the jobs named
  // in `with_checkpoints` (the job's own, a sequence's frames'). Throws std::runtime_error.
  virtual void remove(const std::string& id, const std::vector<std::string>& with_checkpoints) = 0;
  // An ended job is live again (QUEUED, no error, no end time): durable when it returns, so
  // a restart takes it up from its checkpoint. Throws std::runtime_error.
  virtual void requeue(const std::string& id) = 0;
  virtual void set_priority(const std::string& id, int32_t priority) = 0;
  // How many rows name this scene.
  virtual size_t scene_users(const std::string& hash) const = 0;
  // Ended jobs whose end was recorded more than `age` seconds ago, oldest first, at most
  // `limit` of them (retention: --keep-ended).
  virtual std::vector<std::string> ended_before(double age, size_t limit) const = 0;
  virtual void ping() const = 0;  // a query; throws std::runtime_error if it fails

  // ---- workers' credentials (credentials.h) ----
  // Inserts or replaces (by name); durable when it returns. Throws std::runtime_error.
  virtual void put_credential(const StoredCredential& c) = 0;
  virtual void remove_credentials(const std::vector<std::string>& names) = 0;
  virtual std::vector<StoredCredential> credentials() const = 0;

  // ---- events (events.h) ----
  // Gives each event its id and keeps it; only the newest kMaxEvents stay. Throws
  // std::runtime_error.
  virtual void append_events(std::vector<Event>& events) = 0;
  // Events with ids after `after`, oldest first: the first `limit` of them, or with `newest`
  // the last `limit`. Of one job when `job` is given (a sequence's include its frames').
  virtual std::vector<Event> events(const std::string& job, uint64_t after, size_t limit, bool newest) const = 0;
  // A new checkpoint of the job. Throws std::runtime_error naming the file.
  virtual std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const = 0;
  // Reads the job's checkpoint into `plan` (checkpoint.h's read_checkpoint) and returns its
  // render seconds; nothing when the job has none. Throws std::runtime_error when it is
  // damaged or does not fit (the plan is then unusable). Without `with_film`, progress only;
  // with it, the frame's splats into `splats` when given.
  virtual std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan, bool with_film = true,
                                                FrameSplats* splats = nullptr) const = 0;
  // Removes what a crash cut short (temporary files of the job's checkpoint and image).
  virtual void discard_partial_writes(const std::string&) const {}
  // Removes the job's checkpoint (an archived DONE job's: its image holds the film, and it
  // is never requeued). Errors are ignored: a delete removes it later.
  virtual void discard_checkpoint(const std::string& id) = 0;

  // The wall clock an end is stamped with (seconds since 1970): a seam for retention tests.
  std::function<double()> wall = [] {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  };
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
  bool archive(const std::string& id, const std::string& summary, const std::vector<MergedInto>& merged) override;
  std::optional<StoredJob> job(const std::string& id) const override;
  std::vector<StoredJob> page(uint64_t after_seq, size_t n) const override;
  uint64_t count() const override;
  std::vector<StoredJob> newest(size_t n) const override;
  std::vector<std::pair<std::string, std::string>> archived_names() const override;
  std::array<uint64_t, 5> archived_states() const override;
  void flag_merged(uint64_t worker, const std::set<std::string>& skip,
                   const std::function<std::string(uint32_t, bool)>& message) override;
  void forget_merges() override;
  void remove(const std::string& id, const std::vector<std::string>& with_checkpoints) override;
  void requeue(const std::string& id) override;
  void set_priority(const std::string& id, int32_t priority) override;
  size_t scene_users(const std::string& hash) const override;
  std::vector<std::string> ended_before(double age, size_t limit) const override;
  void ping() const override;
  void put_credential(const StoredCredential& c) override;  // (job_store_credentials.cc)
  void remove_credentials(const std::vector<std::string>& names) override;
  std::vector<StoredCredential> credentials() const override;
  void append_events(std::vector<Event>& events) override;  // (job_store_events.cc)
  std::vector<Event> events(const std::string& job, uint64_t after, size_t limit, bool newest) const override;
  // Written to a temporary file, synced, renamed into place.
  std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const override;
  std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan, bool with_film = true,
                                        FrameSplats* splats = nullptr) const override;
  void discard_partial_writes(const std::string& id) const override;
  void discard_checkpoint(const std::string& id) override;
  std::string checkpoint_path(const std::string& id) const;

  // Test seams: runs between a checkpoint's temporary file being written and its rename;
  // after remove()'s and requeue()'s row change, before anything else.
  std::function<void()> before_checkpoint_rename, after_row_commit;

 private:
  void create_tables();
  void exec(const char* sql) const;
  // Runs body() as one transaction (BEGIN IMMEDIATE ... COMMIT), rolled back if it throws;
  // returns what body() returns. mu_ held.
  template <typename Body>
  auto transaction(Body&& body) const {
    exec("BEGIN IMMEDIATE");
    try {
      if constexpr (std::is_void_v<decltype(body())>) {
        body();
        exec("COMMIT");
      } else {
        auto result = body();
        exec("COMMIT");
        return result;
      }
    } catch (...) {
      rollback();
      throw;
    }
  }
  void rollback() const;
  std::string dir_;
  DataFolderLock lock_;  // (before the database is opened; let go after it is closed)
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
  bool archive(const std::string& id, const std::string& summary, const std::vector<MergedInto>& merged) override;
  std::optional<StoredJob> job(const std::string& id) const override;
  std::vector<StoredJob> page(uint64_t after_seq, size_t n) const override;
  uint64_t count() const override;
  std::vector<StoredJob> newest(size_t n) const override;
  std::vector<std::pair<std::string, std::string>> archived_names() const override;
  std::array<uint64_t, 5> archived_states() const override;
  void flag_merged(uint64_t worker, const std::set<std::string>& skip,
                   const std::function<std::string(uint32_t, bool)>& message) override;
  void forget_merges() override;
  void remove(const std::string& id, const std::vector<std::string>& with_checkpoints) override;
  void requeue(const std::string& id) override;
  void set_priority(const std::string& id, int32_t priority) override;
  size_t scene_users(const std::string& hash) const override;
  std::vector<std::string> ended_before(double age, size_t limit) const override;
  void ping() const override;
  void put_credential(const StoredCredential& c) override;
  void remove_credentials(const std::vector<std::string>& names) override;
  std::vector<StoredCredential> credentials() const override;
  void append_events(std::vector<Event>& events) override;
  std::vector<Event> events(const std::string& job, uint64_t after, size_t limit, bool newest) const override;
  std::unique_ptr<CheckpointFile> begin_checkpoint(const std::string& id) const override;
  std::optional<double> read_checkpoint(const std::string& id, FramePlan& plan, bool with_film = true,
                                        FrameSplats* splats = nullptr) const override;
  void discard_checkpoint(const std::string& id) override { set_checkpoint_bytes(id, std::nullopt); }
  std::optional<std::string> checkpoint_bytes(const std::string& id) const;
  void set_checkpoint_bytes(const std::string& id, std::optional<std::string> bytes);  // nullopt: remove
  bool fail_writes = false;  // every write throws, as a full disk would

 private:
  void check_writes() const;
  mutable Mutex mu_;
  uint64_t generation_ = 0;
  std::vector<StoredJob> rows_ TESSERA_GUARDED_BY(mu_);
  struct Merge {
    uint64_t worker;
    std::string job;
    uint32_t tiles;
  };
  std::vector<Merge> merges_ TESSERA_GUARDED_BY(mu_);
  std::map<std::string, StoredCredential> credentials_ TESSERA_GUARDED_BY(mu_);
  std::deque<Event> events_ TESSERA_GUARDED_BY(mu_);
  uint64_t last_event_ TESSERA_GUARDED_BY(mu_) = 0;
  mutable std::map<std::string, std::string> checkpoints_ TESSERA_GUARDED_BY(mu_);
};

// The plan's whole checkpoint, band by band (tests, and plans written outside a coordinator).
void write_checkpoint(const JobStore& store, const std::string& id, const FramePlan& plan, double elapsed);

}  // namespace tessera
