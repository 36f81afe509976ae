#include <algorithm>
#include <cstdint>
#include <map>

#include "server/job_store.h"

namespace tessera {

namespace {
class MemoryCheckpoint : public CheckpointFile {
 public:
  explicit MemoryCheckpoint(std::function<void(std::string)> done) : done_(std::move(done)) {}
  void append(const std::string& bytes) override { bytes_ += bytes; }
  void commit() override { done_(std::move(bytes_)); }

 private:
  std::string bytes_;
  std::function<void(std::string)> done_;
};
}  // namespace

uint64_t MemoryJobStore::next_generation() { return ++generation_; }

void MemoryJobStore::check_writes() const {
  if (fail_writes) throw std::runtime_error("job database: disk I/O error (a test's)");
}

void MemoryJobStore::add(const StoredJob& job) {
  MutexLock lock(mu_);
  check_writes();
  for (const StoredJob& j : rows_)  // as SQLite's primary key
    if (j.meta.id == job.meta.id) throw std::runtime_error("job database: UNIQUE constraint failed: jobs.id");
  StoredJob& row = rows_.emplace_back(job);
  row.meta.scene_bytes = 0;  // not stored: a restart counts the bundle again
}

void MemoryJobStore::end(const std::string& id, v1::JobStatus::State state, const std::string& error, double elapsed) {
  MutexLock lock(mu_);
  check_writes();
  for (StoredJob& j : rows_)
    if (j.meta.id == id) {
      j.state = state;
      j.error = error;
      j.elapsed = elapsed;
      if (j.ended_at == 0) j.ended_at = wall();
    }
}

void MemoryJobStore::remove(const std::string& id, const std::vector<std::string>& with_checkpoints) {
  MutexLock lock(mu_);
  check_writes();
  std::erase_if(rows_, [&](const StoredJob& j) { return j.meta.id == id; });
  std::erase_if(merges_, [&](const Merge& m) { return m.job == id; });
  for (const std::string& j : with_checkpoints) checkpoints_.erase(j);
}

void MemoryJobStore::requeue(const std::string& id) {
  MutexLock lock(mu_);
  check_writes();
  for (StoredJob& j : rows_)
    if (j.meta.id == id) {
      j.state = v1::JobStatus::QUEUED;
      j.error.clear();
      j.elapsed = j.ended_at = 0;
      j.summary.clear();
    }
  std::erase_if(merges_, [&](const Merge& m) { return m.job == id; });
}

void MemoryJobStore::set_priority(const std::string& id, int32_t priority) {
  MutexLock lock(mu_);
  check_writes();
  for (StoredJob& j : rows_)
    if (j.meta.id == id) j.meta.priority = priority;
}

size_t MemoryJobStore::scene_users(const std::string& hash) const {
  MutexLock lock(mu_);
  return size_t(
      std::count_if(rows_.begin(), rows_.end(), [&](const StoredJob& j) { return j.meta.scene_hash == hash; }));
}

std::vector<std::string> MemoryJobStore::ended_before(double age, size_t limit) const {
  std::vector<StoredJob> rows = jobs();
  std::stable_sort(rows.begin(), rows.end(),
                   [](const StoredJob& a, const StoredJob& b) { return a.ended_at < b.ended_at; });
  std::vector<std::string> out;
  for (const StoredJob& j : rows)
    if (!job_live(j.state) && j.ended_at > 0 && j.ended_at < wall() - age && out.size() < limit)
      out.push_back(j.meta.id);
  return out;
}

std::vector<StoredJob> MemoryJobStore::jobs() const {
  std::vector<StoredJob> rows = page(0, SIZE_MAX);
  std::erase_if(rows, [](const StoredJob& j) { return !j.summary.empty(); });
  for (StoredJob& j : rows) j.summary.clear();
  return rows;
}

bool MemoryJobStore::archive(const std::string& id, const std::string& summary, const std::vector<MergedInto>& merged) {
  MutexLock lock(mu_);
  check_writes();
  std::erase_if(merges_, [&](const Merge& m) { return m.job == id; });
  for (StoredJob& j : rows_)
    if (j.meta.id == id && !job_live(j.state)) {
      j.summary = summary;
      for (const MergedInto& m : merged) merges_.push_back({m.worker, id, m.tiles});
      return true;
    }
  return false;
}

std::optional<StoredJob> MemoryJobStore::job(const std::string& id) const {
  MutexLock lock(mu_);
  for (const StoredJob& j : rows_)
    if (j.meta.id == id) return j;
  return std::nullopt;
}

std::vector<StoredJob> MemoryJobStore::page(uint64_t after_seq, size_t n) const {
  std::vector<StoredJob> rows;
  {
    MutexLock lock(mu_);
    for (const StoredJob& j : rows_)
      if (j.meta.seq > after_seq) rows.push_back(j);
  }
  std::stable_sort(rows.begin(), rows.end(),
                   [](const StoredJob& a, const StoredJob& b) { return a.meta.seq < b.meta.seq; });
  if (rows.size() > n) rows.resize(n);
  return rows;
}

uint64_t MemoryJobStore::count() const {
  MutexLock lock(mu_);
  return rows_.size();
}

std::vector<StoredJob> MemoryJobStore::newest(size_t n) const {
  std::vector<StoredJob> rows = page(0, SIZE_MAX);
  if (rows.size() > n) rows.erase(rows.begin(), rows.end() - ptrdiff_t(n));
  return rows;
}

std::vector<std::pair<std::string, std::string>> MemoryJobStore::archived_names() const {
  MutexLock lock(mu_);
  std::vector<std::pair<std::string, std::string>> out;
  for (const StoredJob& j : rows_)
    if (!j.summary.empty()) out.emplace_back(j.meta.id, j.meta.scene_hash);
  return out;
}

std::array<uint64_t, 5> MemoryJobStore::archived_states() const {
  MutexLock lock(mu_);
  std::array<uint64_t, 5> out{};
  for (const StoredJob& j : rows_)
    if (!j.summary.empty()) ++out[std::min<size_t>(4, size_t(j.state))];
  return out;
}

void MemoryJobStore::flag_merged(uint64_t worker, const std::set<std::string>& skip,
                                 const std::function<std::string(uint32_t, bool)>& message) {
  MutexLock lock(mu_);
  check_writes();
  std::map<std::string, uint32_t> hits;
  for (const Merge& m : merges_)
    if (m.worker == worker && !skip.count(m.job)) hits[m.job] += m.tiles;
  for (StoredJob& j : rows_)
    if (auto it = hits.find(j.meta.id); it != hits.end()) {
      const std::string m = message(it->second, !j.frames.empty());
      j.error += (j.error.empty() ? "" : "; ") + m;
    }
  std::erase_if(merges_, [&](const Merge& m) { return m.worker == worker; });
}

void MemoryJobStore::forget_merges() {
  MutexLock lock(mu_);
  merges_.clear();
}

void MemoryJobStore::ping() const { check_writes(); }

void MemoryJobStore::put_credential(const StoredCredential& c) {
  MutexLock lock(mu_);
  check_writes();
  credentials_[c.name] = c;
}

void MemoryJobStore::remove_credentials(const std::vector<std::string>& names) {
  MutexLock lock(mu_);
  check_writes();
  for (const std::string& n : names) credentials_.erase(n);
}

std::vector<StoredCredential> MemoryJobStore::credentials() const {
  MutexLock lock(mu_);
  std::vector<StoredCredential> out;
  for (const auto& [name, c] : credentials_) out.push_back(c);
  return out;
}

void MemoryJobStore::append_events(std::vector<Event>& events) {
  MutexLock lock(mu_);
  check_writes();
  for (Event& e : events) {
    e.id = ++last_event_;
    events_.push_back(e);
  }
  while (events_.size() > kMaxEvents) events_.pop_front();
}

std::vector<Event> MemoryJobStore::events(const std::string& job, uint64_t after, size_t limit, bool newest) const {
  MutexLock lock(mu_);
  std::vector<Event> out;
  for (const Event& e : events_)
    if (e.id > after && (job.empty() || e.job == job)) out.push_back(e);
  if (out.size() > limit)
    out.erase(newest ? out.begin() : out.begin() + ptrdiff_t(limit), newest ? out.end() - ptrdiff_t(limit) : out.end());
  return out;
}

std::unique_ptr<CheckpointFile> MemoryJobStore::begin_checkpoint(const std::string& id) const {
  {
    MutexLock lock(mu_);
    if (fail_writes) throw std::runtime_error("checkpoint: disk I/O error (a test's)");
  }
  return std::make_unique<MemoryCheckpoint>([this, id](std::string bytes) {
    MutexLock lock(mu_);
    if (fail_writes) throw std::runtime_error("checkpoint: disk I/O error (a test's)");
    checkpoints_[id] = std::move(bytes);
  });
}

std::optional<double> MemoryJobStore::read_checkpoint(const std::string& id, FramePlan& plan, bool with_film,
                                                      FrameSplats* splats) const {
  const std::optional<std::string> bytes = checkpoint_bytes(id);
  if (!bytes) return std::nullopt;
  return tessera::read_checkpoint(*bytes, plan, with_film, splats);
}

std::optional<std::string> MemoryJobStore::checkpoint_bytes(const std::string& id) const {
  MutexLock lock(mu_);
  auto it = checkpoints_.find(id);
  if (it == checkpoints_.end()) return std::nullopt;
  return it->second;
}

void MemoryJobStore::set_checkpoint_bytes(const std::string& id, std::optional<std::string> bytes) {
  MutexLock lock(mu_);
  if (bytes)
    checkpoints_[id] = std::move(*bytes);
  else
    checkpoints_.erase(id);
}

}  // namespace tessera
