// The coordinator: the farm's state behind one lock, the units that act on it, and the
// calls gRPC (grpc_services.cc) and HTTP (status_http.cc) make. It decides nothing itself:
//
//   submit       admission.h (request, limits) -> submission.h (scene checked, films made, recorded)
//   lease        dispatcher.h (which tasks, fair shares, checks first); leasing.h (grant, renew, expire)
//   frames       sequence_scheduler.h (which frame starts next; frames made outside the lock)
//   result       result_intake.h (screen, decode outside the lock, merge)
//   check        verifier.h (verify by replay, quarantine); referee.h (renders a disputed task)
//   job state    job_lifecycle.h (start, end, cancel, failure: the one writer of states)
//   workers      worker_lifecycle.h (register, heartbeat, release, unregister)
//   images       snapshotter.h (progressive images and checkpoints: taken, then written)
//   restart      recovery.h (jobs back from the JobStore and checkpoints)
//   load         job_table.h (Load: what live work weighs, counted once)
//   status       job_status.h (what clients see of a job, and the list)
//   after submit job_control.h (priority, requeue, delete; the disk work between the steps)
//   ended jobs   archive.h (leave memory for their rows; read back from them: coordinator_reads.cc)
// A new feature gets its own unit beside these, reached from here by one forwarding call;
// docs/architecture.md says where each step of a task's life is.
//
// Lock rules (clang proves 1 and 2 with -Wthread-safety; core/util/mutex.h):
//  1. mu_ guards the farm's state (jobs, leases, workers, checks, counters) and the units
//     acting on it: both are members declared TESSERA_GUARDED_BY(mu_), reached only through
//     this class. The units hold references to each other and to the state, and are called
//     only with mu_ held; they take no lock themselves.
//  2. Public functions take mu_ (and say so: TESSERA_EXCLUDES where it matters).
//  3. Nothing slow under mu_: no disk, no encoding, no waiting. An operation under mu_ puts
//     the slow work in one Effects (effects.h), which apply() carries out after releasing it.
//  4. A job's image and checkpoint are written by one writer at a time (Snapshotter: the
//     first to ask becomes it, later asks are marked due), copying the film one band at a
//     time under mu_ and writing without it. SceneStore's, SceneUploads', JobStore's and
//     ImageSink's own locks are leaves: nothing is taken while one is held.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "core/util/mutex.h"
#include "server/archive.h"
#include "server/clock.h"
#include "server/counters.h"
#include "server/credentials.h"
#include "server/dispatcher.h"
#include "server/image_sink.h"
#include "server/image_stream.h"
#include "server/job_control.h"
#include "server/job_status.h"
#include "server/job_store.h"
#include "server/options.h"
#include "server/request_error.h"
#include "server/result_intake.h"
#include "server/scene_store.h"
#include "server/scene_uploads.h"
#include "server/worker_lifecycle.h"

namespace tessera {

class Coordinator {
 public:
  static constexpr uint32_t kMaxTasksPerRequest = Dispatcher::kMaxTasksPerRequest;
  static constexpr uint32_t kMaxLiveFrames = SequenceScheduler::kMaxLiveFrames;
  static constexpr size_t kFailuresToFail = JobLifecycle::kFailuresToFail;

  // Images go to `sink` (default: <data_dir>/jobs/<id>/), jobs to `store` (default: SQLite
  // in data_dir). Jobs an earlier run kept come back in their states, live ones from their
  // last checkpoint. Throws std::runtime_error when the data folder cannot be used.
  explicit Coordinator(CoordinatorOptions options, std::unique_ptr<Clock> clock = std::make_unique<SteadyClock>(),
                       std::unique_ptr<ImageSink> sink = nullptr, std::unique_ptr<JobStore> store = nullptr);
  ~Coordinator();

  // Client side. Throw RequestError.
  // `owner`: the submitting token's name; only it (or an admin) may cancel the job.
  std::string submit(const v1::SubmitJobRequest& request, const std::string& owner = "");
  // A scene in pieces (UploadScene; scene_uploads.h): `next` gives each message of the
  // stream, false at its end; written to disk as it comes. SubmitJobRequest.upload_id then
  // names it.
  v1::SceneUpload upload_scene(const std::function<bool(v1::SceneChunk*)>& next, const std::string& owner = "");
  // A job's status; an archived job's (archive.h) tile map is as a compacted job's.
  v1::JobStatus status(const std::string& id, bool with_tiles, TileRange range = {}, FrameRange frames = {}) const;
  // The jobs in memory (live ones, and those ended lately that are not archived yet), in
  // submission order.
  std::vector<v1::JobStatus> list() const;
  // A page of every job the database has, in submission order (ListJobsRequest: at most
  // kMaxPage jobs, page_size 0 included).
  v1::JobList list(uint32_t page_size, const std::string& page_token) const;
  // The `n` jobs submitted last and every live job before them, in submission order (the
  // status page), and how many jobs there are in each state (metrics).
  std::vector<v1::JobStatus> recent(size_t n) const;
  std::array<uint64_t, 5> job_counts() const;
  // `requester` may cancel (requeue, delete, re-prioritise) only its own jobs unless `any`
  // (an admin, or no access tokens).
  v1::JobStatus cancel(const std::string& id, const std::string& requester = "", bool any = true);
  // After submit (job_control.h): a job's priority; a FAILED or CANCELLED job (a sequence's
  // frames not DONE) taken up again from its checkpoints; a job and everything it left on
  // disk gone (a live one cancelled first), returning the bytes freed. Throw RequestError.
  v1::JobStatus set_priority(const std::string& id, int32_t priority, const std::string& requester = "",
                             bool any = true);
  v1::JobStatus requeue(const std::string& id, const std::string& requester = "", bool any = true);
  uint64_t remove(const std::string& id, const std::string& requester = "", bool any = true);
  // Retention (--keep-ended): up to `limit` jobs whose end was recorded over `keep_seconds`
  // ago, oldest first, for remove().
  std::vector<std::string> ended_before(double keep_seconds, size_t limit = 100) const {
    return store_->ended_before(keep_seconds, limit);
  }
  // The latest image in the formats asked for; an ended job's image holds its whole film.
  // A sequence's images are its frames': `frame` names one (it must for a sequence).
  v1::Image image(const std::string& id, bool exr = true, bool png = true, std::optional<int> frame = std::nullopt);
  // The same EXR in pieces of options().image_chunk_bytes through `write` (FetchImageChunks:
  // image_stream.h), resumable, with its checksum; stops when `write` returns false.
  void image_chunks(const v1::FetchImageRequest& request, const std::function<bool(const v1::ImageChunk&)>& write);

  // Worker side.
  // A worker's own credential (credentials.h) for `name`, from the enrolment token named
  // `enroller`. Throws RequestError.
  std::string enrol(const std::string& name, const std::string& enroller) {
    std::string credential = credentials_.enrol(name, enroller, options_.max_workers_per_token);
    uint64_t seq;
    {
      MutexLock lock(mu_);
      seq = ++events_sequenced_;
    }
    record({{0, 0, "worker.enrolled", "", name, enroller, ""}}, seq);
    return credential;
  }
  // Workers' credentials: the Authenticator looks them up here.
  CredentialBook& credentials() { return credentials_; }
  // `principal`: the worker's access token name, or with `enrolled` its own credential's
  // (quarantined ones never get this far: the Authenticator refuses them).
  v1::RegisterResponse register_worker(const v1::RegisterRequest& request, const std::string& principal = "",
                                       bool enrolled = false);
  // The gRPC layer's check before every worker request but Register and scene fetches:
  // throws RequestError unless `secret` is what worker `worker_id`'s registration was given.
  void check_worker(uint64_t worker_id, const std::string& secret) const;
  // Up to max_tasks tasks, stopping once they hold max_samples samples (0: no such limit);
  // always one if any is ready.
  v1::GetTaskResponse get_task(uint64_t worker_id, uint32_t max_tasks = 1, uint64_t max_samples = 0,
                               uint32_t max_passes = 1);
  // A kept scene's manifest; throws RequestError (kNotFound).
  v1::SceneManifest scene(const std::string& hash) const;
  // FetchSceneChunks: `write` gets the scene's manifest, then its pieces from the request's
  // (file, offset) on, read from disk one at a time; stops when `write` returns false.
  // Throws RequestError (kNotFound, kInvalidArgument).
  void scene_chunks(const v1::FetchSceneRequest& request,
                    const std::function<bool(const v1::SceneChunk&)>& write) const;
  // Renews the worker's leases; returns the tasks it must not go on with.
  // `round_trip`: the worker's measured round trip in seconds (0: not measured).
  std::vector<uint64_t> heartbeat(uint64_t worker_id, const std::vector<uint64_t>& task_ids, double round_trip = 0);
  bool heartbeat(uint64_t worker_id, uint64_t task_id) {
    return heartbeat(worker_id, std::vector<uint64_t>{task_id}).empty();
  }
  // A batch of results, each merged if it is wanted and well-formed: one ack each, in order.
  std::vector<v1::ResultAck> submit_results(const std::vector<const v1::TaskResult*>& results);
  v1::ResultAck submit_result(const v1::TaskResult& result) { return submit_results({&result})[0]; }
  // Gives a lease back. With an error, the worker could not render the task: once tasks
  // of a job failed on kFailuresToFail different workers, the job fails with the error.
  void release(uint64_t worker_id, uint64_t task_id, const std::string& error = "");
  // The worker stops: its leases go back to their jobs and it is forgotten.
  void unregister(uint64_t worker_id);

  // Waits up to `timeout` seconds for a change that may make work available (a job
  // submitted, a tile pass merged, a lease ended): lets GetTask long-poll.
  void wait_for_work(double timeout) const;
  // The reaper's tick (every 200 ms): expires overdue leases (get_task does too), ends
  // leases held past --max-task-seconds (failed tasks of their workers), forgets
  // silent workers, skips checks nobody can take, and makes the next frame of each
  // sequence ready to start. Returns how many leases expired.
  size_t expire_leases();
  // Blocks until a job's end is durable, its samples change from `last_samples`, or
  // `timeout` passes; returns its status without tiles. (Clients are told of an end only
  // once it is durable: Job::reported_state.)
  v1::JobStatus wait_for_change(const std::string& id, uint64_t last_samples, double timeout) const;
  // Blocks until the job's end is durable (true) or `timeout` passes (false).
  bool wait_for_end(const std::string& id, double timeout) const;

  // Saves every running job's film and plan now (a coordinator told to stop): a restart
  // then renders nothing again.
  void checkpoint_all();

  // What is left to render, for autoscalers (job_status.h).
  using Queue = QueueDepth;
  static constexpr double kAssumedThreadSpeed = QueueDepth::kAssumedThreadSpeed;
  Queue queue() const {
    MutexLock lock(mu_);
    return queue_depth(jobs_, leases_, workers_.thread_speed());
  }
  // Empty when the coordinator can serve (its job database answers and its data folder
  // takes writes); else what is wrong. For readiness probes.
  std::string unready_reason() const;

  // An operator drains a worker (no new tasks; what it holds it finishes) or resumes it.
  // Throws RequestError (kNotFound) for an unknown worker.
  void drain_worker(uint64_t worker_id, bool drain, const std::string& requester);
  double now() const { return clock_->now(); }  // the clock WorkerInfo's times are on
  std::vector<WorkerInfo> workers() const {
    MutexLock lock(mu_);
    return workers_.list(clock_->now());
  }
  double utilization() const {  // of every live worker's render threads, recently (0 when idle)
    MutexLock lock(mu_);
    return workers_.utilization(clock_->now());
  }
  // Events (events.h), as JobStore::events reads them.
  std::vector<Event> events(const std::string& job, uint64_t after, size_t limit, bool newest) const;
  CoordinatorCounters counters() const {
    MutexLock lock(mu_);
    return counters_;
  }
  double uptime() const { return clock_->now() - started_; }
  const CoordinatorOptions& options() const { return options_; }

 private:
  struct Reserved;
  // Carries out what operations under the lock left to do (rule 3). mu_ not held.
  void apply(Effects fx) TESSERA_EXCLUDES(mu_);
  // An operation's events get their place in the order operations held the lock (mu_ held),
  // so that record() keeps them in that order whichever thread gets there first.
  void sequence(Effects& fx) TESSERA_REQUIRES(mu_) {
    if (!fx.events.empty()) fx.events_seq = ++events_sequenced_;
  }
  // Stamps the events with the wall clock, logs them (one structured line each) and keeps
  // them in the database, in their sequence's order (a later one waits for an earlier one).
  void record(std::vector<Event> events, uint64_t seq) TESSERA_EXCLUDES(mu_);
  uint64_t events_sequenced_ TESSERA_GUARDED_BY(mu_) = 0;
  std::mutex events_mu_;  // a leaf: the events waiting for an earlier operation's, and the log's order
  std::map<uint64_t, std::vector<Event>> events_waiting_;  // by sequence (events_mu_)
  uint64_t events_recorded_ = 0;                           // the last sequence recorded (events_mu_)
  // Runs op(effects) under mu_, then apply()s the effects; returns what op returns.
  template <typename Op>
  auto locked(Op&& op) TESSERA_EXCLUDES(mu_) {
    Effects fx;
    if constexpr (std::is_void_v<std::invoke_result_t<Op&, Effects&>>) {
      {
        MutexLock lock(mu_);
        op(fx);
        sequence(fx);
      }
      apply(std::move(fx));
    } else {
      auto result = [&] {
        MutexLock lock(mu_);
        auto r = op(fx);
        sequence(fx);
        return r;
      }();
      apply(std::move(fx));
      return result;
    }
  }
  // Runs slow() without the lock; if it throws, undo(effects) runs under the lock, and the
  // exception goes on to the caller.
  template <typename Slow, typename Undo>
  auto undo_on_throw(Slow&& slow, Undo&& undo) TESSERA_EXCLUDES(mu_) {
    try {
      return slow();
    } catch (...) {
      locked(undo);
      throw;
    }
  }
  // Writes the job's due image and checkpoint, band by band, as its one writer (the caller
  // became it: Snapshotter::request), until nothing more is due.
  void write(const std::shared_ptr<Job>& job) TESSERA_EXCLUDES(mu_);
  // How long an image fetch or a stopping coordinator waits for another thread's writer.
  static constexpr double kImageWaitSeconds = 120;
  // Waits (mu_ held) until `done()` or `timeout` seconds pass; returns done().
  template <typename Done>
  bool await(Done&& done, double timeout = kImageWaitSeconds) const TESSERA_REQUIRES(mu_) {
    const auto deadline = deadline_in(timeout);
    while (!done() && changed_.wait_until(mu_, deadline)) {
    }
    return done();
  }
  void record_sequence_end(const std::string& id) TESSERA_EXCLUDES(mu_);
  // An ended job leaves memory (archive.h): its row first, then the table.
  void archive(const Archival& a) TESSERA_EXCLUDES(mu_);
  // Runs op() (on the job database, without mu_) and returns what it does; a failure other
  // than a RequestError becomes one (kResourceExhausted) saying why after `context`, the
  // data folder shown as <data>.
  template <typename Op>
  auto with_store(Op&& op, const std::string& context = "") const TESSERA_EXCLUDES(mu_) {
    try {
      return op();
    } catch (const RequestError&) {
      throw;
    } catch (const std::exception& e) {
      throw RequestError(RequestError::Code::kResourceExhausted, context + without_dir(e.what(), options_.data_dir));
    }
  }
  // The status of each row's job, from memory or its row (a row of neither is left out).
  std::vector<v1::JobStatus> statuses(const std::vector<StoredJob>& rows) const TESSERA_EXCLUDES(mu_);
  // An archived job's status from its row; nothing if none. Throws RequestError.
  std::optional<v1::JobStatus> archived(const std::string& id) const TESSERA_EXCLUDES(mu_);
  // The row of the archived job `id` a request would `verb`, nothing if it is not archived
  // (archived_for_change). Throws RequestError.
  std::optional<StoredJob> archived_change(const std::string& id, const std::string& requester, bool any,
                                           const char* verb) const TESSERA_EXCLUDES(mu_);
  // An archived job is being deleted or brought back (JobControl::begin_archived); false if
  // it is in memory again. Throws RequestError (busy).
  bool begin_archived(const std::string& id) TESSERA_EXCLUDES(mu_);
  // Runs in_memory() under mu_ if the job `id` is in memory, else archived() without it (an
  // optional of the same); a job a requeue brought back meanwhile is looked for again.
  // Throws RequestError (kNotFound) if neither has it.
  template <typename InMemory, typename Archived>
  auto find(const std::string& id, InMemory&& in_memory, Archived&& archived) const TESSERA_EXCLUDES(mu_) {
    for (int tries = 0; tries < 2; ++tries) {
      {
        MutexLock lock(mu_);
        if (jobs_.knows(id)) return in_memory();
      }
      if (auto got = archived()) return std::move(*got);
    }
    throw RequestError(RequestError::Code::kNotFound, "no job '" + id + "'");
  }
  void refused() TESSERA_EXCLUDES(mu_);  // a submit refused: counted
  // The job's (or frame's) image as a client is to get it: written first (or waited for)
  // when the one on disk is not current; returns whose image it is (a frame's own id).
  // Throws RequestError when it cannot be.
  std::string current_image(const std::string& id, std::optional<int> frame, ImageStreamHeader* header)
      TESSERA_EXCLUDES(mu_);
  v1::ResultAck check_result(const v1::TaskResult& result, const Lease& lease) TESSERA_EXCLUDES(mu_);

  const CoordinatorOptions options_;
  const std::unique_ptr<Clock> clock_;
  const std::unique_ptr<ImageSink> sink_;
  const std::unique_ptr<JobStore> store_;
  CredentialBook credentials_;                // its own lock, a leaf
  std::atomic<double> credentials_swept_{0};  // the reaper's last sweep of them
  SceneStore scenes_;
  SceneUploads uploads_;  // used without mu_, as scenes_ is
  double started_ = 0;
  const SnapshotWriter writer_;  // used without mu_
  const Referee referee_;        // likewise
  const Snapshotter snapshotter_;

  // Held across an archive's store write and the job's removal from memory, and across
  // job_counts()'s two reads (the store's archived jobs, then memory's), so that a job
  // being archived is counted once, not in both. Taken before mu_, never after.
  mutable std::mutex archive_counts_mu_;
  mutable Mutex mu_;
  mutable CondVar changed_;
  // The farm's state.
  JobTable jobs_ TESSERA_GUARDED_BY(mu_);
  LeaseTable leases_ TESSERA_GUARDED_BY(mu_);
  WorkerRegistry workers_ TESSERA_GUARDED_BY(mu_);
  CheckBook checks_ TESSERA_GUARDED_BY(mu_);
  CoordinatorCounters counters_ TESSERA_GUARDED_BY(mu_);
  // The units acting on it.
  Leasing leasing_ TESSERA_GUARDED_BY(mu_);
  JobLifecycle lifecycle_ TESSERA_GUARDED_BY(mu_);
  SequenceScheduler sequences_ TESSERA_GUARDED_BY(mu_);
  Verifier verifier_ TESSERA_GUARDED_BY(mu_);
  Dispatcher dispatcher_ TESSERA_GUARDED_BY(mu_);
  ResultIntake intake_ TESSERA_GUARDED_BY(mu_);
  WorkerLifecycle worker_lifecycle_ TESSERA_GUARDED_BY(mu_);
  JobControl control_ TESSERA_GUARDED_BY(mu_);
  Archive archive_ TESSERA_GUARDED_BY(mu_);
};

}  // namespace tessera
