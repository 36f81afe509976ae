// Verify by replay's data: the checks waiting for or being rendered by a second worker, and
// who is quarantined. The rules are Verifier's; Leasing and JobLifecycle keep a check's
// lease and a job's checks in step.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "wire.h"

namespace tessera {

struct Check {
  std::string job;
  uint32_t tile = 0, pass = 0;
  std::shared_ptr<const v1::Task> task;  // as the first worker got it
  uint64_t first_worker = 0;
  uint64_t first_serial = 0;  // its registration's (WorkerInfo::serial)
  uint64_t digest = 0;        // of the merged sums
  uint64_t lease = 0;         // the check's live lease (0: waiting for a worker)
  double since = 0;           // waiting since
};

class CheckBook {
 public:
  uint64_t add(Check c) {
    const uint64_t id = next_++;
    checks_[id] = std::move(c);
    return id;
  }
  Check* find(uint64_t id) {
    auto it = checks_.find(id);
    return it == checks_.end() ? nullptr : &it->second;
  }
  std::map<uint64_t, Check>& all() { return checks_; }
  const std::map<uint64_t, Check>& all() const { return checks_; }
  void erase(uint64_t id) { checks_.erase(id); }
  // Forgets every check of the job; returns their live leases (to end).
  std::vector<uint64_t> erase_job(const std::string& job) {
    std::vector<uint64_t> leases;
    for (auto it = checks_.begin(); it != checks_.end();) {
      if (it->second.job != job) {
        ++it;
        continue;
      }
      if (it->second.lease) leases.push_back(it->second.lease);
      it = checks_.erase(it);
    }
    return leases;
  }
  size_t waiting() const {  // checks no worker holds
    size_t n = 0;
    for (const auto& [id, c] : checks_) n += c.lease == 0;
    return n;
  }

  bool quarantined(uint64_t worker) const { return workers_.count(worker) > 0; }
  // False if the worker was already. (An enrolled worker's credential is quarantined in
  // the CredentialBook; a token from the file, which many workers may share, never is.)
  bool quarantine(uint64_t worker) { return workers_.insert(worker).second; }

 private:
  std::map<uint64_t, Check> checks_;
  uint64_t next_ = 1;
  std::set<uint64_t> workers_;  // quarantined worker ids
};

}  // namespace tessera
