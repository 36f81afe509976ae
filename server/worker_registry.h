// The workers the coordinator knows: registered, and heard from recently.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace tessera {

struct WorkerInfo {
  uint64_t id = 0;
  uint64_t serial = 0;  // registrations count up: a higher serial registered later
  std::string name;
  std::string host;       // as the worker says (gethostname), else the address it registered from
  std::string principal;  // the access token's name ("" without tokens)
  bool enrolled = false;  // principal is the worker's own credential (credentials.h)
  // Who it is across registrations: its own credential where it has one (registering
  // again does not make it another worker), else this registration.
  std::string identity() const { return enrolled ? "credential " + principal : "registration " + std::to_string(id); }
  uint32_t probation = 0;  // tasks still to check whatever the fraction (verify_first)
  bool draining = false;   // an operator drained it: no new tasks until resumed
  // What it was given last (the live page): job, tile, pass, and whether as a backup.
  std::string last_job;
  uint32_t last_tile = 0, last_pass = 0;
  bool last_backup = false;
  std::string secret_digest;  // SHA-256 of the secret its registration was given
  uint32_t threads = 0;
  double last_seen = 0;
  double samples_per_second = 0;  // smoothed over results
  uint64_t tasks_done = 0;
  uint32_t leases = 0;    // live leases held
  double round_trip = 0;  // seconds, as the worker measures it (heartbeats); 0: not reported
  // The link's load: compressed sums of this worker's merged results, and their samples.
  uint64_t result_bytes = 0, result_samples = 0;
  uint32_t passes_per_task = 1;  // what its last GetTask asked for (a slow link asks for runs)
  // Render-thread time as the worker reports it with each result, since it registered:
  // busy (rendering) and threads x wall. Utilization is their ratio over the last few
  // seconds of reports, so a worker idle between jobs does not dilute a busy one.
  double busy_thread_seconds = 0, thread_seconds = 0;
  double utilization = 0;
  double window_busy = 0, window_threads = 0, window_start = 0;  // the window's first report
  double last_report = 0;                                        // its last result's time
  // Its utilization as of `now`: 0 once it has sent no result for two windows (an idle
  // worker reports nothing, and its last figure must not stand for ever).
  double utilization_at(double now) const;
};

class WorkerRegistry {
 public:
  static constexpr uint32_t kMaxThreads = 4096;  // a worker's claimed threads, at most
  // A worker's name and host are kept to this many bytes (whole UTF-8 characters).
  static constexpr size_t kMaxTextBytes = 256;
  // `threads` is clamped to [1, kMaxThreads]: it weighs the worker's share of the work.
  // The id (53 bits) and, into `secret` when given, 128 bits (hex) come from OpenSSL's
  // CSPRNG: neither says anything about another worker's.
  WorkerInfo& add(const std::string& name, uint32_t threads, double now, std::string* secret = nullptr);
  WorkerInfo* find(uint64_t id);
  // Whether `secret` is the one worker `id` was given (constant time in the secret).
  bool secret_matches(const WorkerInfo& w, const std::string& secret) const;
  // Workers registered under this access token name.
  size_t count_principal(const std::string& principal) const;
  // Workers registered before the one given `serial`.
  size_t count_before(uint64_t serial) const;
  // Forgets workers not heard from for `timeout` seconds; returns them. (A forgotten worker
  // that comes back is told to register again.)
  std::vector<WorkerInfo> forget_silent(double now, double timeout);
  void remove(uint64_t id);
  size_t size() const { return workers_.size(); }
  uint64_t threads() const { return threads_; }  // of every known worker
  // Every worker, its utilization as of `now`.
  std::vector<WorkerInfo> list(double now) const;
  // A finished task: its render rate (`samples`, as merged, over the worker's `seconds`)
  // feeds the worker's smoothed speed; its thread-time counters the utilization.
  void record_result(uint64_t id, uint64_t samples, uint64_t bytes, double seconds, double busy_thread_seconds,
                     double thread_seconds, double now);
  // The shortest render time a rate is computed over (a worker's report of less counts
  // as this much).
  static constexpr double kMinTaskSeconds = 1e-3;
  // Busy over available render-thread time of every worker, over their windows; a worker
  // silent for two windows counts as idle.
  double utilization(double now) const;
  static constexpr double kWindowSeconds = 5;
  // Samples a second per render thread, over the workers that have measured theirs; the
  // last such figure while none has (0 before any).
  double thread_speed() const;

 private:
  std::map<uint64_t, WorkerInfo> workers_;
  uint64_t threads_ = 0;
  uint64_t serial_ = 0;
  mutable double last_thread_speed_ = 0;
};

}  // namespace tessera
