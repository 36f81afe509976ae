// The coordinator's state machine, free of gRPC and HTTP so tests can drive it directly.
//
// A job's frame is cut into tiles; a task is one tile for one pass. A tile's pass k+1 is
// handed out only after its pass k was merged, so every pixel's sums are added in pass
// order and the image is bit-identical to `tessera render` (see docs/architecture.md).
// Tasks are leased: a lease not renewed by heartbeats expires and the task goes to another
// worker. Results are identified by task id; a result for a (tile, pass) already merged
// is a duplicate and is dropped.
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/io/image_io.h"
#include "core/render/film.h"
#include "core/render/settings.h"
#include "wire.h"

namespace tessera {

// Time source, a seam for tests.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual double now() const = 0;  // seconds
};

class SteadyClock : public Clock {
 public:
  double now() const override {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }
};

struct CoordinatorOptions {
  std::string data_dir = "tessera-data";
  uint32_t default_tile_size = 64;
  double lease_seconds = 10;
  double heartbeat_seconds = 2;
  double image_interval_seconds = 5;  // progressive images at most this often
  // Test seam: runs between an image snapshot leaving the lock and its write.
  std::function<void()> before_image_write;
};

// A request the coordinator refuses, with a message for the client.
class RequestError : public std::runtime_error {
 public:
  enum class Code { kInvalidArgument, kNotFound, kFailedPrecondition };
  RequestError(Code code, const std::string& what) : std::runtime_error(what), code_(code) {}
  Code code() const { return code_; }

 private:
  Code code_;
};

struct CoordinatorCounters {
  uint64_t tasks_dispatched = 0, results_merged = 0, results_duplicate = 0, results_rejected = 0;
  uint64_t leases_expired = 0, leases_released = 0, samples_merged = 0, jobs_submitted = 0, jobs_refused = 0;
  uint64_t images_written = 0;
  double merge_seconds = 0;
};

class Coordinator {
 public:
  Coordinator(CoordinatorOptions options, std::unique_ptr<Clock> clock = std::make_unique<SteadyClock>());
  ~Coordinator();

  // Client side. Throw RequestError.
  std::string submit(const v1::SubmitJobRequest& request);
  v1::JobStatus status(const std::string& id, bool with_tiles) const;
  std::vector<v1::JobStatus> list() const;
  v1::JobStatus cancel(const std::string& id);
  v1::Image image(const std::string& id);                                 // writes one if none was written yet
  std::string image_path(const std::string& id, const char* file) const;  // exr/png on disk

  // Worker side.
  v1::RegisterResponse register_worker(const v1::RegisterRequest& request);
  v1::GetTaskResponse get_task(uint64_t worker_id);
  v1::SceneBundle scene(const std::string& hash) const;
  bool heartbeat(uint64_t worker_id, uint64_t task_id);
  v1::ResultAck submit_result(const v1::TaskResult& result);
  void release(uint64_t worker_id, uint64_t task_id);

  // Waits up to `timeout` seconds for a change that may make work available (a job
  // submitted, a tile pass merged, a lease ended): lets GetTask long-poll.
  void wait_for_work(double timeout) const;
  // Expires overdue leases; get_task calls it too. Returns how many expired.
  size_t expire_leases();
  // Blocks until a job ends or `timeout` seconds pass; returns its status.
  v1::JobStatus wait_for_change(const std::string& id, uint64_t last_samples, double timeout) const;

  struct WorkerInfo {
    uint64_t id = 0;
    std::string name;
    uint32_t threads = 0;
    double last_seen = 0;
    double samples_per_second = 0;  // smoothed over results
    uint64_t tasks_done = 0;
    uint64_t current_task = 0;
  };
  std::vector<WorkerInfo> workers() const;
  CoordinatorCounters counters() const;
  double uptime() const;
  const CoordinatorOptions& options() const { return options_; }

 private:
  struct Job;
  struct TaskRecord {
    std::string job;
    uint32_t tile = 0, pass = 0;
    uint64_t worker = 0;
    double deadline = 0;
  };

  Job* find(const std::string& id) const;  // mu_ held
  v1::JobStatus status_locked(const Job& job, bool with_tiles) const;
  // A film snapshot to write outside the lock, newest-wins by sequence number.
  struct ImageSnapshot {
    Job* job = nullptr;
    std::unique_ptr<Film> film;
    ImageMetadata meta;
    uint64_t seq = 0;
    uint64_t merges = 0;  // the film version copied
  };
  void finish_tile_pass(Job& job, uint32_t tile, double now);
  ImageSnapshot snapshot_locked(Job& job);
  void write_snapshot(const ImageSnapshot& snap);  // mu_ not held
  void write_image(Job& job);                      // mu_ not held: snapshot, then write
  // Ends a lease: the tile loses it (and, with `requeue`, waits for its next worker), the
  // worker is no longer busy with it, and its record is kept so a late result is known.
  std::map<uint64_t, TaskRecord>::iterator end_lease_locked(std::map<uint64_t, TaskRecord>::iterator it, bool requeue);
  size_t expire_leases_locked(double now);

  CoordinatorOptions options_;
  std::unique_ptr<Clock> clock_;
  double started_ = 0;
  mutable std::mutex mu_;
  mutable std::condition_variable changed_;
  std::map<std::string, std::unique_ptr<Job>> jobs_;
  std::map<std::string, v1::SceneBundle> scenes_;  // by content hash
  std::map<uint64_t, TaskRecord> tasks_;           // live leases by task id
  std::map<uint64_t, TaskRecord> expired_;         // ended leases of live jobs: late results
                                                   // are still merged if nobody else's was
  std::map<uint64_t, WorkerInfo> workers_;
  uint64_t next_task_ = 1, next_worker_ = 1, next_job_ = 1;
  CoordinatorCounters counters_;
};

}  // namespace tessera
