// The coordinator's settings (tessera-coordinator's flags set them; tests set them directly).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

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
  // Registered workers of one access token at most: a flood under one credential cannot
  // lock the others out (each worker's own credential makes this 1 per worker).
  size_t max_workers_per_token = 1000;
  // A task's time from its lease to its result, at most: past it the lease ends as a task
  // that failed on its worker (the job fails once that happens on two workers, as for any
  // failure), and the worker, told at its next heartbeat, stops rendering it. Scenes within
  // every load bound can still cost hours a sample (20 M coincident triangles); this keeps
  // one from holding the farm's workers for good. 0: no bound.
  double max_task_seconds = 3600;
  // Scene loads (a submit's check, a requeue's, a restore, the referee's render) at once, at
  // most: the rest wait their turn (server/scene_loads.h), for as long as a turn holds its
  // scene (the referee's render of a disputed task too). tessera-coordinator sets one per
  // 16 GiB of the memory it may use (usable_memory_bytes: a cgroup's limit where lower), 1
  // to 4 (scene_load_default), unless given.
  size_t max_scene_loads = 2;
  // Leases one worker may hold at once. A worker keeps as much work leased as its speed
  // times its round trip asks for (a far worker needs more in flight), up to this; the
  // dispatcher's share by threads still keeps one worker from taking all of a small job.
  uint32_t max_leases_per_worker = 4096;
  // Streams (WatchJob, FetchImageChunks) one caller may hold open at once: each holds a
  // server thread while it lasts.
  size_t max_streams_per_peer = 64;
  // Live (queued or running) jobs one client (token name) may have at once.
  size_t max_jobs_per_client = 100;
  // Pixels of all live frames together: each costs its film's sums, 40 bytes (a snapshot
  // copies one band at a time), so 2^27 is 5.4 GB. tessera-coordinator lowers it to half
  // the memory it may use when that is less (live_pixel_default of usable_memory_bytes: the
  // machine's, or a cgroup's limit where lower).
  int64_t max_live_pixels = int64_t(1) << 27;
  // Scene bytes (of live jobs and of scene uploads) and samples still to render of one
  // client's live jobs together.
  uint64_t max_scene_bytes_per_client = uint64_t(4) << 30;
  uint64_t max_queued_samples_per_client = uint64_t(1) << 40;  // ~12 core-days at 1M samples/s
  // A finished scene upload waits this long for the submit that names it (scene_uploads.h).
  double upload_kept_seconds = 600;
  // Workers get scenes in pieces of at most this many bytes (proto/scene_chunks.h).
  size_t scene_chunk_bytes = size_t(1) << 20;
  // Verify by replay: this fraction of tasks, picked at random, is rendered again by a
  // second worker and the sums compared bit for bit. When they differ, the coordinator
  // renders the task itself, and a worker whose sums differ from its render is
  // quarantined: its leases end, the tiles it merged into live jobs are rendered again,
  // and an enrolled worker's credential (credentials.h) is refused from then on.
  double verify_fraction = 0.01;  // costs this fraction of the farm's render time
  // Probation: every registration's first tasks are all checked (when verify_fraction > 0
  // and another worker can check them), so a worker that lies from the start is caught
  // before its lies can end up in an image, whatever the fraction.
  uint32_t verify_first = 4;
  // Pieces of an image sent by FetchImageChunks (a setting so tests can make them small).
  size_t image_chunk_bytes = size_t(1) << 20;
  // Test seams: between an image snapshot leaving the lock and its write; between a
  // checkpoint's temporary file being written and its rename; ...
  std::function<void()> before_image_write;
  std::function<void()> before_checkpoint_rename;
  // ... after a delete's or requeue's database change, before the rest (files, memory).
  std::function<void()> after_row_commit;
};

}  // namespace tessera
