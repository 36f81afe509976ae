// Leases: which worker renders which task, until when. A lease not renewed by heartbeats
// expires. Ended leases are remembered while their job lives, so that a late result is
// still recognised (and merged if nobody else's was): the newest kEndedPerPass of each
// (job, tile, pass), so that leasing and releasing the same tiles over and over cannot
// grow the table past a bound of the job's size. Once their passes are merged, only their
// ids are kept (a bit each), to tell a late result as a duplicate: a record and a deque
// per merged (tile, pass), about 0.9 KB, grew a job of 2,000 tiles x 1,000 passes by 2 GB.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "wire.h"

namespace tessera {

struct Lease {
  std::string job;
  uint32_t tile = 0, pass = 0;
  uint64_t worker = 0;
  double deadline = 0;
  // Verification: `task` is kept when the result is to be rendered again by another
  // worker; `check` names the check a lease renders (0: an ordinary task).
  std::shared_ptr<const v1::Task> task;
  uint64_t check = 0;
  double granted = 0;       // when (a backup goes to a tile leased long ago)
  uint32_t pass_count = 1;  // a run of passes [pass, pass + pass_count) (FramePlan::take)
  // One of its worker's probation tasks (WorkerInfo::probation): given back to the worker's
  // probation if the lease ends without its result merged (another lease of the tile won,
  // or it expired), so a registration's first merged results are the checked ones.
  bool probation = false;
  uint32_t tile_resets = 0;  // its tile's Job::tile_resets when granted
  bool refused = false;      // a result of it did not decode (ResultIntake::refuse): counted once
};

class LeaseTable {
 public:
  static constexpr size_t kEndedPerPass = 4;

  // Task ids count up from `first_id`: a restarted coordinator starts past the last run's,
  // so a result for a task of that run is never taken for one of this run.
  explicit LeaseTable(uint64_t first_id = 1) : next_(first_id) {}
  uint64_t grant(Lease lease);  // returns the new task id
  const Lease* live(uint64_t id) const;
  Lease* live(uint64_t id) { return const_cast<Lease*>(static_cast<const LeaseTable*>(this)->live(id)); }
  // A live or ended lease: whoever returns its result first is merged.
  const Lease* known(uint64_t id) const;
  // Extends a live lease of this worker; false if it is not live or not the worker's.
  bool renew(uint64_t id, uint64_t worker, double deadline);
  // Ends a live lease (kept as known); nothing if it is not live.
  std::optional<Lease> end(uint64_t id);
  // Ends every live lease past its deadline; returns them with their ids.
  std::vector<std::pair<uint64_t, Lease>> expire(double now);
  // Ends every live lease of the job, and forgets all its leases.
  void forget_job(const std::string& job);
  // Forgets the ended ordinary (not check) leases of the job's tile that `wanted` says are
  // no longer wanted (their passes merged), keeping only their ids (was_merged).
  void forget_merged(const std::string& job, uint32_t tile, const std::function<bool(const Lease&)>& wanted);
  // A lease forget_merged forgot: a result for it is a duplicate.
  bool was_merged(uint64_t id) const;
  // The live leases granted before `time` (held past a bound on a task's time).
  std::vector<uint64_t> granted_before(double time) const;
  // The live leases a worker holds.
  std::vector<uint64_t> held_by(uint64_t worker) const;
  // Live leases of a job: how many distinct workers hold them.
  uint32_t workers_on(const std::string& job) const;
  // The same over several jobs (a sequence's frames): a worker on two frames counts once.
  uint32_t workers_on(const std::set<std::string>& jobs) const;
  size_t live_count() const { return live_.size(); }
  size_t ended_count() const { return ended_.size(); }
  const std::map<uint64_t, Lease>& live_leases() const { return live_; }  // oldest (lowest id) first

 private:
  // Keeps an ended lease, forgetting the oldest of its (job, tile, pass) past kEndedPerPass.
  void remember_ended(uint64_t id, const Lease& l);

  std::map<uint64_t, Lease> live_, ended_;
  // The ended leases' ids by (job, tile, pass), oldest first.
  std::map<std::tuple<std::string, uint32_t, uint32_t>, std::deque<uint64_t>> ended_by_pass_;
  // Ids, a bit each, in blocks of kIdBlock consecutive ids (only blocks that hold one).
  class IdSet {
   public:
    void insert(uint64_t id) { blocks_[id / kIdBlock][id % kIdBlock / 64] |= uint64_t(1) << (id % 64); }
    bool contains(uint64_t id) const {
      auto it = blocks_.find(id / kIdBlock);
      return it != blocks_.end() && (it->second[id % kIdBlock / 64] >> (id % 64) & 1);
    }

   private:
    static constexpr uint64_t kIdBlock = 1024;
    std::unordered_map<uint64_t, std::array<uint64_t, kIdBlock / 64>> blocks_;
  };
  std::map<std::string, IdSet> merged_;  // by job
  uint64_t next_ = 1;
};

}  // namespace tessera
