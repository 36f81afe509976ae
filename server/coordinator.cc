#include "server/coordinator.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "core/io/files.h"
#include "core/render/frames.h"
#include "core/render/tile_renderer.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#define XXH_INLINE_ALL  // header only: nothing to link
#include <xxhash.h>

namespace tessera {

namespace fs = std::filesystem;

namespace {

// Of the sums' values (not their padding or wire encoding, which may differ between two
// honest workers): equal digests, equal bits.
uint64_t sums_digest(const std::vector<PixelSums>& sums) {
  XXH3_state_t st;
  XXH3_64bits_reset(&st);
  for (const PixelSums& p : sums) {
    const double v[4] = {p.r, p.g, p.b, p.lum2};
    XXH3_64bits_update(&st, v, sizeof v);
    XXH3_64bits_update(&st, &p.n, sizeof p.n);
  }
  return XXH3_64bits_digest(&st);
}

// A result's tile sums, for a tile of `pixels` pixels; throws WireError for any mismatch.
std::vector<PixelSums> result_sums(const v1::TaskResult& result, size_t pixels) {
  if (result.raw_size() != pixels * kBytesPerPixel) throw WireError("raw size does not match the tile");
  return decode_sums(result.sums_zstd(), pixels);
}

}  // namespace

Coordinator::Coordinator(CoordinatorOptions options, std::unique_ptr<Clock> clock, std::unique_ptr<ImageSink> sink)
    : options_(std::move(options)),
      clock_(std::move(clock)),
      sink_(sink ? std::move(sink) : std::make_unique<DiskImageSink>((fs::path(options_.data_dir) / "jobs").string())),
      scenes_((fs::path(options_.data_dir) / "scenes").string()),
      store_(std::make_unique<JobStore>(options_.data_dir)) {
  started_ = clock_->now();
  store_->before_checkpoint_rename = options_.before_checkpoint_rename;
  // 2^40 tasks a run: ids of different runs never meet.
  leases_ = LeaseTable(store_->next_generation() << 40);
  restore_jobs();
}

void Coordinator::restore_jobs() {
  const double now = clock_->now();
  std::vector<Job*> ended_on_restore;  // live in the database, but done or lost
  for (StoredJob& sj : store_->jobs()) {
    if (!sj.frames.empty()) {
      restore_sequence(sj, now, ended_on_restore);
      continue;
    }
    RenderSettings settings;
    try {
      settings = from_proto(sj.settings);
    } catch (const WireError& e) {  // checked at submit: only a damaged database gets here
      std::fprintf(stderr, "tessera-coordinator: job %s: stored settings: %s; skipped\n", sj.id.c_str(), e.what());
      continue;
    }
    auto job = std::make_unique<Job>(sj.id, settings);
    job->settings_proto = sj.settings;
    job->name = sj.name;
    job->owner = sj.owner;
    job->priority = sj.priority;
    job->seq = sj.seq;
    job->scene_hash = sj.scene_hash;
    job->state = sj.state;
    job->error = sj.error;
    job->submitted = now;
    next_job_ = std::max(next_job_, sj.seq + 1);
    double elapsed = sj.elapsed;
    std::string lost;  // why a live job cannot go on
    try {
      // An ended job's film stays on disk: start-up decodes only what live jobs go on with.
      if (std::optional<Checkpoint> cp = store_->read_checkpoint(sj.id, job->live())) {
        job->plan.restore(cp->state, std::move(cp->film));
        if (job->live()) elapsed = cp->elapsed;
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera-coordinator: job %s: %s; its samples are rendered again\n", sj.id.c_str(),
                   e.what());
    }
    for (const char* tmp : {"checkpoint.tmp", "image.exr.tmp"}) {  // a write the crash cut short
      std::error_code ec;
      fs::remove(fs::path(options_.data_dir) / "jobs" / sj.id / tmp, ec);
    }
    Job& j = *job;
    jobs_[sj.id] = std::move(job);
    ++counters_.jobs_restored;
    if (j.live()) {
      try {
        scenes_.restore(j.scene_hash);
        const v1::SceneBundle bundle = scenes_.get(j.scene_hash);
        for (const v1::SceneFile& f : bundle.files()) j.scene_bytes += f.path().size() + f.content().size();
      } catch (const std::exception& e) {
        lost = e.what();
      }
      j.tile_lease.assign(j.plan.tiles().size(), 0);
      if (j.plan.merges() > 0 || elapsed > 0) {
        j.state = v1::JobStatus::RUNNING;
        j.started = now - elapsed;
      } else {
        j.state = v1::JobStatus::QUEUED;
      }
      j.last_checkpoint = now;
      j.checkpoint_merges = j.plan.merges();
      if (!lost.empty()) {
        j.error = "cannot go on after the coordinator restarted: " + lost;
        end_job_locked(j, v1::JobStatus::FAILED, now);
        ended_on_restore.push_back(&j);
      } else if (j.plan.done()) {  // the crash came between its last checkpoint and recording its end
        end_job_locked(j, v1::JobStatus::DONE, now);
        ended_on_restore.push_back(&j);
      } else {
        j.spare_film = std::make_unique<Film>(j.plan.film());
      }
    } else {
      // Ended: its image is on disk and its film is not needed; status comes from the plan.
      j.started = now - elapsed;
      j.finished_at = now;
      j.image_frame_passes = j.plan.frame_passes_done();
      j.plan.release_film();  // (restored without one; a plan without a checkpoint has its own)
      j.written_seq = j.checkpoint_seq = j.image_seq = 1;
      j.written_merges = j.checkpoint_written_merges = j.plan.merges();
      j.end_recorded = true;
    }
  }
  scenes_.remove_unused();                          // scenes of jobs that ended, or whose submit the crash cut short
  for (Job* j : ended_on_restore) write_image(*j);  // writes the image and records the end
  write_unwritten();
  std::vector<std::string> ids;
  for (auto& [id, seq] : sequences_) ids.push_back(id);
  for (const std::string& id : ids) record_sequence_end(id);
}

void Coordinator::restore_sequence(StoredJob& sj, double now, std::vector<Job*>& ended_on_restore) {
  auto owned = std::make_unique<Sequence>();
  Sequence& s = *owned;
  try {
    s.settings = from_proto(sj.settings);
  } catch (const WireError& e) {  // checked at submit: only a damaged database gets here
    std::fprintf(stderr, "tessera-coordinator: job %s: stored settings: %s; skipped\n", sj.id.c_str(), e.what());
    return;
  }
  s.id = sj.id;
  s.settings_proto = sj.settings;
  s.frames = sj.frames;
  s.jobs.assign(s.frames.size(), nullptr);
  s.name = sj.name;
  s.owner = sj.owner;
  s.priority = sj.priority;
  s.seq = sj.seq;
  s.scene_hash = sj.scene_hash;
  s.state = sj.state;
  s.error = sj.error;
  s.submitted = now;
  next_job_ = std::max(next_job_, sj.seq + 1);
  sequences_[sj.id] = std::move(owned);
  ++counters_.jobs_restored;
  std::string lost;
  if (s.live()) try {
      scenes_.restore(s.scene_hash);
      const v1::SceneBundle bundle = scenes_.get(s.scene_hash);
      for (const v1::SceneFile& f : bundle.files()) s.scene_bytes += f.path().size() + f.content().size();
    } catch (const std::exception& e) {
      lost = e.what();
    }
  double elapsed = 0;
  bool all_done = true;
  for (size_t i = 0; i < s.frames.size(); ++i) {
    const std::string id = s.frame_job_id(i);
    std::optional<Checkpoint> cp;
    std::unique_ptr<Job> job;
    try {
      // A frame that started has a checkpoint (or is rendered again from the start).
      if (!(cp = store_->read_checkpoint(id, s.live()))) {
        all_done = false;
        continue;
      }
      job = make_frame_job(s, i);
      job->plan.restore(cp->state, std::move(cp->film));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera-coordinator: job %s: %s; its samples are rendered again\n", id.c_str(), e.what());
      all_done = false;
      continue;
    }
    for (const char* tmp : {"checkpoint.tmp", "image.exr.tmp"}) {
      std::error_code ec;
      fs::remove(fs::path(options_.data_dir) / "jobs" / id / tmp, ec);
    }
    Job& j = *job;
    jobs_[id] = std::move(job);
    s.jobs[i] = &j;
    j.submitted = now;
    elapsed = std::max(elapsed, cp->elapsed);
    all_done &= j.plan.done();
    s.frames_done += j.plan.done();
    if (s.live() && !j.plan.done()) {
      j.state = j.plan.merges() > 0 ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED;
      j.started = now - cp->elapsed;
      j.last_checkpoint = now;
      j.checkpoint_merges = j.plan.merges();
      j.spare_film = std::make_unique<Film>(j.plan.film());
      ++s.live_frames;
    } else if (s.live() && j.plan.has_film()) {  // done: its image is rewritten in case it was not
      j.state = v1::JobStatus::DONE;
      j.started = now - cp->elapsed;
      j.finished_at = now;
      ended_on_restore.push_back(&j);
    } else {
      j.state = j.plan.done() ? v1::JobStatus::DONE : v1::JobStatus::CANCELLED;
      j.started = now - cp->elapsed;
      j.finished_at = now;
      j.image_frame_passes = j.plan.frame_passes_done();
      j.plan.release_film();
      j.written_seq = j.checkpoint_seq = j.image_seq = 1;
      j.written_merges = j.checkpoint_written_merges = j.plan.merges();
      j.end_recorded = true;
    }
  }
  if (!s.live()) {
    s.end_recorded = true;
    s.prepared.reset();
    s.started = now - elapsed;
    s.finished_at = now;
  } else if (!lost.empty()) {
    s.error = "cannot go on after the coordinator restarted: " + lost;
    end_sequence_locked(s, v1::JobStatus::FAILED, now);
  } else if (all_done) {
    end_sequence_locked(s, v1::JobStatus::DONE, now);
  } else {
    s.started = now - elapsed;
    s.state = elapsed > 0 ? v1::JobStatus::RUNNING : v1::JobStatus::QUEUED;
    while (s.next < s.jobs.size() && s.jobs[s.next]) ++s.next;
  }
}

std::string Coordinator::without_data_dir(std::string why) const {
  // Clients see this: the data folder is named, not its path on this machine.
  for (size_t at; !options_.data_dir.empty() && (at = why.find(options_.data_dir)) != std::string::npos;)
    why.replace(at, options_.data_dir.size(), "<data>");
  return why;
}

Coordinator::~Coordinator() = default;

double Coordinator::uptime() const { return clock_->now() - started_; }

Sequence* Coordinator::find_sequence(const std::string& id) const {
  auto it = sequences_.find(id);
  return it == sequences_.end() ? nullptr : it->second.get();
}

std::unique_ptr<Job> Coordinator::make_frame_job(const Sequence& s, size_t index) const {
  RenderSettings settings = s.settings;
  settings.frame = s.frames[index];
  auto job = std::make_unique<Job>(s.frame_job_id(index), settings);
  job->settings_proto = to_proto(settings);
  job->sequence = s.id;
  job->frame_index = uint32_t(index);
  job->name = s.name + " frame " + std::to_string(s.frames[index]);
  job->owner = s.owner;
  job->priority = s.priority;
  job->seq = s.seq;
  job->scene_hash = s.scene_hash;
  job->tile_lease.assign(job->plan.tiles().size(), 0);
  job->spare_film = std::make_unique<Film>(job->plan.film());
  return job;
}

Job* Coordinator::start_frame_locked(Sequence& s, double now) {
  while (s.next < s.frames.size() && s.jobs[s.next]) ++s.next;
  if (s.next == s.frames.size() || !s.live()) return nullptr;
  std::unique_ptr<Job> job = std::move(s.prepared);
  if (!job || job->frame_index != s.next) job = make_frame_job(s, s.next);  // (none made in time: here)
  job->submitted = job->last_checkpoint = now;
  Job& j = *job;
  jobs_[j.id] = std::move(job);
  s.jobs[s.next++] = &j;
  ++s.live_frames;
  if (s.state == v1::JobStatus::QUEUED) {
    s.state = v1::JobStatus::RUNNING;
    s.started = now;
  }
  if (j.plan.done()) end_job_locked(j, v1::JobStatus::DONE, now);  // nothing to render (cannot happen today)
  return &j;
}

void Coordinator::prepare_frames(const std::vector<Sequence*>& sequences) {
  for (Sequence* s : sequences) {
    size_t index;
    {
      std::lock_guard<std::mutex> lock(mu_);
      index = s->next;
      if (!s->live() || s->prepared || index >= s->frames.size()) continue;
    }
    std::unique_ptr<Job> job = make_frame_job(*s, index);  // its films, outside the lock
    std::lock_guard<std::mutex> lock(mu_);
    if (s->live() && !s->prepared && s->next == index) s->prepared = std::move(job);
  }
}

void Coordinator::frame_ended_locked(Job& job, double now) {
  Sequence& s = *sequences_.at(job.sequence);
  if (s.live_frames > 0) --s.live_frames;
  if (!s.live()) return;  // the sequence ended first and ends its frames itself
  if (job.state == v1::JobStatus::FAILED) {
    s.error = "frame " + std::to_string(s.frames[job.frame_index]) + ": " + job.error;
    end_sequence_locked(s, v1::JobStatus::FAILED, now);
    return;
  }
  ++s.changes;
  if (job.state == v1::JobStatus::DONE && ++s.frames_done == s.frames.size())  // O(1): long sequences end often
    end_sequence_locked(s, v1::JobStatus::DONE, now);
}

void Coordinator::end_sequence_locked(Sequence& s, v1::JobStatus::State state, double now) {
  s.state = state;
  s.finished_at = now;
  s.prepared.reset();
  for (Job* j : s.jobs)
    if (j && j->live()) {
      end_job_locked(*j, v1::JobStatus::CANCELLED, now);
      unwritten_.push_back(j);  // its image keeps what it rendered
    }
  changed_.notify_all();  // (its scene goes once its end is recorded: record_sequence_end)
}

void Coordinator::record_sequence_end(const std::string& id) {
  v1::JobStatus::State state;
  std::string error;
  double elapsed;
  Sequence* sp;
  {
    std::lock_guard<std::mutex> lock(mu_);
    sp = find_sequence(id);
    if (!sp) return;
    Sequence& s = *sp;
    if (s.live() || s.end_recorded || s.end_recording) return;
    if (s.state == v1::JobStatus::DONE)
      for (const Job* j : s.jobs)
        if (!j || !j->end_recorded) return;  // a frame's final checkpoint is not on disk yet
    s.end_recording = true;
    state = s.state;
    error = s.error;
    elapsed = s.started > 0 ? s.finished_at - s.started : 0;
  }
  Sequence& s = *sp;
  bool ok = false;
  try {
    store_->end(s.id, state, error, elapsed);
    ok = true;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera-coordinator: job %s: recording its end: %s\n", s.id.c_str(), e.what());
  }
  if (ok) scenes_.release(s.scene_hash);
  std::lock_guard<std::mutex> lock(mu_);
  s.end_recording = false;
  s.end_recorded = ok;
}

void Coordinator::write_unwritten() {
  std::vector<Job*> jobs;
  {
    std::lock_guard<std::mutex> lock(mu_);
    jobs.swap(unwritten_);
  }
  for (Job* j : jobs) write_image(*j);
}

Job* Coordinator::find(const std::string& id) const {
  auto it = jobs_.find(id);
  if (it == jobs_.end()) throw RequestError(RequestError::Code::kNotFound, "no job '" + id + "'");
  return it->second.get();
}

std::string Coordinator::new_job_id_locked() {
  // Unguessable: 64 random bits, so one client cannot name another's job by counting.
  char buf[17];
  do std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)ids_());
  while (jobs_.count(buf) || sequences_.count(buf));
  return buf;
}

std::string Coordinator::submit(const v1::SubmitJobRequest& req, const std::string& owner) {
  auto refuse = [&](const std::string& why, RequestError::Code code = RequestError::Code::kInvalidArgument) {
    std::lock_guard<std::mutex> lock(mu_);
    ++counters_.jobs_refused;
    return RequestError(code, why);
  };
  if (req.version() != kProtocolVersion)
    throw refuse("protocol version " + std::to_string(req.version()) + " not supported (this coordinator speaks " +
                 std::to_string(kProtocolVersion) + ")");
  RenderSettings settings;
  std::string hash;
  try {
    settings = from_proto(req.settings());
  } catch (const WireError& e) {
    throw refuse(e.what());
  }
  const std::vector<int> frames(req.frames().begin(), req.frames().end());
  if (!frames.empty()) {
    if (settings.frame) throw refuse("a sequence's settings have no frame number: its frames are listed in frames");
    if (frames.size() > kMaxFrames)
      throw refuse(std::to_string(frames.size()) + " frames; at most " + std::to_string(kMaxFrames) + " in one job");
    std::set<int> seen;
    for (const int f : frames) {
      if (f < -RenderSettings::kMaxFrame || f > RenderSettings::kMaxFrame)
        throw refuse("frame " + std::to_string(f) + " out of range (at most " +
                     std::to_string(RenderSettings::kMaxFrame) + " either side of 0)");
      if (!seen.insert(f).second) throw refuse("frame " + std::to_string(f) + " given twice");
    }
  }
  // Limits first, before anything large is allocated. (Submits racing each other may pass
  // together: the limits are for bounding memory and fairness, not exact to the job.)
  const int64_t pixels = settings.effective_window().area();
  const uint64_t samples = uint64_t(pixels) * uint64_t(settings.spp) * std::max<uint64_t>(1, frames.size());  // at most
  uint64_t scene_bytes = 0;
  for (const v1::SceneFile& f : req.files()) scene_bytes += f.path().size() + f.content().size();
  std::string over;  // the limit this job would pass
  const std::string who = owner.empty() ? std::string("this coordinator") : "client '" + owner + "'";
  {
    std::lock_guard<std::mutex> lock(mu_);
    size_t mine = 0;
    int64_t live_pixels = 0;
    uint64_t my_bytes = 0, my_samples = 0;
    for (const auto& [id, j] : jobs_)
      if (j->live()) {
        live_pixels += j->plan.film().window().area();
        if (j->owner != owner) continue;
        my_samples += j->plan.samples_total() - std::min(j->plan.samples_total(), j->plan.samples_merged());
        if (!j->sequence.empty()) continue;  // its sequence counts as the job
        ++mine;
        my_bytes += j->scene_bytes;
      }
    for (const auto& [id, sq] : sequences_)
      if (sq->live() && sq->owner == owner) {
        ++mine;
        my_bytes += sq->scene_bytes;
        my_samples += sq->frame_samples() * (sq->frames.size() - sq->next);  // frames not started
      }
    if (my_bytes + scene_bytes > options_.max_scene_bytes_per_client)
      over = who + "'s live jobs hold " + std::to_string(my_bytes) + " scene bytes; this job's " +
             std::to_string(scene_bytes) + " would pass the limit of " +
             std::to_string(options_.max_scene_bytes_per_client) + " (--max-scene-bytes-per-client)";
    else if (my_samples + samples > options_.max_queued_samples_per_client)
      over = who + " has " + std::to_string(my_samples) + " samples queued; this job's " + std::to_string(samples) +
             " would pass the limit of " + std::to_string(options_.max_queued_samples_per_client) +
             " (--max-queued-samples-per-client)";
    else if (mine >= options_.max_jobs_per_client)
      over = who + " has " + std::to_string(mine) + " live jobs, the most allowed (--max-jobs-per-client)";
    else if (live_pixels + pixels > options_.max_live_pixels)
      over = "live frames hold " + std::to_string(live_pixels) + " pixels; this job's " + std::to_string(pixels) +
             " would pass the limit of " + std::to_string(options_.max_live_pixels) +
             " (--max-live-pixels); try again later";
  }
  if (!over.empty()) throw refuse(over, RequestError::Code::kResourceExhausted);
  try {
    // A bad scene is refused here, and settings that ask it for what it has not.
    hash = scenes_.add(req.main_file(), req.files(),
                       [&](const Scene& scene) { TileRenderer::check_settings(scene, settings); });
  } catch (const WireError& e) {
    throw refuse(e.what());
  } catch (const SettingsError& e) {
    throw refuse(e.what());
  } catch (const SceneError& e) {
    throw refuse(e.what());
  }
  if (!frames.empty()) return submit_sequence(req, settings, frames, hash, owner, scene_bytes);
  // The plan's film is made here, outside the lock: for a large frame, allocating and
  // zeroing it takes long enough to stall every worker. The snapshot film is made the same
  // way, once workers can start on the job (25 ms for 480 x 360 on a 2-core VM).
  auto job = std::make_unique<Job>("", settings);
  job->settings_proto = to_proto(settings);
  job->scene_hash = hash;
  job->name = req.name().empty() ? req.main_file() : req.name();
  job->priority = req.priority();
  job->owner = owner;
  job->scene_bytes = scene_bytes;
  job->tile_lease.assign(job->plan.tiles().size(), 0);
  const Rect window = job->plan.film().window();
  {
    std::lock_guard<std::mutex> lock(mu_);
    job->id = new_job_id_locked();  // 64 random bits: no other submit picks it meanwhile
    job->seq = next_job_++;
  }
  record_submit(req, job->id, job->name, owner, hash, job->seq, job->settings_proto, {});
  const std::string id = job->id;
  Job* added;
  bool ended;
  {
    std::lock_guard<std::mutex> lock(mu_);
    job->submitted = clock_->now();
    job->last_checkpoint = job->submitted;
    added = (jobs_[id] = std::move(job)).get();
    if (added->plan.done()) end_job_locked(*added, v1::JobStatus::DONE, added->submitted);  // nothing to render
    ended = !added->live();
    ++counters_.jobs_submitted;
    changed_.notify_all();
  }
  if (ended) {
    write_image(*added);  // records the end, which lets the scene go
    return id;
  }
  auto spare = std::make_unique<Film>(window);  // all zero, as the plan's film is
  std::lock_guard<std::mutex> lock(mu_);
  if (added->live() && !added->spare_film) added->spare_film = std::move(spare);  // (unless a snapshot made one)
  return id;
}

std::string Coordinator::submit_sequence(const v1::SubmitJobRequest& req, const RenderSettings& settings,
                                         const std::vector<int>& frames, const std::string& hash,
                                         const std::string& owner, uint64_t scene_bytes) {
  auto s = std::make_unique<Sequence>();
  s->settings = settings;
  s->settings_proto = to_proto(settings);
  s->frames = frames;
  s->jobs.assign(frames.size(), nullptr);
  s->scene_hash = hash;
  s->name = req.name().empty() ? req.main_file() : req.name();
  s->priority = req.priority();
  s->owner = owner;
  s->scene_bytes = scene_bytes;
  {
    std::lock_guard<std::mutex> lock(mu_);
    s->id = new_job_id_locked();
    s->seq = next_job_++;
  }
  s->prepared = make_frame_job(*s, 0);  // the first frame's films, outside the lock
  record_submit(req, s->id, s->name, owner, hash, s->seq, s->settings_proto, frames);
  std::lock_guard<std::mutex> lock(mu_);
  s->submitted = clock_->now();
  const std::string id = s->id;
  sequences_[id] = std::move(s);
  ++counters_.jobs_submitted;
  changed_.notify_all();
  return id;
}

void Coordinator::record_submit(const v1::SubmitJobRequest& req, const std::string& id, const std::string& name,
                                const std::string& owner, const std::string& hash, uint64_t seq,
                                const v1::RenderSettings& settings, const std::vector<int>& frames) {
  StoredJob row;
  row.id = id;
  row.name = name;
  row.owner = owner;
  row.scene_hash = hash;
  row.main_file = req.main_file();
  row.priority = req.priority();
  row.seq = seq;
  row.settings = settings;
  row.frames = frames;
  try {
    store_->add(row);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera-coordinator: submit: %s\n", e.what());
    scenes_.release(hash);
    std::lock_guard<std::mutex> lock(mu_);
    ++counters_.jobs_refused;
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "the coordinator cannot record the job: " + without_data_dir(e.what()));
  }
}

std::map<std::string, uint32_t> Coordinator::workers_on_frames_locked(const Sequence& s) const {
  std::map<std::string, uint32_t> out;
  for (const Job* j : s.jobs)
    if (j && j->live()) out[j->id] = workers_on(*j);
  return out;
}

v1::JobStatus Coordinator::status(const std::string& id, bool with_tiles) const {
  std::lock_guard<std::mutex> lock(mu_);
  if (const Sequence* s = find_sequence(id)) return s->status(clock_->now(), workers_on_frames_locked(*s), true);
  const Job& job = *find(id);
  return job.status(clock_->now(), workers_on(job), with_tiles);
}

std::vector<v1::JobStatus> Coordinator::list() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::pair<uint64_t, v1::JobStatus>> out;  // stills and sequences; frames are in their sequences
  for (const auto& [id, job] : jobs_)
    if (job->sequence.empty()) out.emplace_back(job->seq, job->status(clock_->now(), workers_on(*job), false));
  for (const auto& [id, s] : sequences_)
    out.emplace_back(s->seq, s->status(clock_->now(), workers_on_frames_locked(*s), false));
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<v1::JobStatus> statuses;
  for (auto& [seq, st] : out) statuses.push_back(std::move(st));
  return statuses;
}

v1::RegisterResponse Coordinator::register_worker(const v1::RegisterRequest& req, const std::string& principal) {
  if (req.version() != kProtocolVersion)
    throw RequestError(RequestError::Code::kInvalidArgument,
                       "protocol version " + std::to_string(req.version()) + " not supported");
  std::lock_guard<std::mutex> lock(mu_);
  if (!principal.empty() && quarantined_principals_.count(principal))
    throw RequestError(
        RequestError::Code::kPermissionDenied,
        "worker token '" + principal + "' is quarantined: its results differed from the same tasks rendered elsewhere");
  const double now = clock_->now();
  if (workers_.size() >= options_.max_workers) workers_.forget_silent(now, options_.worker_timeout_seconds);
  if (workers_.size() >= options_.max_workers)
    throw RequestError(RequestError::Code::kResourceExhausted,
                       "the coordinator has its " + std::to_string(options_.max_workers) + " workers");
  WorkerInfo& w = workers_.add(req.name(), req.threads(), now);
  w.principal = principal;
  v1::RegisterResponse r;
  r.set_worker_id(w.id);
  r.set_heartbeat_interval_ms(uint32_t(options_.heartbeat_seconds * 1000));
  r.set_lease_ms(uint32_t(options_.lease_seconds * 1000));
  return r;
}

void Coordinator::lease_ended_locked(uint64_t id, const Lease& l, bool requeue) {
  if (l.check) {  // a check waits for another worker
    if (auto c = checks_.find(l.check); c != checks_.end() && c->second.lease == id) {
      c->second.lease = 0;
      c->second.since = clock_->now();
    }
  } else if (auto job = jobs_.find(l.job); job != jobs_.end() && job->second->tile_lease[l.tile] == id) {
    job->second->tile_lease[l.tile] = 0;
    if (requeue) job->second->plan.put_back(l.tile);
  }
  if (WorkerInfo* w = workers_.find(l.worker); w && w->leases > 0) --w->leases;
}

void Coordinator::end_lease_locked(uint64_t id, bool requeue) {
  if (const std::optional<Lease> l = leases_.end(id)) lease_ended_locked(id, *l, requeue);
}

size_t Coordinator::expire_locked(double now) {
  const auto expired = leases_.expire(now);
  for (const auto& [id, l] : expired) lease_ended_locked(id, l, true);
  counters_.leases_expired += expired.size();
  if (!expired.empty()) changed_.notify_all();
  return expired.size();
}

size_t Coordinator::expire_leases() {
  std::vector<ImageSnapshot> finished;
  size_t expired;
  std::vector<Sequence*> unprepared;  // their next frame's job is made here, off every worker's path
  {
    std::lock_guard<std::mutex> lock(mu_);
    const double now = clock_->now();
    // Here, on the reaper's tick, not in every GetTask: it walks every worker.
    workers_.forget_silent(now, options_.worker_timeout_seconds);
    expired = expire_locked(now);
    // A check that no other worker can take (none is registered) or took for two lease
    // periods is skipped, so that a job does not wait for a second worker forever.
    std::set<Job*> touched;
    for (auto it = checks_.begin(); it != checks_.end();) {
      auto next = std::next(it);
      const size_t others = workers_.size() - (workers_.find(it->second.first_worker) ? 1 : 0);
      if (it->second.lease == 0 && (others == 0 || now - it->second.since > 2 * options_.lease_seconds)) {
        touched.insert(jobs_.at(it->second.job).get());
        drop_check_locked(it, true);
      }
      it = next;
    }
    for (Job* job : touched)
      if (auto snap = finish_if_done_locked(*job, now)) finished.push_back(std::move(*snap));
    for (auto& [id, sq] : sequences_)
      if (sq->live() && !sq->prepared && sq->next < sq->frames.size()) unprepared.push_back(sq.get());
  }
  for (ImageSnapshot& snap : finished) write_snapshot(snap);
  prepare_frames(unprepared);
  return expired;
}

void Coordinator::drop_check_locked(std::map<uint64_t, Check>::iterator it, bool skipped) {
  if (it->second.lease) end_lease_locked(it->second.lease, false);
  if (auto job = jobs_.find(it->second.job); job != jobs_.end() && job->second->pending_checks > 0)
    --job->second->pending_checks;
  counters_.checks_skipped += skipped;
  checks_.erase(it);
}

std::optional<Coordinator::ImageSnapshot> Coordinator::finish_if_done_locked(Job& job, double now) {
  if (!job.live() || !job.plan.done() || job.pending_checks > 0) return std::nullopt;
  end_job_locked(job, v1::JobStatus::DONE, now);
  changed_.notify_all();
  job.image_frame_passes = job.plan.frame_passes_done();
  job.last_image = job.last_checkpoint = now;
  return snapshot_locked(job, true, true);
}

v1::GetTaskResponse Coordinator::get_task(uint64_t worker_id, uint32_t max_tasks, uint64_t max_samples) {
  v1::GetTaskResponse resp;
  std::lock_guard<std::mutex> lock(mu_);
  const double now = clock_->now();
  expire_locked(now);
  if (quarantined_.count(worker_id))
    throw RequestError(RequestError::Code::kPermissionDenied,
                       "worker " + std::to_string(worker_id) +
                           " is quarantined: its results differed from the same tasks rendered elsewhere");
  WorkerInfo* w = workers_.find(worker_id);
  if (!w)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "unknown worker " + std::to_string(worker_id) + "; register again");
  w->last_seen = now;
  // Live jobs (frames of sequences among them), and sequences with frames still to start,
  // by priority, then submission, then frame: a sequence's next frame comes after its
  // started ones and before later jobs, so its first frames finish first and workers go
  // from one frame to the next without waiting.
  struct Source {
    int32_t priority;
    uint64_t seq;
    size_t frame;
    Job* job;
    Sequence* sequence;  // a sequence's frames to start
  };
  std::vector<Source> order;
  uint64_t outstanding = leases_.live_count();  // tasks out now or ready to go, checks included
  for (const auto& [check_id, c] : checks_) outstanding += c.lease == 0;
  for (auto& [id, job] : jobs_)
    if (job->live()) {
      order.push_back({job->priority, job->seq, job->frame_index, job.get(), nullptr});
      outstanding += job->plan.ready();
    }
  for (auto& [id, sq] : sequences_)
    if (sq->live() && sq->next < sq->frames.size()) {
      order.push_back({sq->priority, sq->seq, sq->frames.size(), nullptr, sq.get()});
      // As if the frames it may start were ready: a worker's share counts them.
      const uint32_t startable = kMaxLiveFrames - std::min(kMaxLiveFrames, sq->live_frames);
      outstanding += uint64_t(sq->frame_tiles()) * std::min<uint64_t>(sq->frames.size() - sq->next, startable);
    }
  std::sort(order.begin(), order.end(), [](const Source& a, const Source& b) {
    if (a.priority != b.priority) return a.priority > b.priority;
    return a.seq != b.seq ? a.seq < b.seq : a.frame < b.frame;
  });
  // No more than the worker's share (by threads) of the work there is, less what it holds:
  // when a small frame has fewer tasks than the workers would queue, the first to ask must
  // not take them all while the others idle.
  const uint64_t share =
      (outstanding * w->threads + workers_.threads() - 1) / std::max<uint64_t>(1, workers_.threads());
  const uint64_t unshared = share > w->leases ? share - w->leases : 0;
  max_tasks = uint32_t(std::min<uint64_t>(std::clamp<uint32_t>(max_tasks, 1, kMaxTasksPerRequest), unshared));
  uint64_t samples = 0;
  // Checks first (they are few, and a job waits for its checks to end): any worker but
  // the one whose result is checked.
  for (auto& [check_id, c] : checks_) {
    if (uint32_t(resp.tasks_size()) >= max_tasks) break;
    if (c.lease || c.first_worker == worker_id) continue;
    Lease l{c.job, c.tile, c.pass, worker_id, now + options_.lease_seconds, nullptr};
    l.check = check_id;
    c.lease = leases_.grant(std::move(l));
    ++w->leases;
    v1::Task* task = resp.add_tasks();
    *task = *c.task;
    task->set_task_id(c.lease);
    ++counters_.tasks_dispatched;
  }
  // Verification needs a second worker.
  const bool sample_checks = options_.verify_fraction > 0 && workers_.size() > 1;
  std::uniform_real_distribution<double> uniform(0, 1);
  auto room = [&] { return uint32_t(resp.tasks_size()) < max_tasks && (max_samples == 0 || samples < max_samples); };
  int64_t live_pixels = -1;  // counted when first needed
  auto take_from = [&](Job* job) {
    while (room()) {
      std::optional<TileTask> t = job->plan.take();
      if (!t) break;
      const uint64_t task_id =
          leases_.grant({job->id, t->tile, t->pass, worker_id, now + options_.lease_seconds, nullptr});
      job->tile_lease[t->tile] = task_id;
      ++w->leases;
      if (job->state == v1::JobStatus::QUEUED) {
        job->state = v1::JobStatus::RUNNING;
        job->started = now;
      }
      v1::Task* task = resp.add_tasks();
      task->set_task_id(task_id);
      task->set_job_id(job->id);
      task->set_scene_hash(job->scene_hash);
      *task->mutable_settings() = job->settings_proto;
      *task->mutable_tile() = to_proto(t->rect);
      task->set_pass(t->pass);
      task->set_sample_begin(t->sample_begin);
      task->set_sample_end(t->sample_end);
      uint64_t pixels = uint64_t(t->rect.area());
      if (!t->active.empty()) {
        task->set_active(t->active.data(), t->active.size());
        pixels = uint64_t(std::count(t->active.begin(), t->active.end(), 1));
      }
      samples += pixels * (t->sample_end - t->sample_begin);
      ++counters_.tasks_dispatched;
      if (sample_checks && uniform(ids_) < options_.verify_fraction)
        leases_.live(task_id)->task = std::make_shared<const v1::Task>(*task);
    }
  };
  for (const Source& src : order) {
    if (src.job) {
      take_from(src.job);
      continue;
    }
    // The worker has room and the sequence's started frames have no ready task: start the
    // next frame, within the limits on films in memory.
    Sequence& sq = *src.sequence;
    while (room() && sq.live_frames < kMaxLiveFrames) {
      if (live_pixels < 0) {
        live_pixels = 0;
        for (const auto& [id, j] : jobs_)
          if (j->live()) live_pixels += j->plan.film().window().area();
      }
      const int64_t pixels = sq.settings.effective_window().area();
      if (sq.live_frames > 0 && live_pixels + pixels > options_.max_live_pixels) break;
      Job* job = start_frame_locked(sq, now);
      if (!job) break;
      live_pixels += pixels;
      take_from(job);
    }
  }
  if (resp.tasks_size() == 0) resp.set_retry_after_ms(200);
  return resp;
}

v1::SceneBundle Coordinator::scene(const std::string& hash) const {
  try {
    return scenes_.get(hash);
  } catch (const std::out_of_range&) {
    throw RequestError(RequestError::Code::kNotFound, "no scene with hash " + hash);
  }
}

std::vector<uint64_t> Coordinator::heartbeat(uint64_t worker_id, const std::vector<uint64_t>& task_ids) {
  std::lock_guard<std::mutex> lock(mu_);
  const double now = clock_->now();
  if (WorkerInfo* w = workers_.find(worker_id)) w->last_seen = now;
  std::vector<uint64_t> refused;
  for (uint64_t id : task_ids)
    if (!leases_.renew(id, worker_id, now + options_.lease_seconds)) refused.push_back(id);
  return refused;
}

void Coordinator::release(uint64_t worker_id, uint64_t task_id, const std::string& error) {
  Job* failed = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const Lease* l = leases_.live(task_id);
    if (!l || l->worker != worker_id) return;
    const std::string job_id = l->job;
    end_lease_locked(task_id, true);
    ++counters_.leases_released;
    changed_.notify_all();
    auto it = jobs_.find(job_id);
    if (error.empty() || it == jobs_.end() || !it->second->live()) return;
    Job& job = *it->second;
    ++counters_.tasks_failed;
    job.failed_on.insert(worker_id);
    if (job.failed_on.size() < kFailuresToFail) return;  // maybe that worker's trouble: another tries
    job.error = "tasks failed on " + std::to_string(job.failed_on.size()) + " workers: " + error.substr(0, 1024);
    end_job_locked(job, v1::JobStatus::FAILED, clock_->now());
    failed = &job;
  }
  write_image(*failed);  // keep what was rendered
  write_unwritten();     // a sequence's other frames, when a frame failed
  if (!failed->sequence.empty()) record_sequence_end(failed->sequence);
}

void Coordinator::end_job_locked(Job& job, v1::JobStatus::State state, double now) {
  job.state = state;
  job.finished_at = now;
  for (auto it = checks_.begin(); it != checks_.end();) {  // undecided checks: moot now
    auto next = std::next(it);
    if (it->second.job == job.id) drop_check_locked(it, false);
    it = next;
  }
  for (uint64_t lease : job.tile_lease)
    if (lease) end_lease_locked(lease, false);
  leases_.forget_job(job.id);
  // Its scene is dropped, from memory and disk, once its end is on disk (write_snapshot)
  // and no live job uses it: a crash before then finds the job live and its scene there.
  // The film (and so the image) stays. Submitting the scene again checks it again. A
  // sequence holds the scene for its frames until its own end is recorded.
  if (!job.sequence.empty()) frame_ended_locked(job, now);
}

void Coordinator::unregister(uint64_t worker_id) {
  std::lock_guard<std::mutex> lock(mu_);
  for (uint64_t id : leases_.held_by(worker_id)) {
    end_lease_locked(id, true);
    ++counters_.leases_released;
  }
  workers_.remove(worker_id);
  changed_.notify_all();
}

v1::ResultAck Coordinator::submit_result(const v1::TaskResult& result) { return submit_results({&result})[0]; }

std::vector<v1::ResultAck> Coordinator::submit_results(const std::vector<const v1::TaskResult*>& results) {
  std::vector<v1::ResultAck> acks(results.size());
  // Is each result's task known, answered by its lease's holder and still wanted? Then its
  // sums are decoded and checked outside the lock (the slow part), and the batch merged
  // under one hold of it, each looked at again: another copy may have been merged meanwhile.
  auto wanted = [&](size_t i, Lease* out) -> bool {
    const v1::TaskResult& result = *results[i];
    const Lease* l = leases_.known(result.task_id());
    // Never issued, or issued to another worker: only the lease's holder may answer it.
    if (!l || l->worker != result.worker_id() || quarantined_.count(l->worker)) {
      ++counters_.results_rejected;
      return false;
    }
    *out = *l;
    if (l->check) return true;  // checked in check_result
    auto job = jobs_.find(l->job);
    if (job == jobs_.end() || !job->second->live()) return false;
    if (!job->second->plan.wants(l->tile, l->pass)) {
      ++counters_.results_duplicate;
      acks[i].set_duplicate(true);
      return false;
    }
    return true;
  };
  struct Incoming {
    size_t index;
    size_t pixels = 0;
    uint32_t pass_len = 0;
    std::optional<CheckedSums> sums;
  };
  std::vector<Incoming> incoming;
  std::vector<std::pair<size_t, Lease>> checks;  // results of verification tasks
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (size_t i = 0; i < results.size(); ++i) {
      Lease lease;
      if (!wanted(i, &lease)) continue;
      if (lease.check) {
        checks.emplace_back(i, std::move(lease));
        continue;
      }
      const FramePlan& plan = jobs_.at(lease.job)->plan;
      const auto& [s0, s1] = plan.passes()[lease.pass];
      const size_t pixels = size_t(plan.tiles()[lease.tile].area());
      incoming.push_back({i, pixels, s1 - s0, std::nullopt});
    }
  }
  uint64_t malformed = 0;
  for (Incoming& in : incoming) {
    try {
      in.sums = FramePlan::check(result_sums(*results[in.index], in.pixels), in.pass_len);
    } catch (const WireError&) {
    }
    malformed += !in.sums;
  }
  std::vector<ImageSnapshot> pending;
  bool merged = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    counters_.results_rejected += malformed;
    for (Incoming& in : incoming) {
      if (!in.sums) continue;
      const v1::TaskResult& result = *results[in.index];
      Lease lease;
      if (!wanted(in.index, &lease) || lease.check) continue;
      Job& job = *jobs_.at(lease.job);
      const auto t0 = std::chrono::steady_clock::now();
      if (job.plan.merge(lease.tile, lease.pass, *in.sums) != FramePlan::Merge::kMerged) {
        ++counters_.results_rejected;
        continue;
      }
      counters_.merge_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      counters_.samples_merged += in.sums->samples();
      ++counters_.results_merged;
      // Whichever copy of the task arrived first won; every lease on this (tile, pass) ends
      // (kept known, so a repeat of this result is recognised as a duplicate).
      const uint64_t other = job.tile_lease[lease.tile];
      end_lease_locked(result.task_id(), false);
      if (other) end_lease_locked(other, false);
      job.merged_by[result.worker_id()].push_back(lease.tile);
      if (!job.sequence.empty()) ++sequences_.at(job.sequence)->changes;
      if (lease.task) {  // picked for verification: another worker renders it again
        Check& c = checks_[next_check_++];
        c.job = job.id;
        c.tile = lease.tile;
        c.pass = lease.pass;
        c.task = lease.task;
        c.first_worker = result.worker_id();
        c.digest = sums_digest(in.sums->sums());
        c.since = clock_->now();
        ++job.pending_checks;
        ++counters_.checks_issued;
      }
      if (std::optional<ImageSnapshot> snap = after_merge_locked(job, result, clock_->now()))
        pending.push_back(std::move(*snap));
      acks[in.index].set_accepted(true);
      merged = true;
    }
    if (merged) changed_.notify_all();
  }
  for (ImageSnapshot& snap : pending) write_snapshot(snap);
  for (const auto& [i, lease] : checks) acks[i] = check_result(*results[i], lease);
  return acks;
}

v1::ResultAck Coordinator::check_result(const v1::TaskResult& result, const Lease& lease) {
  v1::ResultAck ack;
  Check c;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = checks_.find(lease.check);
    if (it == checks_.end() || it->second.lease != result.task_id()) return ack;  // decided, or moot
    c = it->second;
  }
  const Rect rect = from_proto(c.task->tile());
  uint64_t digest;
  try {
    digest = sums_digest(result_sums(result, size_t(rect.area())));
  } catch (const WireError&) {
    std::lock_guard<std::mutex> lock(mu_);
    ++counters_.results_rejected;
    return ack;
  }
  const uint64_t checker = result.worker_id();
  std::optional<ImageSnapshot> finished;
  std::vector<uint64_t> liars;
  std::string why;
  if (digest != c.digest) {
    // Two workers differ: this process renders the task too, and whoever differs from it
    // is quarantined (both, if all three differ). Rare, so done here, outside the lock.
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++counters_.check_mismatches;
    }
    try {
      const uint64_t ours = sums_digest(render_here(*c.task));
      if (ours != c.digest) liars.push_back(c.first_worker);
      if (ours != digest) liars.push_back(checker);
      why = "job " + c.job + " tile " + std::to_string(c.tile) + " pass " + std::to_string(c.pass) +
            ": its sums differ from the coordinator's render of the same task";
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera-coordinator: check of job %s tile %u: cannot render it here: %s\n", c.job.c_str(),
                   c.tile, e.what());
    }
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = checks_.find(lease.check);
    if (it == checks_.end() || it->second.lease != result.task_id()) return ack;  // moot meanwhile
    drop_check_locked(it, false);
    if (digest == c.digest) ++counters_.checks_passed;
    for (uint64_t w : liars) quarantine_locked(w, why);
    ack.set_accepted(std::find(liars.begin(), liars.end(), checker) == liars.end());
    if (auto job = jobs_.find(c.job); job != jobs_.end()) finished = finish_if_done_locked(*job->second, clock_->now());
    changed_.notify_all();
  }
  if (finished) write_snapshot(*finished);
  return ack;
}

std::vector<PixelSums> Coordinator::render_here(const v1::Task& task) {
  const v1::SceneBundle b = scenes_.get(task.scene_hash());
  static std::atomic<uint64_t> seq{0};
  const fs::path dir =
      fs::path(options_.data_dir) / "scenes" / (task.scene_hash() + ".referee-" + std::to_string(++seq));
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{dir};
  const Scene scene = load_scene(unpack_bundle(dir.string(), b.main_file(), b.files()));
  const Rect rect = from_proto(task.tile());
  if (!task.active().empty() && task.active().size() != size_t(rect.area())) throw WireError("active mask size");
  const auto* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
  TileStats stats;
  return TileRenderer(scene, from_proto(task.settings()))
      .render(rect, task.sample_begin(), task.sample_end(), mask, &stats);
}

void Coordinator::quarantine_locked(uint64_t worker, const std::string& why) {
  if (!quarantined_.insert(worker).second) return;
  ++counters_.workers_quarantined;
  std::string name = std::to_string(worker);
  if (const WorkerInfo* w = workers_.find(worker)) {
    name = "'" + w->name + "' (" + (w->principal.empty() ? "" : "token '" + w->principal + "', ") + name + ")";
    if (!w->principal.empty()) quarantined_principals_.insert(w->principal);
  }
  std::fprintf(stderr, "tessera-coordinator: worker %s quarantined: %s\n", name.c_str(), why.c_str());
  for (uint64_t id : leases_.held_by(worker)) end_lease_locked(id, true);
  // What it merged is rendered again: every tile of a live job it added sums to starts
  // over (a tile's passes build on each other). An ended job is flagged.
  for (auto& [id, job] : jobs_) {
    auto mine = job->merged_by.find(worker);
    if (mine == job->merged_by.end()) continue;
    std::set<uint32_t> tiles(mine->second.begin(), mine->second.end());
    job->merged_by.erase(mine);
    if (job->live()) {
      for (uint32_t t : tiles) {
        if (job->tile_lease[t]) end_lease_locked(job->tile_lease[t], false);
        job->plan.reset_tile(t);
        ++counters_.tiles_rendered_again;
      }
      for (auto it = checks_.begin(); it != checks_.end();) {  // checks of those tiles are moot
        auto next = std::next(it);
        if (it->second.job == id && tiles.count(it->second.tile)) drop_check_locked(it, false);
        it = next;
      }
    } else if (job->state == v1::JobStatus::DONE) {
      job->error += std::string(job->error.empty() ? "" : "; ") + std::to_string(tiles.size()) +
                    " tiles hold results of worker " + name +
                    ", quarantined after the job ended (its results differed from the same tasks rendered "
                    "elsewhere): submit the job again for an image without them";
      try {
        store_->end(job->id, job->state, job->error, job->finished_at - job->started);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "tessera-coordinator: job %s: %s\n", job->id.c_str(), e.what());
      }
    }
  }
  workers_.remove(worker);
  changed_.notify_all();
}

std::optional<Coordinator::ImageSnapshot> Coordinator::after_merge_locked(Job& job, const v1::TaskResult& result,
                                                                          double now) {
  workers_.record_result(result.worker_id(), result.samples(), result.render_seconds(), result.busy_thread_seconds(),
                         result.thread_seconds(), now);
  const bool done = job.plan.done() && job.pending_checks == 0;  // every check decided
  if (done) end_job_locked(job, v1::JobStatus::DONE, now);
  const uint32_t frame = job.plan.frame_passes_done();
  // Progressive images and checkpoints take at most 1/kWriteShare of the time: a large
  // frame's take long enough to write that the interval alone would let writing crowd out
  // merging.
  constexpr double kWriteShare = 20;
  const double image_interval = std::max(options_.image_interval_seconds, kWriteShare * job.image_write_seconds);
  const double checkpoint_interval = std::max(options_.checkpoint_seconds, kWriteShare * job.checkpoint_write_seconds);
  const bool image = done || (frame > job.image_frame_passes && now - job.last_image >= image_interval);
  const bool checkpoint = done || now - job.last_checkpoint >= checkpoint_interval;
  if (!image && !checkpoint) return std::nullopt;
  if (image) {
    job.image_frame_passes = frame;
    job.last_image = now;
  }
  if (checkpoint) job.last_checkpoint = now;
  return snapshot_locked(job, image, checkpoint);
}

Coordinator::ImageSnapshot Coordinator::snapshot_locked(Job& job, bool image, bool checkpoint) {
  ImageSnapshot snap;
  snap.job = &job;
  if (!job.plan.has_film()) return snap;  // ended, written, released: nothing to write
  std::unique_ptr<Film> film = std::move(job.spare_film);
  if (film)
    *film = job.plan.film();  // into the mapped pages of the last snapshot
  else
    film = std::make_unique<Film>(job.plan.film());
  snap.film = std::move(film);
  snap.seq = ++job.image_seq;
  snap.merges = job.plan.merges();
  snap.image = image;
  snap.checkpoint = checkpoint;
  if (checkpoint) {
    snap.plan = job.plan.state();
    job.checkpoint_merges = snap.merges;
  }
  snap.elapsed = job.started > 0 ? (job.live() ? clock_->now() : job.finished_at) - job.started : 0;
  snap.ended = !job.live();
  snap.state = job.state;
  snap.error = job.error;
  snap.meta = {{"job", job.id},
               {"scene", job.name},
               {"seed", std::to_string(job.plan.settings().seed)},
               {"frame_passes", std::to_string(job.plan.frame_passes_done())}};
  if (job.started > 0) snap.meta["render_seconds"] = std::to_string(snap.elapsed);
  if (const std::optional<int>& frame = job.plan.settings().frame) {
    snap.meta["frame"] = std::to_string(*frame);
    snap.meta["time"] = std::to_string(job.plan.settings().time());  // seconds: frame / fps
  }
  return snap;
}

void Coordinator::write_snapshot(ImageSnapshot& snap) {
  if (!snap.film) return;
  if (options_.before_image_write) options_.before_image_write();
  Job& job = *snap.job;
  enum Outcome { kSkipped, kWritten, kFailed };  // skipped: a newer one is written
  Outcome image = kSkipped, checkpoint = kSkipped;
  std::string image_why, checkpoint_why;
  double image_seconds = 0, checkpoint_seconds = 0;
  bool release_film = false;
  auto attempt = [&](const char* what, double* seconds, std::string* why, auto&& write) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      write();
      *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      return kWritten;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera-coordinator: job %s: %s: %s (kept in memory; retried)\n", job.id.c_str(), what,
                   e.what());
      *why = without_data_dir(e.what());
      return kFailed;
    }
  };
  {
    std::lock_guard<std::mutex> wl(job.write_mu);
    if (snap.image && snap.seq > job.written_seq) {
      image = attempt("image", &image_seconds, &image_why, [&] { sink_->write(job.id, *snap.film, snap.meta); });
      if (image == kWritten) {
        job.written_seq = snap.seq;
        job.written_merges = snap.merges;
      }
    }
    if (snap.checkpoint && snap.seq > job.checkpoint_seq) {
      checkpoint = attempt("checkpoint", &checkpoint_seconds, &checkpoint_why,
                           [&] { store_->write_checkpoint(job.id, snap.plan, *snap.film, snap.elapsed); });
      if (checkpoint == kWritten) {
        job.checkpoint_seq = snap.seq;
        job.checkpoint_written_merges = snap.merges;
      }
    }
    // A DONE job's end is recorded once the checkpoint with its whole film is on disk, so
    // that a restart never finds a DONE job with part of a film. A cancelled or failed job's
    // end is recorded at once: nothing more will be rendered for it either way.
    const bool whole = job.checkpoint_written_merges == snap.merges;
    if (snap.ended && !job.end_recorded && (whole || snap.state != v1::JobStatus::DONE)) {
      try {
        if (job.sequence.empty()) {  // (a frame has no row; its sequence holds the scene)
          store_->end(job.id, snap.state, snap.error, snap.elapsed);
          scenes_.release(job.scene_hash);
        }
        job.end_recorded = true;
      } catch (const std::exception& e) {
        std::fprintf(stderr, "tessera-coordinator: job %s: recording its end: %s\n", job.id.c_str(), e.what());
      }
    }
    release_film = snap.ended && job.end_recorded && whole && job.written_merges == snap.merges;
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (image == kWritten) job.image_write_seconds = image_seconds;
    if (checkpoint == kWritten) job.checkpoint_write_seconds = checkpoint_seconds;
    counters_.images_written += image == kWritten;
    counters_.image_errors += image == kFailed;
    counters_.checkpoints_written += checkpoint == kWritten;
    counters_.checkpoint_errors += checkpoint == kFailed;
    if (image == kWritten) job.image_error.clear();
    if (image == kFailed) job.image_error = image_why;
    if (checkpoint == kWritten) job.checkpoint_error.clear();
    if (checkpoint == kFailed) job.checkpoint_error = checkpoint_why;
    if (job.live())
      job.spare_film = std::move(snap.film);  // for the next snapshot
    else if (release_film)
      job.plan.release_film();  // the image and checkpoint on disk hold it all
  }
  if (snap.ended && !job.sequence.empty()) {
    record_sequence_end(job.sequence);
  }
}

void Coordinator::write_image(Job& job) {
  ImageSnapshot snap;
  {
    std::lock_guard<std::mutex> lock(mu_);
    snap = snapshot_locked(job);
  }
  write_snapshot(snap);
}

void Coordinator::checkpoint_all() {
  std::vector<ImageSnapshot> snaps;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& [id, job] : jobs_)
      if (job->live() && job->plan.merges() != job->checkpoint_merges) {
        job->last_checkpoint = clock_->now();
        snaps.push_back(snapshot_locked(*job, false, true));
      }
  }
  for (ImageSnapshot& snap : snaps) write_snapshot(snap);
}

v1::JobStatus Coordinator::cancel(const std::string& id, const std::string& requester, bool any) {
  auto refuse_other = [&](const std::string& owner) {
    if (!any && owner != requester)
      throw RequestError(RequestError::Code::kPermissionDenied,
                         "job " + id + " belongs to '" + owner + "': a client may cancel only its own jobs");
  };
  Job* job = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (Sequence* s = find_sequence(id)) {
      refuse_other(s->owner);
      // Finished frames stay as they are; frames being rendered keep what they have.
      if (s->live()) end_sequence_locked(*s, v1::JobStatus::CANCELLED, clock_->now());
    } else {
      job = find(id);
      refuse_other(job->owner);
      if (!job->sequence.empty())
        throw RequestError(RequestError::Code::kFailedPrecondition,
                           "job " + id + " is a frame of sequence " + job->sequence + ": cancel the sequence");
      if (!job->live()) return job->status(clock_->now(), 0, false);
      end_job_locked(*job, v1::JobStatus::CANCELLED, clock_->now());
      changed_.notify_all();
    }
  }
  if (job) {
    write_image(*job);  // keep what was rendered
  } else {
    write_unwritten();
    record_sequence_end(id);
  }
  return status(id, false);
}

Job* Coordinator::frame_job_locked(const std::string& id, std::optional<int> frame) const {
  const Sequence* s = find_sequence(id);
  if (!s) {
    Job* job = find(id);
    if (frame && job->plan.settings().frame != frame)
      throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " has no frame " + std::to_string(*frame));
    return job;
  }
  if (!frame)
    throw RequestError(RequestError::Code::kInvalidArgument, "job " + id + " is a sequence of " +
                                                                 std::to_string(s->frames.size()) +
                                                                 " frames: name one (fetch --frame N, or --all)");
  const auto at = std::find(s->frames.begin(), s->frames.end(), *frame);
  if (at == s->frames.end())
    throw RequestError(RequestError::Code::kNotFound, "job " + id + " has no frame " + std::to_string(*frame));
  Job* job = s->jobs[size_t(at - s->frames.begin())];
  if (!job)
    throw RequestError(RequestError::Code::kFailedPrecondition,
                       "job " + id + ": frame " + std::to_string(*frame) +
                           (s->live() ? " has not started yet" : " was never rendered (the job ended first)"));
  return job;
}

v1::Image Coordinator::image(const std::string& id, bool exr, bool png, std::optional<int> frame) {
  Job* job;
  bool live;
  uint64_t merges;
  {
    std::lock_guard<std::mutex> lock(mu_);
    job = frame_job_locked(id, frame);
    live = job->live();
    merges = job->plan.merges();
  }
  // A live job gets its latest image. An ended job's film no longer changes, and the image
  // must hold all of it: the merge (or cancel) that ended the job writes its last snapshot
  // after releasing mu_, so a client that saw the end can get here first.
  bool current;
  {
    std::lock_guard<std::mutex> wl(job->write_mu);
    current = job->written_seq > 0 && (live || job->written_merges == merges);
  }
  if (!current) write_image(*job);
  v1::Image img;
  {
    std::lock_guard<std::mutex> wl(job->write_mu);
    if (job->written_seq == 0 || (!live && job->written_merges != merges)) {
      std::lock_guard<std::mutex> lock(mu_);
      throw RequestError(RequestError::Code::kFailedPrecondition,
                         "job " + job->id + ": its image could not be written (" + job->image_error +
                             "); the samples are kept and the write is retried");
    }
    if (exr) img.set_exr(sink_->exr(job->id));
    if (png) img.set_png(sink_->png(job->id));
  }
  std::lock_guard<std::mutex> lock(mu_);
  img.set_frame_passes_done(job->image_frame_passes);
  return img;
}

v1::JobStatus Coordinator::wait_for_change(const std::string& id, uint64_t last_samples, double timeout) const {
  std::unique_lock<std::mutex> lock(mu_);
  if (const Sequence* s = find_sequence(id)) {
    // Any merge into any frame since the caller's status (whose samples it passed); the
    // predicate is O(1) however long the sequence (it runs on every merge's notify).
    const uint64_t since = s->changes;
    if (s->samples_merged() != last_samples) return s->status(clock_->now(), workers_on_frames_locked(*s), true);
    changed_.wait_for(lock, std::chrono::duration<double>(timeout), [&] { return !s->live() || s->changes != since; });
    return s->status(clock_->now(), workers_on_frames_locked(*s), true);
  }
  const Job* job = find(id);
  changed_.wait_for(lock, std::chrono::duration<double>(timeout),
                    [&] { return !job->live() || job->plan.samples_merged() != last_samples; });
  return job->status(clock_->now(), workers_on(*job), false);
}

bool Coordinator::wait_for_end(const std::string& id, double timeout) const {
  std::unique_lock<std::mutex> lock(mu_);
  if (const Sequence* s = find_sequence(id))
    return changed_.wait_for(lock, std::chrono::duration<double>(timeout), [&] { return !s->live(); });
  const Job* job = find(id);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout), [&] { return !job->live(); });
}

void Coordinator::wait_for_work(double timeout) const {
  std::unique_lock<std::mutex> lock(mu_);
  changed_.wait_for(lock, std::chrono::duration<double>(timeout));
}

std::vector<WorkerInfo> Coordinator::workers() const {
  std::lock_guard<std::mutex> lock(mu_);
  return workers_.list();
}

double Coordinator::utilization() const {
  std::lock_guard<std::mutex> lock(mu_);
  return workers_.utilization();
}

Coordinator::Queue Coordinator::queue() const {
  std::lock_guard<std::mutex> lock(mu_);
  Queue q;
  q.tasks_leased = leases_.live_count();
  for (const auto& [id, job] : jobs_)
    if (job->live()) {
      q.tasks_ready += job->plan.ready();
      q.samples_remaining +=
          job->plan.samples_total() - std::min(job->plan.samples_total(), job->plan.samples_merged());
    }
  for (const auto& [id, s] : sequences_)  // frames not started yet
    if (s->live()) {
      for (size_t i = s->next; i < s->frames.size(); ++i) q.samples_remaining += s->jobs[i] ? 0 : s->frame_samples();
      q.tasks_ready += s->next < s->frames.size() ? s->frame_tiles() : 0;  // the next frame's first passes
    }
  double speed = 0, threads = 0;
  for (const WorkerInfo& w : workers_.list())
    if (w.samples_per_second > 0) {
      speed += w.samples_per_second;
      threads += w.threads;
    }
  if (threads > 0) thread_speed_ = speed / threads;
  q.samples_per_thread_second = thread_speed_ > 0 ? thread_speed_ : kAssumedThreadSpeed;
  q.core_seconds_remaining = double(q.samples_remaining) / q.samples_per_thread_second;
  return q;
}

std::string Coordinator::unready_reason() const {
  try {
    store_->ping();
  } catch (const std::exception& e) {
    return without_data_dir(e.what());
  }
  const fs::path probe = fs::path(options_.data_dir) / ".ready-probe";
  try {
    write_file_atomic(probe.string(), "ok\n");
  } catch (const std::exception&) {
    return "the data folder does not take writes";
  }
  std::error_code ec;
  fs::remove(probe, ec);
  return "";
}

CoordinatorCounters Coordinator::counters() const {
  std::lock_guard<std::mutex> lock(mu_);
  return counters_;
}

}  // namespace tessera
