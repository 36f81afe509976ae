// The coordinator, free of gRPC and HTTP so tests drive it directly. It wires together:
//   SceneStore      scenes by content hash, checked at submit    (scene_store.h)
//   Job + FramePlan each job's schedule, film and progress       (job.h, core/render/frame_plan.h)
//   LeaseTable      which worker renders which task, until when  (lease_table.h)
//   WorkerRegistry  who is there, and how fast                   (worker_registry.h)
//   ImageSink       where progressive images go                  (image_sink.h)
//   JobStore        what survives a crash: jobs in SQLite, film checkpoints (job_store.h)
// A task is one tile of one job for one pass, leased to one worker. The frame plan makes
// the merged image bit-identical to `tessera render`; the coordinator adds leases, job
// priorities, images and durability. One mutex guards everything but scene checks, image
// and checkpoint writes, and the job database.
#pragma once

#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "server/clock.h"
#include "server/image_sink.h"
#include "server/job.h"
#include "server/job_store.h"
#include "server/lease_table.h"
#include "server/scene_store.h"
#include "server/worker_registry.h"

namespace tessera {

struct CoordinatorOptions {
  std::string data_dir = "tessera-data";
  double lease_seconds = 10;
  double heartbeat_seconds = 2;
  double image_interval_seconds = 5;  // progressive images at most this often
  // A live job's film and plan are saved at least this often while it merges results: a
  // coordinator killed and restarted renders again at most the results of this long.
  double checkpoint_seconds = 5;
  // A worker not heard from for this long is forgotten (it registers again if it returns).
  double worker_timeout_seconds = 60;
  // Registered workers at most: a Register loop cannot grow the coordinator without bound.
  size_t max_workers = 10000;
  // Live (queued or running) jobs one client (token name) may have at once.
  size_t max_jobs_per_client = 100;
  // Pixels of all live frames together: each costs two 40-byte films in memory (the plan's
  // and the snapshot's), so the default, 2^27, is about 10 GB at most.
  int64_t max_live_pixels = int64_t(1) << 27;
  // Scene bytes and samples still to render of one client's live jobs together.
  uint64_t max_scene_bytes_per_client = uint64_t(4) << 30;
  uint64_t max_queued_samples_per_client = uint64_t(1) << 40;  // ~12 core-days at 1M samples/s
  // Verify by replay: this fraction of tasks, picked at random, is rendered again by a
  // second worker and the sums compared bit for bit. When they differ, the coordinator
  // renders the task itself, and a worker whose sums differ from its render is
  // quarantined: its leases end, the tiles it merged into live jobs are rendered again,
  // and, with access tokens, its token may not register again.
  double verify_fraction = 0.01;  // costs this fraction of the farm's render time
  // Test seams: between an image snapshot leaving the lock and its write; between a
  // checkpoint's temporary file being written and its rename.
  std::function<void()> before_image_write;
  std::function<void()> before_checkpoint_rename;
};

// A request the coordinator refuses, with a message for the client.
class RequestError : public std::runtime_error {
 public:
  enum class Code { kInvalidArgument, kNotFound, kFailedPrecondition, kResourceExhausted, kPermissionDenied };
  RequestError(Code code, const std::string& what) : std::runtime_error(what), code_(code) {}
  Code code() const { return code_; }

 private:
  Code code_;
};

struct CoordinatorCounters {
  uint64_t tasks_dispatched = 0, results_merged = 0, results_duplicate = 0, results_rejected = 0;
  uint64_t leases_expired = 0, leases_released = 0, tasks_failed = 0, samples_merged = 0, jobs_submitted = 0,
           jobs_refused = 0;
  uint64_t images_written = 0, image_errors = 0, checkpoints_written = 0, checkpoint_errors = 0;
  uint64_t jobs_restored = 0;
  uint64_t checks_issued = 0, checks_passed = 0, check_mismatches = 0, checks_skipped = 0, workers_quarantined = 0,
           tiles_rendered_again = 0;
  double merge_seconds = 0;
};

class Coordinator {
 public:
  static constexpr uint32_t kMaxTasksPerRequest = 256;
  // Images go to `sink`, or to <data_dir>/jobs/<id>/ when it is null. Jobs kept in
  // data_dir by an earlier run come back in their states, live ones from their last
  // checkpoint. Throws std::runtime_error when the data folder cannot be used.
  explicit Coordinator(CoordinatorOptions options, std::unique_ptr<Clock> clock = std::make_unique<SteadyClock>(),
                       std::unique_ptr<ImageSink> sink = nullptr);
  ~Coordinator();

  // Client side. Throw RequestError.
  // `owner`: the submitting token's name; only it (or an admin) may cancel the job.
  std::string submit(const v1::SubmitJobRequest& request, const std::string& owner = "");
  v1::JobStatus status(const std::string& id, bool with_tiles) const;
  std::vector<v1::JobStatus> list() const;  // in submission order
  // `requester` may cancel only its own jobs unless `any` (an admin, or no access tokens).
  v1::JobStatus cancel(const std::string& id, const std::string& requester = "", bool any = true);
  // The latest image in the formats asked for; an ended job's image holds its whole film.
  // A sequence's images are its frames': `frame` names one (it must for a sequence).
  v1::Image image(const std::string& id, bool exr = true, bool png = true, std::optional<int> frame = std::nullopt);
  // Frames of one sequence with films at once, at most: each holds two films in memory.
  static constexpr uint32_t kMaxLiveFrames = 64;

  // Worker side.
  // `principal`: the worker's access token name (a quarantined one may not register).
  v1::RegisterResponse register_worker(const v1::RegisterRequest& request, const std::string& principal = "");
  // Up to max_tasks tasks, stopping once they hold max_samples samples (0: no such limit);
  // always one if any is ready.
  v1::GetTaskResponse get_task(uint64_t worker_id, uint32_t max_tasks = 1, uint64_t max_samples = 0);
  v1::SceneBundle scene(const std::string& hash) const;
  // Renews the worker's leases; returns the tasks it must not go on with.
  std::vector<uint64_t> heartbeat(uint64_t worker_id, const std::vector<uint64_t>& task_ids);
  bool heartbeat(uint64_t worker_id, uint64_t task_id) {
    return heartbeat(worker_id, std::vector<uint64_t>{task_id}).empty();
  }
  // A batch of results, each merged if it is wanted and well-formed: one ack each, in order.
  std::vector<v1::ResultAck> submit_results(const std::vector<const v1::TaskResult*>& results);
  v1::ResultAck submit_result(const v1::TaskResult& result);
  // Gives a lease back. With an error, the worker could not render the task: once tasks
  // of a job failed on kFailuresToFail different workers, the job fails with the error.
  void release(uint64_t worker_id, uint64_t task_id, const std::string& error = "");
  static constexpr size_t kFailuresToFail = 2;
  // The worker stops: its leases go back to their jobs and it is forgotten.
  void unregister(uint64_t worker_id);

  // Waits up to `timeout` seconds for a change that may make work available (a job
  // submitted, a tile pass merged, a lease ended): lets GetTask long-poll.
  void wait_for_work(double timeout) const;
  // Expires overdue leases (get_task does too), forgets silent workers and makes the next
  // frame of each sequence ready to start (only here: the reaper calls it every 200 ms).
  // Returns how many leases expired.
  size_t expire_leases();
  // Blocks until a job ends, its samples change from `last_samples`, or `timeout` passes;
  // returns its status without tiles.
  v1::JobStatus wait_for_change(const std::string& id, uint64_t last_samples, double timeout) const;
  // Blocks until the job has ended (true) or `timeout` passes (false).
  bool wait_for_end(const std::string& id, double timeout) const;

  // Saves every running job's film and plan now (a coordinator told to stop): a restart
  // then renders nothing again.
  void checkpoint_all();

  // What is left to render, for autoscalers (Kubernetes HPA, Slurm scripts): tasks ready
  // and leased, samples not yet merged (an upper bound with adaptive sampling), and those
  // samples in core-seconds at the render speed per thread measured lately.
  struct Queue {
    uint64_t tasks_ready = 0, tasks_leased = 0, samples_remaining = 0;
    double samples_per_thread_second = 0;  // measured; kAssumedThreadSpeed before any result
    double core_seconds_remaining = 0;
  };
  static constexpr double kAssumedThreadSpeed = 1e6;  // samples/s a thread, about ours on CS184 scenes
  Queue queue() const;
  // Empty when the coordinator can serve (its job database answers and its data folder
  // takes writes); else what is wrong. For readiness probes.
  std::string unready_reason() const;

  std::vector<WorkerInfo> workers() const;
  double utilization() const;  // of every live worker's render threads, recently
  CoordinatorCounters counters() const;
  double uptime() const;
  const CoordinatorOptions& options() const { return options_; }

 private:
  // A film to write outside the lock, newest-wins by sequence number.
  // A snapshot writes the image, the checkpoint, or both; one taken after the job ended
  // also records the end in the job database, once its checkpoint is on disk.
  struct ImageSnapshot {
    Job* job = nullptr;
    std::unique_ptr<Film> film;  // null: nothing to write (an ended job's film was released)
    ImageMetadata meta;
    uint64_t seq = 0;
    uint64_t merges = 0;  // the film version copied
    bool image = true, checkpoint = true;
    PlanState plan;
    double elapsed = 0;
    bool ended = false;
    v1::JobStatus::State state = v1::JobStatus::QUEUED;
    std::string error;
  };

  Job* find(const std::string& id) const;  // mu_ held; throws kNotFound
  std::string submit_sequence(const v1::SubmitJobRequest& req, const RenderSettings& settings,
                              const std::vector<int>& frames, const std::string& hash, const std::string& owner,
                              uint64_t scene_bytes);
  std::map<std::string, uint32_t> workers_on_frames_locked(const Sequence& s) const;
  // Records a submitted job (or sequence, with its frames) durably before the client hears
  // of it (mu_ not held: it waits for the disk); if it cannot, releases the scene's use and
  // refuses the submit.
  void record_submit(const v1::SubmitJobRequest& req, const std::string& id, const std::string& name,
                     const std::string& owner, const std::string& hash, uint64_t seq,
                     const v1::RenderSettings& settings, const std::vector<int>& frames);
  Sequence* find_sequence(const std::string& id) const;  // mu_ held; null if not one

  // Sequences. A frame's job, made from the sequence's constant fields (so without mu_).
  std::unique_ptr<Job> make_frame_job(const Sequence& s, size_t index) const;
  // Starts the sequence's next frame (its prepared job if there is one); null when every
  // frame has started.
  Job* start_frame_locked(Sequence& s, double now);
  // Makes the next frame's job of these sequences outside the lock (mu_ not held): the
  // reaper's tick (expire_leases) does, so a worker's GetTask never waits for films to be
  // allocated; a frame started before its job was prepared is made under the lock.
  void prepare_frames(const std::vector<Sequence*>& sequences);
  void frame_ended_locked(Job& job, double now);
  // Ends the sequence; its live frames end as CANCELLED (queued in unwritten_).
  void end_sequence_locked(Sequence& s, v1::JobStatus::State state, double now);
  // Records a sequence's end in the job database once it can (mu_ not held): at once for a
  // cancelled or failed one, after every frame's final checkpoint for a DONE one.
  void record_sequence_end(const std::string& id);
  // The job of `id`, or of its frame `frame` when `id` is a sequence; throws RequestError.
  Job* frame_job_locked(const std::string& id, std::optional<int> frame) const;
  void write_unwritten();  // final images of frames ended by their sequence (mu_ not held)
  void restore_sequence(StoredJob& row, double now, std::vector<Job*>& ended_on_restore);
  uint32_t workers_on(const Job& job) const { return leases_.workers_on(job.id); }
  ImageSnapshot snapshot_locked(Job& job, bool image = true, bool checkpoint = true);
  void restore_jobs();                                      // from store_, at construction
  std::string without_data_dir(std::string message) const;  // for clients' eyes
  void write_snapshot(ImageSnapshot& snap);                 // mu_ not held; gives the film back to the job
  void write_image(Job& job);                               // mu_ not held: snapshot, then write
  // Ends a live lease: the tile loses it (and, with `requeue`, is ready again), the worker
  // holds one lease fewer; the lease stays known so a late result is recognised.
  void end_lease_locked(uint64_t id, bool requeue);
  // The job is DONE, CANCELLED or FAILED: its leases end, and its scene goes if unused.
  void end_job_locked(Job& job, v1::JobStatus::State state, double now);
  void lease_ended_locked(uint64_t id, const Lease& lease, bool requeue);
  size_t expire_locked(double now);
  // After a merge: the job's end, the worker's speed, and maybe a progressive image.
  std::optional<ImageSnapshot> after_merge_locked(Job& job, const v1::TaskResult& result, double now);
  std::string new_job_id_locked();

  // Verify by replay (see CoordinatorOptions::verify_fraction).
  struct Check {
    std::string job;
    uint32_t tile = 0, pass = 0;
    std::shared_ptr<const v1::Task> task;  // as the first worker got it
    uint64_t first_worker = 0;
    uint64_t digest = 0;  // of the merged sums
    uint64_t lease = 0;   // the check's live lease (0: waiting for a worker)
    double since = 0;     // waiting since
  };
  v1::ResultAck check_result(const v1::TaskResult& result, const Lease& lease);
  // The sums of a task as this process renders them: the referee when two workers differ.
  std::vector<PixelSums> render_here(const v1::Task& task);
  void quarantine_locked(uint64_t worker, const std::string& why);
  void drop_check_locked(std::map<uint64_t, Check>::iterator it, bool skipped);
  // The plan is done and no check is pending: the job is DONE; returns its final snapshot.
  std::optional<ImageSnapshot> finish_if_done_locked(Job& job, double now);

  CoordinatorOptions options_;
  std::unique_ptr<Clock> clock_;
  std::unique_ptr<ImageSink> sink_;
  SceneStore scenes_;
  std::unique_ptr<JobStore> store_;
  double started_ = 0;
  mutable std::mutex mu_;
  mutable std::condition_variable changed_;
  std::map<std::string, std::unique_ptr<Job>> jobs_;  // jobs are never removed; frames too
  std::map<std::string, std::unique_ptr<Sequence>> sequences_;
  std::vector<Job*> unwritten_;  // ended frames whose final image is still to be written
  LeaseTable leases_;
  WorkerRegistry workers_;
  uint64_t next_job_ = 1;
  std::mt19937_64 ids_{std::random_device{}()};
  CoordinatorCounters counters_;
  mutable double thread_speed_ = 0;  // the last measured samples/s per render thread (0: none yet)
  std::map<uint64_t, Check> checks_;
  uint64_t next_check_ = 1;
  std::set<uint64_t> quarantined_;                // worker ids
  std::set<std::string> quarantined_principals_;  // their token names, refused at Register
};

}  // namespace tessera
