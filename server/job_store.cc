#include "server/job_store.h"

#include <sqlite3.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "core/io/files.h"
#include "core/render/frames.h"
#include "server/data_marker.h"
#include "server/sqlite_statement.h"

namespace tessera {

namespace fs = std::filesystem;

SqliteJobStore::SqliteJobStore(const std::string& data_dir)
    : dir_((fs::create_directories(data_dir), data_dir)), lock_(dir_) {
  check_data_marker(dir_);  // a lost database is refused, not replaced by an empty one
  const std::string path = (fs::path(dir_) / "coordinator.db").string();
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    const std::string why = sqlite_error(db_, "cannot open " + path);
    sqlite3_close(db_);
    throw std::runtime_error(why);
  }
  sqlite3_busy_timeout(db_, 5000);
  try {
    create_tables();
  } catch (const std::exception& e) {  // (named: "file is not a database" said which only here)
    sqlite3_close(db_);
    throw std::runtime_error(path + ": " + e.what());
  }
  set_data_marker(dir_, true);
}

void SqliteJobStore::create_tables() {
  // WAL: a commit is one append, readers never block it; NORMAL: durable across a killed
  // process (the WAL is in the page cache), at most the last commits lost to a power cut.
  exec("PRAGMA journal_mode=WAL");
  exec("PRAGMA synchronous=NORMAL");
  exec(R"(CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value INTEGER NOT NULL))");
  exec(R"(CREATE TABLE IF NOT EXISTS jobs(
            id TEXT PRIMARY KEY, seq INTEGER NOT NULL, name TEXT NOT NULL, owner TEXT NOT NULL,
            priority INTEGER NOT NULL, scene_hash TEXT NOT NULL, main_file TEXT NOT NULL,
            settings BLOB NOT NULL, state INTEGER NOT NULL, error TEXT NOT NULL,
            elapsed REAL NOT NULL, frames TEXT NOT NULL DEFAULT ''))");
  // A database from before sequences gains their column.
  bool has_frames = false;
  for (Statement q(db_, "PRAGMA table_info(jobs)"); q.step();) has_frames |= q.column_text(1) == "frames";
  if (!has_frames) exec("ALTER TABLE jobs ADD COLUMN frames TEXT NOT NULL DEFAULT ''");
  // ... and the wall-clock time of an end (retention): ended jobs of an older database get a
  // full retention period from now.
  bool has_ended_at = false;
  for (Statement q(db_, "PRAGMA table_info(jobs)"); q.step();) has_ended_at |= q.column_text(1) == "ended_at";
  if (!has_ended_at) {
    exec("ALTER TABLE jobs ADD COLUMN ended_at REAL NOT NULL DEFAULT 0");
    Statement(db_, "UPDATE jobs SET ended_at = ?1 WHERE state >= 2").real(1, wall()).step();
  }
  // ... and archived jobs' last status (archive.h), with whose results their tiles hold.
  bool has_summary = false;
  for (Statement q(db_, "PRAGMA table_info(jobs)"); q.step();) has_summary |= q.column_text(1) == "summary";
  if (!has_summary) exec("ALTER TABLE jobs ADD COLUMN summary BLOB");
  // ... and when each job was submitted (wall clock; 0 for jobs of an older database).
  bool has_submitted_at = false;
  for (Statement q(db_, "PRAGMA table_info(jobs)"); q.step();) has_submitted_at |= q.column_text(1) == "submitted_at";
  if (!has_submitted_at) exec("ALTER TABLE jobs ADD COLUMN submitted_at REAL NOT NULL DEFAULT 0");
  exec("CREATE TABLE IF NOT EXISTS merged_into(worker INTEGER NOT NULL, job TEXT NOT NULL, tiles INTEGER NOT NULL)");
  exec("CREATE INDEX IF NOT EXISTS jobs_scene ON jobs(scene_hash)");
  exec("CREATE INDEX IF NOT EXISTS jobs_seq ON jobs(seq)");
  exec("CREATE INDEX IF NOT EXISTS merged_worker ON merged_into(worker)");
  exec(R"(CREATE TABLE IF NOT EXISTS credentials(name TEXT PRIMARY KEY, digest BLOB NOT NULL,
            enroller TEXT NOT NULL, created REAL NOT NULL, quarantined_at REAL NOT NULL, why TEXT NOT NULL))");
  exec(R"(CREATE TABLE IF NOT EXISTS events(id INTEGER PRIMARY KEY AUTOINCREMENT, time REAL NOT NULL,
            kind TEXT NOT NULL, job TEXT NOT NULL, worker TEXT NOT NULL, who TEXT NOT NULL, detail TEXT NOT NULL))");
  exec("CREATE INDEX IF NOT EXISTS events_job ON events(job, id)");
}

SqliteJobStore::~SqliteJobStore() {
  // A clean close folds the write-ahead log into coordinator.db and deletes it.
  if (sqlite3_close(db_) == SQLITE_OK && !fs::exists(fs::path(dir_) / "coordinator.db-wal")) {
    try {
      set_data_marker(dir_, false);
    } catch (const std::exception&) {  // the next start then asks for a WAL it does not need: it says how to go on
    }
  }
}

void SqliteJobStore::exec(const char* sql) const {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string why = std::string("job database: ") + (err ? err : "error") + " (" + sql + ")";
    sqlite3_free(err);
    throw std::runtime_error(why);
  }
}

void SqliteJobStore::rollback() const { sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr); }

namespace {
std::string frames_text(const std::vector<int>& frames) {  // as parse_frames reads it
  std::string out;
  for (int f : frames) {
    if (!out.empty()) out += ',';
    out += std::to_string(f);
  }
  return out;
}
}  // namespace

uint64_t SqliteJobStore::next_generation() {
  MutexLock lock(mu_);
  Statement(db_,
            "INSERT INTO meta(key, value) VALUES('generation', 1) "
            "ON CONFLICT(key) DO UPDATE SET value = value + 1")
      .step();
  Statement q(db_, "SELECT value FROM meta WHERE key = 'generation'");
  q.step();
  return uint64_t(q.column_int(0));
}

void SqliteJobStore::add(const StoredJob& j) {
  MutexLock lock(mu_);
  Statement(db_,
            "INSERT INTO jobs(id, seq, name, owner, priority, scene_hash, main_file, settings, state, error, elapsed, "
            "frames, submitted_at) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13)")
      .text(1, j.meta.id)
      .integer(2, int64_t(j.meta.seq))
      .text(3, j.meta.name)
      .text(4, j.meta.owner)
      .integer(5, j.meta.priority)
      .text(6, j.meta.scene_hash)
      .text(7, j.meta.main_file)
      .blob(8, j.meta.settings.SerializeAsString())
      .integer(9, j.state)
      .text(10, j.error)
      .real(11, j.elapsed)
      .text(12, frames_text(j.frames))
      .real(13, j.meta.submitted_at)
      .step();
}

void SqliteJobStore::end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) {
  MutexLock lock(mu_);
  // (an end written again, a liar's tiles found in it, keeps its time)
  Statement(db_,
            "UPDATE jobs SET state = ?2, error = ?3, elapsed = ?4, "
            "ended_at = CASE WHEN ended_at > 0 THEN ended_at ELSE ?5 END WHERE id = ?1")
      .text(1, id)
      .integer(2, state)
      .text(3, error)
      .real(4, elapsed)
      .real(5, wall())
      .step();
}

void SqliteJobStore::remove(const std::string& id, const std::vector<std::string>& with_checkpoints) {
  {
    MutexLock lock(mu_);
    Statement(db_, "DELETE FROM jobs WHERE id = ?1").text(1, id).step();
    Statement(db_, "DELETE FROM merged_into WHERE job = ?1").text(1, id).step();
  }
  if (after_row_commit) after_row_commit();
  // The row is gone: a checkpoint left behind (a disk error) is removed with its folder,
  // here by the image sink or at the next start, which removes folders no row names.
  for (const std::string& j : with_checkpoints)
    for (const char* name : {"checkpoint", "checkpoint.tmp"}) {
      std::error_code ec;
      fs::remove(fs::path(dir_) / "jobs" / j / name, ec);
    }
}

void SqliteJobStore::requeue(const std::string& id) {
  {
    MutexLock lock(mu_);
    Statement(db_, "DELETE FROM merged_into WHERE job = ?1").text(1, id).step();  // (in memory again: its own)
    Statement(db_, "UPDATE jobs SET state = ?2, error = '', elapsed = 0, ended_at = 0, summary = NULL WHERE id = ?1")
        .text(1, id)
        .integer(2, v1::JobStatus::QUEUED)
        .step();
  }
  if (after_row_commit) after_row_commit();
}

void SqliteJobStore::set_priority(const std::string& id, int32_t priority) {
  MutexLock lock(mu_);
  Statement(db_, "UPDATE jobs SET priority = ?2 WHERE id = ?1").text(1, id).integer(2, priority).step();
}

size_t SqliteJobStore::scene_users(const std::string& hash) const {
  MutexLock lock(mu_);
  Statement q(db_, "SELECT count(*) FROM jobs WHERE scene_hash = ?1");
  q.text(1, hash).step();
  return size_t(q.column_int(0));
}

std::vector<std::string> SqliteJobStore::ended_before(double age, size_t limit) const {
  MutexLock lock(mu_);
  Statement q(db_,
              "SELECT id FROM jobs WHERE state >= 2 AND ended_at > 0 AND ended_at < ?1 ORDER BY ended_at LIMIT ?2");
  q.real(1, wall() - age).integer(2, int64_t(limit));
  std::vector<std::string> out;
  while (q.step()) out.push_back(q.column_text(0));
  return out;
}

namespace {

// The columns a StoredJob is read from, and the reading (`summary`: the archived status too).
constexpr const char* kRowColumns =
    "id, seq, name, owner, priority, scene_hash, main_file, settings, state, error, elapsed, frames, ended_at, "
    "submitted_at";

// `tolerant`: a row whose settings or frames cannot be read comes back marked (unreadable),
// not as an error that stops every other row being read.
StoredJob read_row(const Statement& q, bool with_summary, bool tolerant = false) {
  StoredJob j;
  j.meta.id = q.column_text(0);
  j.meta.seq = uint64_t(q.column_int(1));
  j.meta.name = q.column_text(2);
  j.meta.owner = q.column_text(3);
  j.meta.priority = int32_t(q.column_int(4));
  j.meta.scene_hash = q.column_text(5);
  j.meta.main_file = q.column_text(6);
  const auto damaged = [&](const std::string& what) {
    if (!tolerant) throw std::runtime_error("job database: job " + j.meta.id + ": " + what);
    if (j.unreadable.empty()) j.unreadable = what;
  };
  if (!j.meta.settings.ParseFromString(q.column_text(7))) damaged("unreadable settings");
  const int64_t state = q.column_int(8);
  j.state = v1::JobStatus::State_IsValid(int(state)) ? v1::JobStatus::State(state) : v1::JobStatus::FAILED;
  j.error = q.column_text(9);
  j.elapsed = q.column_real(10);
  try {
    const std::string frames = q.column_text(11);
    if (!frames.empty()) j.frames = parse_frames(frames);
  } catch (const std::exception& e) {
    damaged(std::string("unreadable frames: ") + e.what());
  }
  j.ended_at = q.column_real(12);
  j.meta.submitted_at = q.column_real(13);
  if (with_summary) j.summary = q.column_text(14);
  return j;
}

// `list`: a sequence's frames not read (page, newest).
std::string select_rows(const char* where_and_order, bool with_summary, bool list = false) {
  std::string columns = kRowColumns;
  if (list) columns.replace(columns.find(", frames,"), 9, ", '' AS frames,");
  return "SELECT " + columns + (with_summary ? ", summary" : "") + " FROM jobs " + where_and_order;
}

}  // namespace

std::vector<StoredJob> SqliteJobStore::jobs() const {
  MutexLock lock(mu_);
  Statement q(db_, select_rows("WHERE summary IS NULL ORDER BY seq", false).c_str());
  std::vector<StoredJob> out;
  while (q.step()) out.push_back(read_row(q, false, true));
  return out;
}

bool SqliteJobStore::archive(const std::string& id, const std::string& summary, const std::vector<MergedInto>& merged) {
  MutexLock lock(mu_);
  return transaction([&] {
    Statement(db_, "DELETE FROM merged_into WHERE job = ?1").text(1, id).step();
    Statement(db_, "UPDATE jobs SET summary = ?2 WHERE id = ?1 AND state >= 2").text(1, id).blob(2, summary).step();
    const bool took = sqlite3_changes(db_) > 0;
    if (took)
      for (const MergedInto& m : merged)
        Statement(db_, "INSERT INTO merged_into(worker, job, tiles) VALUES(?1, ?2, ?3)")
            .integer(1, int64_t(m.worker))
            .text(2, id)
            .integer(3, m.tiles)
            .step();
    return took;
  });
}

std::optional<StoredJob> SqliteJobStore::job(const std::string& id) const {
  MutexLock lock(mu_);
  Statement q(db_, select_rows("WHERE id = ?1", true).c_str());
  q.text(1, id);
  if (!q.step()) return std::nullopt;
  return read_row(q, true);
}

std::vector<StoredJob> SqliteJobStore::page(uint64_t after_seq, size_t n) const {
  MutexLock lock(mu_);
  Statement q(db_, select_rows("WHERE seq > ?1 ORDER BY seq LIMIT ?2", true, true).c_str());
  q.integer(1, int64_t(after_seq)).integer(2, int64_t(std::min<size_t>(n, INT64_MAX)));
  std::vector<StoredJob> out;
  while (q.step()) out.push_back(read_row(q, true));
  return out;
}

uint64_t SqliteJobStore::count() const {
  MutexLock lock(mu_);
  Statement q(db_, "SELECT count(*) FROM jobs");
  q.step();
  return uint64_t(q.column_int(0));
}

std::vector<StoredJob> SqliteJobStore::newest(size_t n) const {
  MutexLock lock(mu_);
  Statement q(db_, select_rows("ORDER BY seq DESC LIMIT ?1", true, true).c_str());
  q.integer(1, int64_t(std::min<size_t>(n, INT64_MAX)));
  std::vector<StoredJob> out;
  while (q.step()) out.push_back(read_row(q, true));
  std::reverse(out.begin(), out.end());
  return out;
}

std::vector<std::pair<std::string, std::string>> SqliteJobStore::archived_names() const {
  MutexLock lock(mu_);
  Statement q(db_, "SELECT id, scene_hash FROM jobs WHERE summary IS NOT NULL");
  std::vector<std::pair<std::string, std::string>> out;
  while (q.step()) out.emplace_back(q.column_text(0), q.column_text(1));
  return out;
}

std::array<uint64_t, 5> SqliteJobStore::archived_states() const {
  MutexLock lock(mu_);
  Statement q(db_, "SELECT state, count(*) FROM jobs WHERE summary IS NOT NULL GROUP BY state");
  std::array<uint64_t, 5> out{};
  while (q.step()) out[size_t(std::clamp<int64_t>(q.column_int(0), 0, 4))] += uint64_t(q.column_int(1));
  return out;
}

void SqliteJobStore::flag_merged(uint64_t worker, const std::set<std::string>& skip,
                                 const std::function<std::string(uint32_t, bool)>& message) {
  MutexLock lock(mu_);
  std::vector<std::pair<std::string, uint32_t>> hits;  // job, tiles
  {
    Statement q(db_, "SELECT job, sum(tiles) FROM merged_into WHERE worker = ?1 GROUP BY job");
    q.integer(1, int64_t(worker));
    while (q.step())
      if (!skip.count(q.column_text(0))) hits.emplace_back(q.column_text(0), uint32_t(q.column_int(1)));
  }
  transaction([&] {
    for (const auto& [job, tiles] : hits) {
      Statement f(db_, "SELECT frames != '' FROM jobs WHERE id = ?1");
      if (!f.text(1, job).step()) continue;
      const std::string m = message(tiles, f.column_int(0) != 0);
      Statement(db_, "UPDATE jobs SET error = CASE WHEN error = '' THEN ?2 ELSE error || '; ' || ?2 END WHERE id = ?1")
          .text(1, job)
          .text(2, m)
          .step();
    }
    Statement(db_, "DELETE FROM merged_into WHERE worker = ?1").integer(1, int64_t(worker)).step();
  });
}

void SqliteJobStore::forget_merges() {
  MutexLock lock(mu_);
  exec("DELETE FROM merged_into");
}

void SqliteJobStore::ping() const {
  {
    MutexLock lock(mu_);
    Statement(db_, "SELECT count(*) FROM jobs").step();
  }
  const fs::path probe = fs::path(dir_) / ".ready-probe";
  try {
    write_file_atomic(probe.string(), "ok\n");
  } catch (const std::exception&) {
    throw std::runtime_error("the data folder does not take writes");
  }
  std::error_code ec;
  fs::remove(probe, ec);
}

std::string SqliteJobStore::checkpoint_path(const std::string& id) const {
  return (fs::path(dir_) / "jobs" / id / "checkpoint").string();
}

namespace {
class FileCheckpoint : public CheckpointFile {
 public:
  FileCheckpoint(const std::string& path, std::function<void()> before_rename)
      : file_(path), before_rename_(std::move(before_rename)) {}
  void append(const std::string& bytes) override { file_.append(bytes); }
  void commit() override { file_.commit({true, before_rename_}); }

 private:
  AtomicFile file_;
  std::function<void()> before_rename_;
};
}  // namespace

std::unique_ptr<CheckpointFile> SqliteJobStore::begin_checkpoint(const std::string& id) const {
  const fs::path path = checkpoint_path(id);
  fs::create_directories(path.parent_path());
  return std::make_unique<FileCheckpoint>(path.string(), before_checkpoint_rename);
}

std::optional<double> SqliteJobStore::read_checkpoint(const std::string& id, FramePlan& plan, bool with_film,
                                                      FrameSplats* splats) const {
  const std::string path = checkpoint_path(id);
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    const int err = errno;
    std::error_code ec;
    if (!fs::exists(path, ec) && !ec) return std::nullopt;
    if (fs::is_directory(path, ec)) throw std::runtime_error(path + ": is a folder, not a checkpoint");
    throw DataFolderError(path + ": cannot read the checkpoint: " + std::strerror(err) +
                          " (the coordinator must be able to read its data folder)");
  }
  return tessera::read_checkpoint(
      [&](char* out, size_t n) {
        in.read(out, std::streamsize(n));
        return size_t(in.gcount());
      },
      plan, with_film, splats);
}

void SqliteJobStore::discard_partial_writes(const std::string& id) const {
  // (The noisy image a denoised one is made from, too: only ever a step to it.)
  for (const char* tmp : {"checkpoint.tmp", "image.exr.tmp", "image.noisy.exr", "image.noisy.exr.tmp"}) {
    std::error_code ec;
    fs::remove(fs::path(dir_) / "jobs" / id / tmp, ec);
  }
}

void SqliteJobStore::discard_checkpoint(const std::string& id) {
  std::error_code ec;
  fs::remove(checkpoint_path(id), ec);
}

void write_checkpoint(const JobStore& store, const std::string& id, const FramePlan& plan, double elapsed) {
  std::unique_ptr<CheckpointFile> file = store.begin_checkpoint(id);
  CheckpointEncoder enc(plan, elapsed, [&](const std::string& bytes) { file->append(bytes); });
  BandCopy band;
  for (uint32_t b = 0; b < plan.bands(); ++b) {
    plan.copy_band(b, &band);
    enc.band(band);
  }
  enc.finish();
  file->commit();
}

}  // namespace tessera
