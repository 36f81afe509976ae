#include "server/worker_registry.h"

#include <algorithm>
#include <cmath>

#include "core/util/text.h"
#include "server/secrets.h"

namespace tessera {

WorkerInfo& WorkerRegistry::add(const std::string& name, uint32_t threads, double now, std::string* secret) {
  WorkerInfo w;
  // 53 random bits: unguessable, and exact as a JSON number in a browser.
  do {
    w.id = random_u64() >> 11;
  } while (w.id == 0 || workers_.count(w.id));
  const std::string s = random_hex(16);
  w.secret_digest = sha256(s);
  if (secret) *secret = s;
  w.serial = ++serial_;
  w.name = peer_text(name, kMaxTextBytes);
  w.threads = std::clamp<uint32_t>(threads, 1, kMaxThreads);
  w.last_seen = now;
  threads_ += w.threads;
  return workers_[w.id] = w;
}

void WorkerRegistry::remove(uint64_t id) {
  auto it = workers_.find(id);
  if (it == workers_.end()) return;
  threads_ -= it->second.threads;
  workers_.erase(it);
}

bool WorkerRegistry::secret_matches(const WorkerInfo& w, const std::string& secret) const {
  return equal_secret(sha256(secret), w.secret_digest);
}

size_t WorkerRegistry::count_principal(const std::string& principal) const {
  size_t n = 0;
  for (const auto& [id, w] : workers_) n += w.principal == principal;
  return n;
}

size_t WorkerRegistry::count_before(uint64_t serial) const {
  size_t n = 0;
  for (const auto& [id, w] : workers_) n += w.serial < serial;
  return n;
}

WorkerInfo* WorkerRegistry::find(uint64_t id) {
  auto it = workers_.find(id);
  return it == workers_.end() ? nullptr : &it->second;
}

std::vector<WorkerInfo> WorkerRegistry::forget_silent(double now, double timeout) {
  std::vector<WorkerInfo> gone;
  for (auto it = workers_.begin(); it != workers_.end();) {
    if (now - it->second.last_seen > timeout) {
      gone.push_back(it->second);
      threads_ -= it->second.threads;
      it = workers_.erase(it);
    } else {
      ++it;
    }
  }
  return gone;
}

double WorkerInfo::utilization_at(double now) const {
  return now - last_report > 2 * WorkerRegistry::kWindowSeconds ? 0 : utilization;
}

std::vector<WorkerInfo> WorkerRegistry::list(double now) const {
  std::vector<WorkerInfo> out;
  for (const auto& [id, w] : workers_) {
    out.push_back(w);
    out.back().utilization = w.utilization_at(now);
  }
  return out;
}

void WorkerRegistry::record_result(uint64_t id, uint64_t samples, uint64_t bytes, double seconds,
                                   double busy_thread_seconds, double thread_seconds, double now) {
  WorkerInfo* w = find(id);
  if (!w) return;
  w->last_seen = now;
  w->last_report = now;
  ++w->tasks_done;
  w->result_bytes += bytes;
  w->result_samples += samples;
  // `seconds` is the worker's word: a rate only from a finite time, and never over
  // `samples` in kMinTaskSeconds (one report of 1e-300 s made this worker's speed, the
  // farm's thread speed and so the remaining-work signal infinite for good).
  if (std::isfinite(seconds) && seconds > 0) {
    const double rate = double(samples) / std::max(seconds, kMinTaskSeconds);
    w->samples_per_second = w->samples_per_second > 0 ? 0.8 * w->samples_per_second + 0.2 * rate : rate;
  }
  // Reports only grow; one that does not (a restarted worker process reusing an id
  // cannot, ids are never reused), or is not finite, is ignored.
  if (!std::isfinite(thread_seconds) || !std::isfinite(busy_thread_seconds)) return;
  if (!(thread_seconds >= w->thread_seconds) || !(busy_thread_seconds >= w->busy_thread_seconds)) return;
  if (w->window_start == 0 || now - w->window_start > kWindowSeconds) {
    w->window_busy = w->busy_thread_seconds;
    w->window_threads = w->thread_seconds;
    w->window_start = now;
  }
  w->busy_thread_seconds = busy_thread_seconds;
  w->thread_seconds = thread_seconds;
  const double dt = w->thread_seconds - w->window_threads;
  if (dt > 0) w->utilization = std::min(1.0, (w->busy_thread_seconds - w->window_busy) / dt);
}

double WorkerRegistry::utilization(double now) const {
  double busy = 0, threads = 0;
  for (const auto& [id, w] : workers_) {
    if (now - w.last_report > 2 * kWindowSeconds) {  // idle: a window of its threads, unused
      threads += w.threads * kWindowSeconds;
      continue;
    }
    busy += w.busy_thread_seconds - w.window_busy;
    threads += w.thread_seconds - w.window_threads;
  }
  return threads > 0 ? std::min(1.0, busy / threads) : 0;
}

double WorkerRegistry::thread_speed() const {
  double speed = 0, threads = 0;
  for (const auto& [id, w] : workers_)
    if (w.samples_per_second > 0) {
      speed += w.samples_per_second;
      threads += w.threads;
    }
  if (threads > 0) last_thread_speed_ = speed / threads;
  return last_thread_speed_;
}

}  // namespace tessera
