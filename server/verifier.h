// Verify by replay (CoordinatorOptions::verify_fraction; docs/security.md). A fraction of
// tasks, picked at random, keeps its Task; when its result is merged a check is issued and
// handed to another worker before ordinary tasks. Equal digests pass. Different ones are
// judged by the Referee (this process renders the task) and whoever differs is quarantined:
// its leases end, every tile of a live job it merged into starts over, ended jobs are
// flagged. A job ends only once its checks are decided (or skipped: no other worker took
// one for two lease periods). Runs under the coordinator's lock but for judge().
#pragma once

#include <functional>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "server/job_lifecycle.h"

namespace tessera {

// Renders a task as this process would: the referee when two workers differ.
// A job with AOVs: their sums too (empty otherwise).
struct RefereeRender {
  std::vector<PixelSums> sums;
  std::vector<AovSums> aovs;
  std::vector<SplatRecord> splats;  // a frame tracing light paths: one record per pass
  RefereeRender(std::vector<PixelSums> s, std::vector<AovSums> a = {},  // NOLINT: a tile's sums are a render
                std::vector<SplatRecord> sp = {})
      : sums(std::move(s)), aovs(std::move(a)), splats(std::move(sp)) {}
};
using Referee = std::function<RefereeRender(const v1::Task&)>;

// Of the sums' values (not their padding or wire encoding, which may differ between two
// honest workers): equal digests, equal bits.
// The digest a check compares: a result's sums, and its AOV sums when the job has them.
// With `splats` (a frame tracing light paths), the task's splat records too.
uint64_t sums_digest(const std::vector<PixelSums>& sums, const std::vector<AovSums>* aovs = nullptr,
                     const std::vector<SplatRecord>* splats = nullptr);
// The digest of a check's result (decoded as for merging); nothing when it is malformed,
// and what is wrong with it in *why.
std::optional<uint64_t> result_digest(const v1::TaskResult& result, const Check& check, std::string* why);

class Verifier {
 public:
  Verifier(double verify_fraction, double lease_seconds, CheckBook& checks, JobTable& jobs, Leasing& leasing,
           WorkerRegistry& workers, JobLifecycle& lifecycle, CoordinatorCounters& counters)
      : fraction_(verify_fraction),
        lease_seconds_(lease_seconds),
        checks_(checks),
        jobs_(jobs),
        leasing_(leasing),
        workers_(workers),
        lifecycle_(lifecycle),
        counters_(counters) {}

  bool active() const { return fraction_ > 0 && workers_.size() > 1; }  // it needs a second worker
  bool pick() { return std::uniform_real_distribution<double>(0, 1)(rng_) < fraction_; }
  // A picked task's result was merged: its check waits for another worker.
  void issue(Job& job, const Lease& lease, uint64_t worker, uint64_t digest, double now);
  // Leases waiting checks to the worker (only those it may_check), up to `max` tasks in all
  // in `out`.
  void lease_checks(WorkerInfo& worker, uint32_t max, double now, v1::GetTaskResponse& out);
  // Whether the worker may render the check: not the first worker, nor, once the first
  // worker's registration has ended, a worker registered after it (maybe itself again).
  bool may_check(const Check& c, const WorkerInfo& worker);

  // A check's result came: the check, unless it was decided or became moot.
  std::optional<Check> pending(uint64_t check, uint64_t task_id) const;
  struct Verdict {
    bool same = true;             // the checker's sums equal the merged ones
    std::vector<uint64_t> liars;  // who differs from the referee's render
    std::string why;
  };
  // Outside the lock: compares, and asks the referee when the two differ.
  static Verdict judge(const Check& check, uint64_t digest, uint64_t checker, const Referee& referee);
  // Under the lock again: the check is decided. Returns whether the checker's result counts.
  bool decide(uint64_t check, uint64_t task_id, uint64_t checker, const Verdict& v, double now, Effects& fx);

  // Checks nobody can take (no other worker) or took for two lease periods are skipped, so
  // a job does not wait for a second worker forever.
  void skip_stale(double now, Effects& fx);
  bool quarantined(uint64_t worker) const { return checks_.quarantined(worker); }
  // A worker found lying (decide() calls it): its leases end, what it merged into live jobs
  // is rendered again (a frame with light paths' splats whole: they are not told apart), ended jobs (and sequences
  // whose frames left memory) are flagged. Archived jobs (archive.h) are flagged in their rows, through fx.flags; an
  // enrolled worker's credential is quarantined through fx.credentials_quarantined.
  void quarantine(uint64_t worker, const std::string& why, double now, Effects& fx);
  // What an ended job is flagged with when `tiles` of its tiles (a sequence's finished
  // frames': `frames`) hold results of `worker`, quarantined after it ended.
  static std::string ended_flag(uint32_t tiles, const std::string& worker, bool frames);

 private:
  void drop(uint64_t check, bool skipped, double now);
  // An ended job holds a liar's tiles: said in its error and its database row (a frame's
  // in its sequence's).
  void flag_ended(Job& job, const std::string& flag, Effects& fx);
  void flag_sequence(Sequence& s, const std::string& flag, Effects& fx);

  double fraction_, lease_seconds_;
  CheckBook& checks_;
  JobTable& jobs_;
  Leasing& leasing_;
  WorkerRegistry& workers_;
  JobLifecycle& lifecycle_;
  CoordinatorCounters& counters_;
  std::mt19937_64 rng_{std::random_device{}()};
};

}  // namespace tessera
