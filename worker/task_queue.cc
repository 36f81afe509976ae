#include "worker/task_queue.h"

#include <spdlog/spdlog.h>

#include <algorithm>

namespace tessera::worker {

double Held::row_samples(int row) const {
  const uint32_t n = task.sample_end() - task.sample_begin();
  if (!mask) return double(rect.w) * n;
  int active = 0;
  for (int x = 0; x < rect.w; ++x) active += mask[size_t(row) * rect.w + x] != 0;
  return double(active) * n;
}

QueueLoad TaskQueue::load_locked() const {
  QueueLoad l{held_.size(), queued_rows_, queued_samples_, samples_per_thread_second_, round_trip_, max_leases_};
  l.passes_per_task = budget_.passes_per_task();
  l.pass_samples = pass_samples_;
  l.passes_fixed = budget_.fixed();
  return l;
}

void TaskQueue::set_max_leases(size_t coordinator_bound, size_t own_cap) {
  std::lock_guard<std::mutex> lock(mu_);
  max_leases_ = std::max<size_t>(1, own_cap > 0 ? std::min(coordinator_bound, own_cap) : coordinator_bound);
  more_.notify_one();
}

void TaskQueue::note_round_trip(double seconds) {
  std::lock_guard<std::mutex> lock(mu_);
  seconds = std::clamp(seconds, 0.0, 60.0);
  min_round_trip_ = min_round_trip_ <= 0 ? seconds : std::min(min_round_trip_, seconds);
  // As TCP smooths its round trip (RFC 6298, gain 1/8), but quicker to follow a longer one,
  // so that a slower link does not starve the threads while the average catches up.
  round_trip_ = round_trip_ <= 0        ? seconds
                : seconds > round_trip_ ? 0.5 * (round_trip_ + seconds)
                                        : 0.875 * round_trip_ + 0.125 * seconds;
  if (lookahead_.wants_more(load_locked())) more_.notify_one();
}

void TaskQueue::note_upload(const UploadBudget::Call& call) {
  std::lock_guard<std::mutex> lock(mu_);
  const uint32_t before = budget_.passes_per_task();
  budget_.note(call, min_round_trip_);
  if (budget_.passes_per_task() != before)
    spdlog::info("results outrun the link ({:.2f} MB/s): asking for tiles {} passes at a time",
                 budget_.link_rate() / 1e6, budget_.passes_per_task());
}

QueueLoad TaskQueue::load() const {
  std::lock_guard<std::mutex> lock(mu_);
  return load_locked();
}

std::optional<LeaseRequest> TaskQueue::wait_for_room(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  more_.wait_for(lock, timeout, [this] { return stopping_ || lookahead_.wants_more(load_locked()); });
  if (stopping_ || !lookahead_.wants_more(load_locked())) return std::nullopt;
  return lookahead_.request(load_locked());
}

void TaskQueue::preparing(uint64_t task_id) {
  std::lock_guard<std::mutex> lock(mu_);
  preparing_.insert(task_id);
}

void TaskQueue::not_prepared(uint64_t task_id) {
  std::lock_guard<std::mutex> lock(mu_);
  preparing_.erase(task_id);
  refused_.erase(task_id);
}

bool TaskQueue::add(std::shared_ptr<Held> h) {
  std::lock_guard<std::mutex> lock(mu_);
  preparing_.erase(h->task.task_id());
  if (refused_.erase(h->task.task_id())) return false;
  held_[h->task.task_id()] = h;
  queued_rows_ += uint64_t(h->rect.h);
  for (int row = 0; row < h->rect.h; ++row) queued_samples_ += h->row_samples(row);
  // Higher priority first, else in the order leased; a task whose rows have begun stays
  // in front, so that it finishes.
  auto at = queue_.begin();
  if (at != queue_.end() && (*at)->next_row > 0) ++at;
  at = std::find_if(at, queue_.end(),
                    [&](const std::shared_ptr<Held>& q) { return q->task.priority() < h->task.priority(); });
  queue_.insert(at, std::move(h));
  work_.notify_all();
  return true;
}

bool TaskQueue::holds_tasks() const {
  std::lock_guard<std::mutex> lock(mu_);
  return !held_.empty();
}

void TaskQueue::drop_all() {
  std::lock_guard<std::mutex> lock(mu_);
  while (!held_.empty()) drop_locked(held_.begin()->first);
  refused_.insert(preparing_.begin(), preparing_.end());
  preparing_.clear();
}

std::optional<TaskQueue::Row> TaskQueue::next_row() {
  std::unique_lock<std::mutex> lock(mu_);
  work_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
  if (stopping_) return std::nullopt;
  Row r{queue_.front(), queue_.front()->next_row++};
  if (r.task->next_row == r.task->rect.h) {
    queue_.pop_front();
    if (queue_.empty() && !outbox_.empty()) outbox_cv_.notify_one();  // results stop lingering
  }
  --queued_rows_;
  queued_samples_ -= r.task->row_samples(r.row);
  // Wake the fetcher only when it has something to do: a wake-up per row cost a 2-core
  // machine 4% of its render time in context switches.
  if (lookahead_.wants_more(load_locked())) more_.notify_one();
  return r;
}

void TaskQueue::row_done(const Row& r, const std::vector<PixelSums>& sums, const TileStats& stats, double t0, double t1,
                         const std::vector<AovSums>* aovs, const std::vector<SplatRecord>* splats) {
  std::lock_guard<std::mutex> lock(mu_);
  Held& h = *r.task;
  busy_thread_seconds_ += t1 - t0;
  h.busy += t1 - t0;
  h.first_row = h.rows_done == 0 ? t0 : std::min(h.first_row, t0);
  h.last_row = std::max(h.last_row, t1);
  const size_t w = size_t(h.rect.w), area = size_t(h.rect.area());  // each plane's row in its place
  for (size_t plane = 0; plane < sums.size() / w; ++plane)
    std::copy_n(sums.begin() + ptrdiff_t(plane * w), w, h.sums.begin() + ptrdiff_t(plane * area + size_t(r.row) * w));
  if (aovs && !h.aovs.empty()) std::copy(aovs->begin(), aovs->end(), h.aovs.begin() + ptrdiff_t(r.row) * h.rect.w);
  if (splats && splats->size() == h.splats.size())
    for (size_t pass = 0; pass < splats->size(); ++pass) h.splats[pass].append((*splats)[pass]);
  h.stats.add(stats);
  if (++h.rows_done == h.rect.h && !h.cancel) {
    if (h.busy > 0) {
      const double rate = double(h.stats.samples) / h.busy;
      samples_per_thread_second_ =
          samples_per_thread_second_ > 0 ? 0.7 * samples_per_thread_second_ + 0.3 * rate : rate;
      const double per_pass = double(h.stats.samples) / double(std::max<size_t>(1, h.passes.size()));
      pass_samples_ = pass_samples_ > 0 ? 0.7 * pass_samples_ + 0.3 * per_pass : per_pass;
    }
    // The sender sleeps through its linger: only the first result of a batch wakes it.
    if (outbox_.empty()) outbox_cv_.notify_one();
    outbox_.push_back(r.task);
  }
}

TaskQueue::Batch TaskQueue::take_finished(std::chrono::milliseconds linger) {
  std::unique_lock<std::mutex> lock(mu_);
  outbox_cv_.wait(lock, [this] { return stopping_ || !outbox_.empty(); });
  if (outbox_.empty()) return {};  // stopping, and everything finished was sent
  // While the render threads still have work, let results gather for a moment: one call
  // for several results. With nothing queued, a result may be what frees the next pass
  // of a tile, so it goes at once. (The render thread that takes the last queued row
  // wakes the sender early.)
  outbox_cv_.wait_for(lock, linger, [this] { return stopping_ || queue_.empty(); });
  Batch b{std::move(outbox_), busy_thread_seconds_};
  outbox_.clear();
  return b;
}

void TaskQueue::sent(const Batch& batch, bool ok) {
  std::lock_guard<std::mutex> lock(mu_);
  for (const std::shared_ptr<Held>& h : batch.tasks) {
    if (ok) ++tasks_done_;
    held_.erase(h->task.task_id());
  }
  more_.notify_one();
}

std::vector<uint64_t> TaskQueue::held_ids() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<uint64_t> ids;
  for (const auto& [id, h] : held_) ids.push_back(id);
  ids.insert(ids.end(), preparing_.begin(), preparing_.end());
  return ids;
}

void TaskQueue::drop_unfinished(const std::vector<uint64_t>& refused) {
  std::lock_guard<std::mutex> lock(mu_);
  for (uint64_t id : refused) {
    if (auto it = held_.find(id); it != held_.end() && it->second->rows_done < it->second->rect.h) drop_locked(id);
    if (preparing_.erase(id)) refused_.insert(id);
  }
}

void TaskQueue::drop_locked(uint64_t task_id) {
  auto it = held_.find(task_id);
  if (it == held_.end()) return;
  const std::shared_ptr<Held> h = it->second;
  h->cancel = true;
  for (auto q = queue_.begin(); q != queue_.end(); ++q)
    if (*q == h) {
      for (int row = h->next_row; row < h->rect.h; ++row) {
        --queued_rows_;
        queued_samples_ -= h->row_samples(row);
      }
      queue_.erase(q);
      break;
    }
  held_.erase(it);
  more_.notify_one();
}

bool TaskQueue::wait_stopped(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  return stopped_cv_.wait_for(lock, timeout, [this] { return stopping_; });
}

void TaskQueue::stop() {
  std::lock_guard<std::mutex> lock(mu_);
  stopping_ = true;
  for (auto& [id, h] : held_) h->cancel = true;
  work_.notify_all();
  more_.notify_all();
  outbox_cv_.notify_all();
  stopped_cv_.notify_all();
}

bool TaskQueue::stopping() const {
  std::lock_guard<std::mutex> lock(mu_);
  return stopping_;
}

std::vector<uint64_t> TaskQueue::take_held() {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<uint64_t> ids;
  for (const auto& [id, h] : held_) ids.push_back(id);
  ids.insert(ids.end(), preparing_.begin(), preparing_.end());
  held_.clear();
  queue_.clear();
  refused_.insert(preparing_.begin(), preparing_.end());  // (given back: not to be added after)
  preparing_.clear();
  return ids;
}

}  // namespace tessera::worker
