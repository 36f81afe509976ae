#include "server/lease_table.h"

#include <set>

namespace tessera {

uint64_t LeaseTable::grant(Lease lease) {
  const uint64_t id = next_++;
  live_.emplace(id, std::move(lease));
  return id;
}

const Lease* LeaseTable::live(uint64_t id) const {
  auto it = live_.find(id);
  return it == live_.end() ? nullptr : &it->second;
}

const Lease* LeaseTable::known(uint64_t id) const {
  if (const Lease* l = live(id)) return l;
  auto it = ended_.find(id);
  return it == ended_.end() ? nullptr : &it->second;
}

bool LeaseTable::renew(uint64_t id, uint64_t worker, double deadline) {
  auto it = live_.find(id);
  if (it == live_.end() || it->second.worker != worker) return false;
  it->second.deadline = deadline;
  return true;
}

void LeaseTable::remember_ended(uint64_t id, const Lease& l) {
  ended_.emplace(id, l);
  std::deque<uint64_t>& ids = ended_by_pass_[{l.job, l.tile, l.pass}];
  ids.push_back(id);
  if (ids.size() > kEndedPerPass) {
    ended_.erase(ids.front());
    ids.pop_front();
  }
}

std::optional<Lease> LeaseTable::end(uint64_t id) {
  auto it = live_.find(id);
  if (it == live_.end()) return std::nullopt;
  Lease l = it->second;
  live_.erase(it);
  remember_ended(id, l);
  return l;
}

std::vector<std::pair<uint64_t, Lease>> LeaseTable::expire(double now) {
  std::vector<std::pair<uint64_t, Lease>> out;
  for (auto it = live_.begin(); it != live_.end();) {
    if (it->second.deadline >= now) {
      ++it;
      continue;
    }
    out.emplace_back(it->first, it->second);
    remember_ended(it->first, it->second);
    it = live_.erase(it);
  }
  return out;
}

std::vector<uint64_t> LeaseTable::granted_before(double time) const {
  std::vector<uint64_t> out;
  for (const auto& [id, l] : live_)
    if (l.granted < time) out.push_back(id);
  return out;
}

void LeaseTable::forget_job(const std::string& job) {
  for (auto* m : {&live_, &ended_})
    for (auto it = m->begin(); it != m->end();) it = it->second.job == job ? m->erase(it) : std::next(it);
  ended_by_pass_.erase(ended_by_pass_.lower_bound({job, 0, 0}),
                       ended_by_pass_.upper_bound({job, UINT32_MAX, UINT32_MAX}));
  merged_.erase(job);
}

void LeaseTable::forget_merged(const std::string& job, uint32_t tile, const std::function<bool(const Lease&)>& wanted) {
  auto it = ended_by_pass_.lower_bound({job, tile, 0});
  const auto end = ended_by_pass_.upper_bound({job, tile, UINT32_MAX});
  while (it != end) {
    std::deque<uint64_t>& ids = it->second;
    for (auto id = ids.begin(); id != ids.end();) {
      auto l = ended_.find(*id);
      if (l == ended_.end() || l->second.check || wanted(l->second)) {
        ++id;
        continue;
      }
      merged_[job].insert(*id);
      ended_.erase(l);
      id = ids.erase(id);
    }
    it = ids.empty() ? ended_by_pass_.erase(it) : std::next(it);
  }
}

bool LeaseTable::was_merged(uint64_t id) const {
  for (const auto& [job, ids] : merged_)
    if (ids.contains(id)) return true;
  return false;
}

std::vector<uint64_t> LeaseTable::held_by(uint64_t worker) const {
  std::vector<uint64_t> out;
  for (const auto& [id, l] : live_)
    if (l.worker == worker) out.push_back(id);
  return out;
}

uint32_t LeaseTable::workers_on(const std::string& job) const { return workers_on(std::set<std::string>{job}); }

uint32_t LeaseTable::workers_on(const std::set<std::string>& jobs) const {
  std::set<uint64_t> w;
  for (const auto& [id, l] : live_)
    if (jobs.count(l.job)) w.insert(l.worker);
  return uint32_t(w.size());
}

}  // namespace tessera
