#include "worker/scene_cache.h"

#include <fcntl.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <utility>
#include <vector>

#include "core/scene/load.h"
#include "rpc.h"
#include "scene_chunks.h"
#include "wire.h"

namespace tessera::worker {

namespace fs = std::filesystem;

namespace {

// Removes `hash`'s partial downloads (every scene's, for "") left by processes no longer
// running (a worker killed mid-fetch); another live worker's, sharing the cache folder, is
// left alone.
void remove_orphaned_partials(const fs::path& dir, const std::string& hash) {
  std::error_code ec;
  constexpr std::string_view kPartial = ".partial-";
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    const size_t at = name.find(kPartial);
    if (at == std::string::npos || (!hash.empty() && (at != hash.size() || name.compare(0, at, hash) != 0))) continue;
    const long pid = std::strtol(name.c_str() + at + kPartial.size(), nullptr, 10);
    if (pid > 0 && kill(pid_t(pid), 0) != 0 && errno == ESRCH) fs::remove_all(e.path(), ec);
  }
}

// A lock on a scene folder's marker (its `.main`), held by every worker that loads or holds
// the scene (shared) and taken by the disk bound before it removes the folder (exclusive,
// without waiting: a folder in use is skipped). flock(2) locks belong to an open file, so
// two workers in one process exclude each other as two processes do.
class MarkerLock {
 public:
  // A shared lock on `marker`, or an empty one where it is gone (never there, or removed
  // by another worker's disk bound before the lock was had: its folder goes too). Throws
  // where the marker is there but cannot be opened.
  static MarkerLock shared(const fs::path& marker) { return take(marker, LOCK_SH); }
  // An exclusive lock, or an empty one where the marker is gone or another worker holds it.
  static MarkerLock exclusive(const fs::path& marker) { return take(marker, LOCK_EX | LOCK_NB); }
  MarkerLock() = default;
  MarkerLock(MarkerLock&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  MarkerLock& operator=(MarkerLock&& o) noexcept {
    std::swap(fd_, o.fd_);
    return *this;
  }
  ~MarkerLock() {
    if (fd_ >= 0) ::close(fd_);  // (closing the file drops its lock)
  }
  explicit operator bool() const { return fd_ >= 0; }

 private:
  static MarkerLock take(const fs::path& marker, int how) {
    const bool exclusive = how & LOCK_EX;
    MarkerLock l;
    // (Read-write for an exclusive lock where it can be: NFS emulates flock by fcntl locks,
    // whose write lock needs a file open for writing.)
    if (exclusive) l.fd_ = ::open(marker.c_str(), O_RDWR | O_CLOEXEC);
    if (l.fd_ < 0) l.fd_ = ::open(marker.c_str(), O_RDONLY | O_CLOEXEC);
    if (l.fd_ < 0) {
      if (errno == ENOENT || errno == ENOTDIR || exclusive) return l;  // gone; or not ours to remove
      throw std::runtime_error("scene cache: cannot open " + marker.string() + ": " + std::strerror(errno));
    }
    int rc;
    while ((rc = ::flock(l.fd_, how)) != 0 && errno == EINTR) {
    }
    if (rc != 0 && errno == EWOULDBLOCK) return MarkerLock();  // another worker holds it
    if (rc != 0) {
      // A filesystem without locks (ENOLCK): the folder is used unlocked, and the disk
      // bound goes by the idle time alone, as it did before locks.
      static std::atomic<bool> warned{false};
      if (!warned.exchange(true))
        spdlog::warn(
            "scene cache: cannot lock {} ({}): workers sharing the folder rely on --cache-max-gib's idle "
            "time alone",
            marker.string(), std::strerror(errno));
    }
    // Removed between the open and the lock (the remover unlinks it under its lock):
    // nothing to hold.
    struct stat st;
    if (::fstat(l.fd_, &st) != 0 || st.st_nlink == 0) return MarkerLock();
    return l;
  }
  int fd_ = -1;
};

// Removes `dir` by first renaming it aside (to a partial folder of this process's, which
// remove_orphaned_partials clears if this process dies meanwhile): a worker putting a
// fresh copy in place meanwhile is not removed with it. Never throws.
void remove_aside(const fs::path& dir) {
  static std::atomic<uint64_t> removals{0};
  std::error_code ec;
  const fs::path aside = dir.parent_path() / (dir.filename().string() + ".partial-" + std::to_string(::getpid()) +
                                              "-removed-" + std::to_string(removals++));
  fs::rename(dir, aside, ec);
  fs::remove_all(ec ? dir : aside, ec);
}

// A loaded scene and the lock on its folder, released with the scene's last holder.
struct LockedScene {
  MarkerLock lock;
  Scene scene;
};

// The process's resident memory (/proc/self/statm); 0 where it cannot be read.
uint64_t resident_bytes() {
  std::ifstream in("/proc/self/statm");
  uint64_t size = 0, resident = 0;
  if (!(in >> size >> resident)) return 0;
  return resident * uint64_t(sysconf(_SC_PAGESIZE));
}

}  // namespace

size_t SceneCache::scenes_held() const {
  size_t n = 0;
  for (const auto& [hash, s] : scenes_) n += !s.expired();
  return n;
}

void SceneCache::mark_used(const std::string& hash) const {
  std::error_code ec;  // (best effort: a read-only cache folder only loses the order)
  fs::last_write_time(fs::path(dir_) / hash / ".main", fs::file_time_type::clock::now(), ec);
}

SceneCache::SceneCache(std::string dir, FetchChunks fetch, Bounds bound)
    : dir_(std::move(dir)), fetch_(std::move(fetch)), bound_(bound) {
  // Every scene's downloads that dead workers left (they went only when the same scene was
  // fetched again: a farm's worth of scenes never asked for again stayed on the disk).
  remove_orphaned_partials(dir_, "");
}

std::shared_ptr<Scene> SceneCache::scene(const std::string& hash) {
  if (auto it = scenes_.find(hash); it != scenes_.end())
    if (std::shared_ptr<Scene> s = it->second.lock()) return s;
  for (auto it = scenes_.begin(); it != scenes_.end();) it = it->second.expired() ? scenes_.erase(it) : std::next(it);
  if (hash.size() != 32 || hash.find_first_not_of("0123456789abcdef") != std::string::npos)
    throw WireError("bad scene hash '" + hash + "'");
  const fs::path dir = fs::path(dir_) / hash;
  // Locked before it is read, and held with the scene: another worker's disk bound leaves
  // the folder alone while this one loads it or may read its files again (an --env map of
  // a renderer of other settings). A folder removed between looking and locking is
  // fetched again.
  for (int fetches = 0;; ++fetches) {
    if (MarkerLock lock = MarkerLock::shared(dir / ".main")) {
      std::string main;
      if (std::ifstream in(dir / ".main"); !std::getline(in, main))
        throw std::runtime_error("scene cache: cannot read " + (dir / ".main").string());
      mark_used(hash);
      if (fetches > 0) trim(hash);
      auto held = std::make_shared<LockedScene>(LockedScene{std::move(lock), load_scene((dir / main).string())});
      std::shared_ptr<Scene> s(held, &held->scene);
      scenes_[hash] = s;
      return s;
    }
    if (fetches == 2)
      throw std::runtime_error("scene cache: scene " + hash + " was removed from " + dir_ +
                               " (another worker's --cache-max-gib) each time it was fetched");
    fetch(hash);
  }
}

void SceneCache::trim(const std::string& fetched) {
  if (bound_.max_disk_bytes == 0) return;
  try {
    trim_folder(fetched);
  } catch (const std::exception& e) {  // the disk bound waits for the next fetch; the task goes on
    spdlog::warn("scene cache: could not keep within --cache-max-gib: {}", e.what());
  }
}

void SceneCache::trim_folder(const std::string& fetched, uint64_t to_free) {
  struct Kept {
    fs::file_time_type used;
    uint64_t bytes = 0;
    fs::path dir;
  };
  std::vector<Kept> kept;
  uint64_t total = 0;
  std::error_code ec;
  const auto skip = fs::directory_options::skip_permission_denied;
  // (Iterated with error codes: folders come and go as other workers sharing this one work.)
  for (fs::directory_iterator e(dir_, skip, ec), end; !ec && e != end; e.increment(ec)) {
    const fs::path marker = e->path() / ".main";
    std::error_code mec;
    const fs::file_time_type used = fs::last_write_time(marker, mec);
    if (mec) continue;  // not a whole scene (a partial fetch, something else)
    Kept k{used, 0, e->path()};
    for (fs::recursive_directory_iterator f(e->path(), skip, mec), fend; !mec && f != fend; f.increment(mec))
      if (std::error_code fec; f->is_regular_file(fec)) k.bytes += f->file_size(fec);
    total += k.bytes;
    const std::string hash = e->path().filename().string();
    const auto held = scenes_.find(hash);  // in this worker's memory: its files may still be read
    if (hash != fetched && (held == scenes_.end() || held->second.expired())) kept.push_back(std::move(k));
  }
  std::sort(kept.begin(), kept.end(), [](const Kept& a, const Kept& b) { return a.used < b.used; });
  const bool room = to_free > 0;  // making room for a fetch: any scene no worker holds
  const auto idle_since =
      fs::file_time_type::clock::now() - std::chrono::duration_cast<fs::file_time_type::duration>(
                                             std::chrono::duration<double>(room ? 0.0 : bound_.min_idle_seconds));
  uint64_t freed = 0;
  for (const Kept& k : kept) {
    if (room ? freed >= to_free : total <= bound_.max_disk_bytes || k.used > idle_since) break;
    // Looked at again (another worker may have used it since), then its marker first: a
    // removal cut short leaves a folder that is fetched again, never one that looks whole.
    // Skipped where another worker holds it (loading it, or with it in memory).
    std::error_code mec;
    const MarkerLock lock = MarkerLock::exclusive(k.dir / ".main");
    if (!lock || fs::last_write_time(k.dir / ".main", mec) > idle_since || mec || !fs::remove(k.dir / ".main", mec) ||
        mec)
      continue;
    remove_aside(k.dir);
    total -= k.bytes;
    freed += k.bytes;
    spdlog::info("scene cache: removed scene {} ({} bytes, least recently used) {}", k.dir.filename().string(), k.bytes,
                 room ? "to make room for scene " + fetched : std::string("to stay within --cache-max-gib"));
  }
}

void SceneCache::make_room(const std::string& hash, uint64_t need) {
  const auto free_now = [&]() -> std::optional<uint64_t> {
    if (free_disk_bytes) return free_disk_bytes();
    struct statvfs v {};
    if (::statvfs(dir_.c_str(), &v) != 0) return std::nullopt;
    return uint64_t(v.f_bavail) * uint64_t(v.f_frsize);
  };
  const uint64_t want = need + need / 32 + (uint64_t(1) << 20);  // (the file system's own, and the marker)
  const std::optional<uint64_t> before = free_now();
  if (!before || *before >= want) return;
  trim_folder(hash, want - *before);
  const std::optional<uint64_t> after = free_now();
  if (after && *after < want)
    throw std::runtime_error("scene cache " + dir_ + ": scene " + hash + " takes " + std::to_string(need >> 20) +
                             " MiB, and the disk has " + std::to_string(*after >> 20) +
                             " MiB free with every scene no worker holds removed");
}

void SceneCache::fetch(const std::string& hash) {
  // Into a folder of this process's own, renamed into place once whole and checked: workers
  // that share a cache folder each fetch into their own, and the first in place is used.
  static std::atomic<uint64_t> fetches{0};
  const fs::path dir = fs::path(dir_) / hash, part = fs::path(dir_) / (hash + ".partial-" + std::to_string(::getpid()) +
                                                                       "-" + std::to_string(fetches++));
  struct Cleanup {
    fs::path part;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(part, ec);
    }
  } cleanup{part};
  remove_orphaned_partials(dir_, hash);  // earlier runs', cut short
  const std::string what = "scene " + hash;
  std::unique_ptr<SceneReceiver> rx;
  v1::FetchSceneRequest req;
  req.set_scene_hash(hash);
  Backoff backoff(Backoff::kWorkerFirstSeconds);
  for (int failures = 0;;) {
    const auto at = [&] { return rx ? std::pair(rx->next_file(), rx->next_offset()) : std::pair(0u, uint64_t(0)); };
    const auto before = at();
    bool first = true;
    const grpc::Status st = fetch_(req, [&](const v1::SceneChunk& chunk) {
      if (!first) return rx->add(chunk);
      first = false;  // the manifest
      if (!chunk.has_manifest() || chunk.manifest().scene_hash() != hash)
        throw WireError(what + ": the coordinator sent no manifest of it");
      if (!rx) {
        rx = std::make_unique<SceneReceiver>(part.string(), chunk.manifest(), what);  // (its folder, no byte yet)
        make_room(hash, rx->bytes());
      } else if (chunk.manifest().SerializeAsString() != rx->manifest().SerializeAsString())
        throw WireError(what + ": its manifest changed between two fetches");
    });
    if (st.ok()) break;
    failures = at() > before ? 0 : failures + 1;
    const bool busy = st.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED;
    if (busy && failures >= kFetchAttempts) throw SceneBusy("fetch scene " + hash + ": " + st.error_message());
    if (!(unreachable(st) || busy) || failures >= kFetchAttempts)
      throw std::runtime_error("fetch scene " + hash + ": " + st.error_message());
    if (rx) {  // goes on from the first byte it lacks
      req.set_file(rx->next_file());
      req.set_offset(rx->next_offset());
    }
    backoff.wait();
  }
  if (!rx) throw WireError(what + ": the coordinator sent no manifest of it");
  rx->finish();  // every byte, hashing to `hash`
  const std::string main = rx->manifest().main_file();
  rx.reset();
  errno = 0;
  if (!(std::ofstream(part / ".main") << main << "\n")) {
    const int e = errno;
    throw std::runtime_error("cannot write the scene cache's marker " + (part / ".main").string() +
                             (e ? std::string(": ") + std::strerror(e) : std::string()));
  }
  std::error_code ec;
  fs::rename(part, dir, ec);
  if (ec && fs::exists(dir / ".main")) return;  // another worker's, the same bytes
  if (ec) {
    remove_aside(dir);  // an earlier run's, unfinished, or one another worker's bound is removing
    fs::rename(part, dir, ec);
    if (ec && !fs::exists(dir / ".main"))  // (else another worker's copy came first: the same bytes)
      throw std::runtime_error("cannot put scene " + hash + " in the scene cache " + dir_ + ": " + ec.message());
  }
}

std::shared_ptr<const PreparedRenderer> SceneCache::prepare(const v1::Task& task) {
  const std::string key = task.scene_hash() + task.settings().SerializeAsString();
  if (auto it = prepared_.find(key); it != prepared_.end()) return it->second;
  auto p = std::make_shared<PreparedRenderer>();
  const RenderSettings settings = from_proto(task.settings());
  // The frames of a sequence share one acceleration structure: a renderer built for any
  // frame of the same (scene, settings) lends its own to the next frame's. (Each frame's
  // tasks carry only that frame's camera: CameraPath::for_frame.)
  v1::RenderSettings base = task.settings();
  base.clear_frame();
  base.clear_camera_path();
  const std::string base_key = task.scene_hash() + base.SerializeAsString();
  std::shared_ptr<const PreparedRenderer> sibling;
  for (const auto& [k, q] : prepared_)
    if (q->base_key == base_key) sibling = q;
  if (sibling) {
    p->scene = sibling->scene;
    p->renderer = std::make_unique<TileRenderer>(*sibling->renderer, settings);
  } else {
    p->scene = scene(task.scene_hash());
    p->renderer = std::make_unique<TileRenderer>(*p->scene, settings);
  }
  p->base_key = base_key;
  // Used: the disk bound's order (its files may still be read: an --env map by the next
  // renderer of other settings; another worker sharing the folder sees the use too).
  mark_used(task.scene_hash());
  // Tasks in flight hold their renderers; the cache keeps the latest few.
  prepared_[key] = p;
  prepared_order_.push_back(key);
  while (prepared_order_.size() > kKeptRenderers) {
    prepared_.erase(prepared_order_.front());
    prepared_order_.pop_front();
  }
  // Above the memory bound, the oldest renderers no task holds go, the newest never; once
  // dropping one frees nothing the process gives back, no more go (the rest of the memory
  // is elsewhere: dropping more would only rebuild renderers task after task).
  if (bound_.max_memory_bytes == 0) return p;
  for (auto it = prepared_order_.begin(); std::next(it) != prepared_order_.end();) {
    const uint64_t before = resident_bytes();
    if (before <= bound_.max_memory_bytes) break;
    if (prepared_[*it].use_count() > 1) {  // a task renders with it
      ++it;
      continue;
    }
    prepared_.erase(*it);
    it = prepared_order_.erase(it);
    if (resident_bytes() >= before) break;
  }
  return p;
}

}  // namespace tessera::worker
