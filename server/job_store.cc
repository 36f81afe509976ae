#include "server/job_store.h"

#include <sqlite3.h>
#include <zstd.h>
#define XXH_INLINE_ALL  // header only: nothing to link
#include <xxhash.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "core/io/files.h"
#include "core/render/frames.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

constexpr char kMagic[4] = {'T', 'S', 'C', 'K'};
// Version 2: the film's sums in chunks of kChunkPixels, each compressed on its own (a
// whole film as one buffer took 8 times as long per pixel: caches, and page faults for
// buffers of the film's size). Version 1 is still read.
constexpr uint32_t kCheckpointVersion = 2;
constexpr uint32_t kChunkPixels = 1 << 16;

// Little-endian fields, appended and read back in order.
class Writer {
 public:
  template <typename T>
  void put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  void bytes(const std::string& b) {
    put(uint64_t(b.size()));
    out += b;
  }
  std::string out;
};

class Reader {
 public:
  explicit Reader(const std::string& in) : in_(in) {}
  template <typename T>
  T get() {
    T v;
    need(sizeof v);
    std::memcpy(&v, in_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }
  std::string bytes() {
    const uint64_t n = get<uint64_t>();
    need(n);
    std::string b = in_.substr(at_, n);
    at_ += n;
    return b;
  }
  size_t at() const { return at_; }

 private:
  void need(uint64_t n) const {
    if (n > in_.size() - at_) throw std::runtime_error("checkpoint: truncated");
  }
  const std::string& in_;
  size_t at_ = 0;
};

std::string sqlite_error(sqlite3* db, const std::string& what) {
  return "job database: " + what + ": " + (db ? sqlite3_errmsg(db) : "out of memory");
}

// One prepared statement, finalized on scope exit.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) : db_(db) {
    if (sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) != SQLITE_OK) throw std::runtime_error(sqlite_error(db, sql));
  }
  ~Statement() { sqlite3_finalize(s_); }
  Statement& text(int i, const std::string& v) {
    sqlite3_bind_text(s_, i, v.data(), int(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& blob(int i, const std::string& v) {
    sqlite3_bind_blob(s_, i, v.data(), int(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& integer(int i, int64_t v) {
    sqlite3_bind_int64(s_, i, v);
    return *this;
  }
  Statement& real(int i, double v) {
    sqlite3_bind_double(s_, i, v);
    return *this;
  }
  bool step() {  // true while there is a row
    const int rc = sqlite3_step(s_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    throw std::runtime_error(sqlite_error(db_, "step"));
  }
  std::string column_text(int i) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_blob(s_, i));
    return p ? std::string(p, size_t(sqlite3_column_bytes(s_, i))) : std::string();
  }
  int64_t column_int(int i) const { return sqlite3_column_int64(s_, i); }
  double column_real(int i) const { return sqlite3_column_double(s_, i); }

 private:
  sqlite3* db_;
  sqlite3_stmt* s_ = nullptr;
};

}  // namespace

std::string encode_checkpoint(const PlanState& state, const Film& film, double elapsed) {
  Writer w;
  w.out.append(kMagic, 4);
  w.put(kCheckpointVersion);
  w.put(uint32_t(state.progress.size()));
  for (const TileProgress& t : state.progress) {
    w.put(t.passes_done);
    w.put(uint8_t(t.finished));
    w.put(t.relative_error);
  }
  w.put(state.samples_merged);
  w.put(state.merges);
  w.put(state.work_done);
  w.put(state.work_total);
  w.put(elapsed);
  const Rect& r = film.window();
  for (int v : {r.x, r.y, r.w, r.h}) w.put(int32_t(v));
  std::string active(ZSTD_compressBound(state.active.size()), '\0');
  const size_t n = ZSTD_compress(active.data(), active.size(), state.active.data(), state.active.size(), 1);
  if (ZSTD_isError(n)) throw std::runtime_error("checkpoint: cannot compress the active mask");
  active.resize(n);
  w.put(uint64_t(state.active.size()));
  w.bytes(active);
  const std::vector<PixelSums>& pixels = film.pixels();
  std::vector<std::string> chunks;
  size_t size = w.out.size() + 4 + 8;
  for (size_t at = 0; at < pixels.size(); at += kChunkPixels) {
    chunks.push_back(encode_sums(pixels.data() + at, std::min<size_t>(kChunkPixels, pixels.size() - at)));
    size += 8 + chunks.back().size();
  }
  w.out.reserve(size);  // (appending a film's worth piece by piece would copy it many times)
  w.put(kChunkPixels);
  for (const std::string& c : chunks) w.bytes(c);
  w.put(uint64_t(XXH64(w.out.data(), w.out.size(), 0)));
  return std::move(w.out);
}

Checkpoint decode_checkpoint(const std::string& bytes, bool with_film) {
  if (bytes.size() < 4 + 8 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    throw std::runtime_error("checkpoint: not a checkpoint file");
  uint64_t sum;
  std::memcpy(&sum, bytes.data() + bytes.size() - 8, 8);
  if (XXH64(bytes.data(), bytes.size() - 8, 0) != sum) throw std::runtime_error("checkpoint: checksum mismatch");
  Reader in(bytes);
  in.get<uint32_t>();  // magic
  const uint32_t version = in.get<uint32_t>();
  if (version != 1 && version != kCheckpointVersion)
    throw std::runtime_error("checkpoint: version " + std::to_string(version) + " not supported");
  Checkpoint c;
  const uint32_t tiles = in.get<uint32_t>();
  if (uint64_t(tiles) * 9 > bytes.size()) throw std::runtime_error("checkpoint: truncated");
  c.state.progress.resize(tiles);
  for (TileProgress& t : c.state.progress) {
    t.passes_done = in.get<uint32_t>();
    t.finished = in.get<uint8_t>() != 0;
    t.relative_error = in.get<float>();
  }
  c.state.samples_merged = in.get<uint64_t>();
  c.state.merges = in.get<uint64_t>();
  c.state.work_done = in.get<double>();
  c.state.work_total = in.get<double>();
  c.elapsed = in.get<double>();
  Rect r;
  r.x = in.get<int32_t>();
  r.y = in.get<int32_t>();
  r.w = in.get<int32_t>();
  r.h = in.get<int32_t>();
  if (r.w < 0 || r.h < 0 || r.area() > (int64_t(1) << 32)) throw std::runtime_error("checkpoint: bad film window");
  const uint64_t active_size = in.get<uint64_t>();
  if (active_size != 0 && active_size != uint64_t(r.area())) throw std::runtime_error("checkpoint: bad active mask");
  const std::string active = in.bytes();
  c.state.active.resize(active_size);
  if (active_size) {
    const size_t n = ZSTD_decompress(c.state.active.data(), active_size, active.data(), active.size());
    if (ZSTD_isError(n) || n != active_size) throw std::runtime_error("checkpoint: bad active mask");
  }
  const size_t pixels = size_t(r.area());
  const uint32_t chunk = version == 1 ? uint32_t(std::max<size_t>(1, pixels)) : in.get<uint32_t>();
  if (chunk == 0) throw std::runtime_error("checkpoint: bad film chunk size");
  std::vector<std::string> chunks;
  for (size_t at = 0; at < pixels || (version == 1 && chunks.empty()); at += chunk) chunks.push_back(in.bytes());
  if (in.at() != bytes.size() - 8) throw std::runtime_error("checkpoint: trailing bytes");
  if (!with_film) return c;
  c.film = Film(r);
  try {
    for (size_t i = 0, at = 0; i < chunks.size() && at < pixels; ++i, at += chunk)
      decode_sums(chunks[i], &c.film.at(0, 0) + at, std::min<size_t>(chunk, pixels - at));
  } catch (const WireError& e) {
    throw std::runtime_error(std::string("checkpoint: film: ") + e.what());
  }
  return c;
}

JobStore::JobStore(const std::string& data_dir) : dir_(data_dir) {
  fs::create_directories(dir_);
  const std::string path = (fs::path(dir_) / "coordinator.db").string();
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    const std::string why = sqlite_error(db_, "cannot open " + path);
    sqlite3_close(db_);
    throw std::runtime_error(why);
  }
  sqlite3_busy_timeout(db_, 5000);
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
}

JobStore::~JobStore() { sqlite3_close(db_); }

void JobStore::exec(const char* sql) const {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string why = std::string("job database: ") + (err ? err : "error") + " (" + sql + ")";
    sqlite3_free(err);
    throw std::runtime_error(why);
  }
}

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

uint64_t JobStore::next_generation() {
  std::lock_guard<std::mutex> lock(mu_);
  Statement(db_,
            "INSERT INTO meta(key, value) VALUES('generation', 1) "
            "ON CONFLICT(key) DO UPDATE SET value = value + 1")
      .step();
  Statement q(db_, "SELECT value FROM meta WHERE key = 'generation'");
  q.step();
  return uint64_t(q.column_int(0));
}

void JobStore::add(const StoredJob& j) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement(db_,
            "INSERT INTO jobs(id, seq, name, owner, priority, scene_hash, main_file, settings, state, error, elapsed, "
            "frames) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)")
      .text(1, j.id)
      .integer(2, int64_t(j.seq))
      .text(3, j.name)
      .text(4, j.owner)
      .integer(5, j.priority)
      .text(6, j.scene_hash)
      .text(7, j.main_file)
      .blob(8, j.settings.SerializeAsString())
      .integer(9, j.state)
      .text(10, j.error)
      .real(11, j.elapsed)
      .text(12, frames_text(j.frames))
      .step();
}

void JobStore::end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement(db_, "UPDATE jobs SET state = ?2, error = ?3, elapsed = ?4 WHERE id = ?1")
      .text(1, id)
      .integer(2, state)
      .text(3, error)
      .real(4, elapsed)
      .step();
}

std::vector<StoredJob> JobStore::jobs() const {
  std::lock_guard<std::mutex> lock(mu_);
  Statement q(db_,
              "SELECT id, seq, name, owner, priority, scene_hash, main_file, settings, state, error, elapsed, frames "
              "FROM jobs ORDER BY seq");
  std::vector<StoredJob> out;
  while (q.step()) {
    StoredJob j;
    j.id = q.column_text(0);
    j.seq = uint64_t(q.column_int(1));
    j.name = q.column_text(2);
    j.owner = q.column_text(3);
    j.priority = int32_t(q.column_int(4));
    j.scene_hash = q.column_text(5);
    j.main_file = q.column_text(6);
    if (!j.settings.ParseFromString(q.column_text(7)))
      throw std::runtime_error("job database: job " + j.id + ": unreadable settings");
    const int64_t state = q.column_int(8);
    j.state = v1::JobStatus::State_IsValid(int(state)) ? v1::JobStatus::State(state) : v1::JobStatus::FAILED;
    j.error = q.column_text(9);
    j.elapsed = q.column_real(10);
    try {
      const std::string frames = q.column_text(11);
      if (!frames.empty()) j.frames = parse_frames(frames);
    } catch (const std::exception& e) {
      throw std::runtime_error("job database: job " + j.id + ": unreadable frames: " + e.what());
    }
    out.push_back(std::move(j));
  }
  return out;
}

void JobStore::ping() const {
  std::lock_guard<std::mutex> lock(mu_);
  Statement(db_, "SELECT count(*) FROM jobs").step();
}

std::string JobStore::checkpoint_path(const std::string& id) const {
  return (fs::path(dir_) / "jobs" / id / "checkpoint").string();
}

void JobStore::write_checkpoint(const std::string& id, const PlanState& state, const Film& film, double elapsed) const {
  const fs::path path = checkpoint_path(id);
  fs::create_directories(path.parent_path());
  write_file_atomic(path.string(), encode_checkpoint(state, film, elapsed), {true, before_checkpoint_rename});
}

std::optional<Checkpoint> JobStore::read_checkpoint(const std::string& id, bool with_film) const {
  const std::string path = checkpoint_path(id);
  std::error_code ec;
  if (!fs::exists(path, ec)) return std::nullopt;
  return decode_checkpoint(read_file_bytes(path), with_film);
}

}  // namespace tessera
