#include "server/worker_registry.h"

namespace tessera {

WorkerInfo& WorkerRegistry::add(const std::string& name, uint32_t threads, double now) {
  WorkerInfo w;
  w.id = next_++;
  w.name = name.substr(0, 256);
  w.threads = threads;
  w.last_seen = now;
  return workers_[w.id] = w;
}

WorkerInfo* WorkerRegistry::find(uint64_t id) {
  auto it = workers_.find(id);
  return it == workers_.end() ? nullptr : &it->second;
}

std::vector<uint64_t> WorkerRegistry::forget_silent(double now, double timeout) {
  std::vector<uint64_t> gone;
  for (auto it = workers_.begin(); it != workers_.end();) {
    if (now - it->second.last_seen > timeout) {
      gone.push_back(it->first);
      it = workers_.erase(it);
    } else {
      ++it;
    }
  }
  return gone;
}

std::vector<WorkerInfo> WorkerRegistry::list() const {
  std::vector<WorkerInfo> out;
  for (const auto& [id, w] : workers_) out.push_back(w);
  return out;
}

void WorkerRegistry::record_result(uint64_t id, uint64_t samples, double seconds, double now) {
  WorkerInfo* w = find(id);
  if (!w) return;
  w->last_seen = now;
  ++w->tasks_done;
  if (seconds > 0) {
    const double rate = double(samples) / seconds;
    w->samples_per_second = w->samples_per_second > 0 ? 0.8 * w->samples_per_second + 0.2 * rate : rate;
  }
}

}  // namespace tessera
