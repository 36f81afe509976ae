#include "server/coordinator.h"

#include <charconv>
#include <filesystem>

#include "core/util/log.h"
#include "core/util/text.h"
#include "server/image_stream.h"
#include "server/recovery.h"
#include "server/referee.h"
#include "server/submission.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

std::unique_ptr<JobStore> sqlite_store(const CoordinatorOptions& o) {
  auto store = std::make_unique<SqliteJobStore>(o.data_dir);
  store->before_checkpoint_rename = o.before_checkpoint_rename;
  store->after_row_commit = o.after_row_commit;
  return store;
}

// What a submit's event says: the job's name, size, samples and frames.
std::string submitted_detail(const v1::SubmitJobRequest& req) {
  const v1::RenderSettings& s = req.settings();
  // Appends, not `+` chains: g++ 12 warns falsely (-Wrestrict) on `"'" + str` here.
  std::string d;
  if (!req.name().empty()) d.append("'").append(peer_text(req.name(), kMaxJobNameBytes)).append("', ");
  d.append(std::to_string(s.width())).append("x").append(std::to_string(s.height()));
  d.append(", ").append(std::to_string(s.spp())).append(" spp");
  if (req.frames_size() > 0) d.append(", ").append(std::to_string(req.frames_size())).append(" frames");
  return d;
}

}  // namespace

Coordinator::Coordinator(CoordinatorOptions options, std::unique_ptr<Clock> clock, std::unique_ptr<ImageSink> sink,
                         std::unique_ptr<JobStore> store)
    : options_(std::move(options)),
      clock_(std::move(clock)),
      sink_(sink ? std::move(sink) : std::make_unique<DiskImageSink>((fs::path(options_.data_dir) / "jobs").string())),
      store_(store ? std::move(store) : sqlite_store(options_)),
      credentials_(*store_),
      scenes_((fs::path(options_.data_dir) / "scenes").string(), options_.max_scene_loads),
      uploads_(scenes_, *clock_, options_.upload_kept_seconds),
      writer_(
          *sink_, *store_,
          {[this](const std::string& hash) { scenes_.release(hash); }, options_.before_image_write, options_.data_dir}),
      referee_(local_referee(scenes_)),
      snapshotter_(options_.image_interval_seconds, options_.checkpoint_seconds),
      leases_(store_->next_generation() << 40),  // 2^40 tasks a run: ids of different runs never meet
      leasing_(leases_, jobs_, workers_, checks_, counters_, options_.lease_seconds),
      lifecycle_(jobs_, leasing_, snapshotter_, counters_),
      sequences_(jobs_, lifecycle_),
      verifier_(options_.verify_fraction, options_.lease_seconds, checks_, jobs_, leasing_, workers_, lifecycle_,
                counters_),
      dispatcher_({jobs_, leases_, leasing_, workers_, checks_, verifier_, sequences_, lifecycle_},
                  options_.max_live_pixels, options_.max_leases_per_worker),
      intake_({jobs_, leases_, leasing_, workers_, verifier_, lifecycle_, snapshotter_, counters_}),
      worker_lifecycle_({workers_, jobs_, leases_, leasing_, checks_, lifecycle_, counters_}, options_),
      control_(jobs_, lifecycle_, snapshotter_, counters_),
      archive_(jobs_) {
  started_ = clock_->now();
  std::set<std::string> archived;  // ids; their scenes and files stay
  std::set<std::string> scenes;
  for (auto& [id, scene] : store_->archived_names()) archived.insert(std::move(id)), scenes.insert(std::move(scene));
  Effects fx;
  {
    MutexLock lock(mu_);
    const auto restore_scene = [this](const std::string& hash) { return scenes_.restore(hash); };
    const auto image_passes = [this](const std::string& job) -> std::optional<uint32_t> {
      const std::map<std::string, std::string> a = sink_->attributes(job);  // (one read of its header)
      const auto final = a.find("tessera/final"), passes = a.find("tessera/frame_passes");
      if (final == a.end() || final->second != "1" || passes == a.end()) return std::nullopt;  // a final image only
      uint32_t n = 0;
      const std::string& v = passes->second;
      if (std::from_chars(v.data(), v.data() + v.size(), n).ec != std::errc()) return std::nullopt;
      return n;
    };
    Recovery recovery({*store_, jobs_, lifecycle_, snapshotter_, counters_, restore_scene, image_passes});
    recovery.restore(clock_->now(), fx);
    for (const StoredJob& row : recovery.kept())  // (unreadable rows: their files stay)
      archived.insert(row.meta.id), scenes.insert(row.meta.scene_hash);
    for (const auto& [id, s] : jobs_.sequences()) fx.sequence_ends.push_back(id);  // ended, not yet recorded
    size_t taken_up = jobs_.sequences().size();
    for (const auto& [id, job] : jobs_.jobs()) taken_up += job->sequence.empty();
    fx.event("coordinator.started", "", "", "jobs taken up: " + std::to_string(taken_up));
    sequence(fx);
    scenes.merge(jobs_.scene_hashes());
    scenes_.remove_unused(scenes);  // scenes of deleted jobs, or of a submit the crash cut short
    // Files of jobs deleted while their files were being removed: no row names them now.
    sink_->remove_unknown([&](const std::string& id) TESSERA_REQUIRES(mu_) {
      const auto frame = Sequence::split_frame_id(id);
      return jobs_.names(id) || archived.count(id) || (frame && archived.count(frame->first));
    });
  }
  apply(std::move(fx));
}

Coordinator::~Coordinator() = default;

// ---- the slow work, after the lock ----

void Coordinator::apply(Effects fx) {
  if (fx.changed) changed_.notify_all();
  if (fx.events_seq) record(std::move(fx.events), fx.events_seq);
  for (const std::shared_ptr<Job>& job : fx.writes) write(job);
  for (const RowEnd& r : fx.rows) try {
      store_->end(r.id, r.state, r.error, r.elapsed);
    } catch (const std::exception& e) {
      spdlog::error("job {}: recording its end: {}", r.id, e.what());
    }
  for (const std::string& id : fx.sequence_ends) record_sequence_end(id);
  for (const Effects::Flag& f : fx.flags) try {
      store_->flag_merged(f.worker, f.flagged_in_memory,
                          [&](uint32_t tiles, bool frames) { return Verifier::ended_flag(tiles, f.name, frames); });
    } catch (const std::exception& e) {
      spdlog::error("worker {}: flagging the archived jobs that hold its results: {}", f.name, e.what());
    }
  for (const Archival& a : fx.archive) archive(a);
  for (const auto& [name, why] : fx.credentials_quarantined) credentials_.quarantine(name, why);
  for (auto& [sequence, index] : fx.prepare) {
    std::shared_ptr<Job> job = SequenceScheduler::make_frame(*sequence, index);  // its films, outside the lock
    MutexLock lock(mu_);
    sequences_.offer(*sequence, index, std::move(job));
  }
}

void Coordinator::record(std::vector<Event> events, uint64_t seq) {
  std::lock_guard<std::mutex> lock(events_mu_);
  events_waiting_[seq] = std::move(events);
  // Every operation's events are recorded by the thread that finds them next in line.
  for (auto it = events_waiting_.begin(); it != events_waiting_.end() && it->first == events_recorded_ + 1;
       it = events_waiting_.erase(it)) {
    ++events_recorded_;
    std::vector<Event>& batch = it->second;
    const double wall = store_->wall();
    for (Event& e : batch) {
      e.time = wall;
      const bool bad = e.kind == "job.failed" || e.kind == "frame.failed" || e.kind == "task.failed" ||
                       e.kind == "worker.quarantined" || e.kind == "worker.lost";
      spdlog::log(bad ? spdlog::level::warn : spdlog::level::info, "{}", event_line(e));
    }
    try {
      store_->append_events(batch);
    } catch (const std::exception& e) {  // the log has them
      spdlog::error("keeping {} events in the database: {}", batch.size(), e.what());
    }
  }
}

std::vector<Event> Coordinator::events(const std::string& job, uint64_t after, size_t limit, bool newest) const {
  return store_->events(job, after, limit, newest);
}

void Coordinator::write(const std::shared_ptr<Job>& job) {
  for (;;) {  // this thread is the job's one writer until next() finds nothing more due
    SnapshotPlan plan;
    {
      MutexLock lock(mu_);
      plan = snapshotter_.next(*job, clock_->now());
    }
    if (!plan.image && !plan.checkpoint) return changed_.notify_all();  // no writer now: a delete may wait
    const SnapshotOutcome out = writer_.write(
        *job, plan,
        [&](uint32_t band, BandCopy* copy) {
          MutexLock lock(mu_);                                      // one band at a time: merges go on between them
          if (!job->plan.has_film() || job->removed) return false;  // (a job being deleted: stop)
          job->plan.copy_band(band, copy);
          if (plan.image) job->splats.copy_band(copy);  // (a checkpoint's splats: after the bands)
          return true;
        },
        [&](const std::function<void()>& step) {
          MutexLock lock(mu_);
          step();
        });
    bool left;
    {
      MutexLock lock(mu_);
      snapshotter_.written(*job, plan, out, counters_);
      left = jobs_.let_go(*job);  // a DONE frame whole on disk leaves memory: nothing more is due
    }
    changed_.notify_all();  // an image fetch may wait for this write; an end may be durable now
    if (out.end_recorded && !job->sequence.empty()) record_sequence_end(job->sequence);
    if (left) return;
  }
}

void Coordinator::record_sequence_end(const std::string& id) {
  std::optional<RowEnd> row;
  std::string scene;
  {
    MutexLock lock(mu_);
    if (!(row = lifecycle_.sequence_end_due(id))) return;
    scene = jobs_.find_sequence(id)->meta.scene_hash;
  }
  const bool ok = writer_.record_end(*row, scene);
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    lifecycle_.sequence_end_recorded(id, ok);
    fx.changed = true;
  });
}

void Coordinator::archive(const Archival& a) {
  std::lock_guard<std::mutex> counts(archive_counts_mu_);  // (job_counts: once, not twice)
  bool archived = false;
  try {
    archived = store_->archive(a.id, a.summary, a.merged);
    if (archived)
      for (const std::string& id : a.done_checkpoints) store_->discard_checkpoint(id);
  } catch (const std::exception& e) {  // it stays in memory; the next tick tries again
    spdlog::warn("job {}: archiving: {}", a.id, e.what());
  }
  MutexLock lock(mu_);
  archive_.done(a, archived);
}

bool Coordinator::begin_archived(const std::string& id) {
  MutexLock lock(mu_);
  if (jobs_.knows(id)) return false;  // a requeue brought it back meanwhile
  control_.begin_archived(id);
  return true;
}

// ---- clients ----

void Coordinator::refused() {
  MutexLock lock(mu_);
  ++counters_.jobs_refused;
}

// A request's place in the limits while it works outside the lock (JobTable::reserve),
// given back however the request ends; an added job counts itself.
struct Coordinator::Reserved {
  Coordinator& c;
  uint64_t token = 0;
  ~Reserved() {
    if (!token) return;
    MutexLock lock(c.mu_);
    c.jobs_.release(token);
  }
};

std::string Coordinator::submit(const v1::SubmitJobRequest& req, const std::string& owner) {
  Submission sub;
  Reserved reserved{*this};
  try {
    Admission a = admit(req);
    if (!req.upload_id().empty()) a.scene_bytes = uploads_.bytes(req.upload_id(), owner);
    JobMeta meta;
    meta.owner = owner;
    {
      MutexLock lock(mu_);
      const std::string over = over_limit(a, jobs_.load(owner), options_, owner);
      if (!over.empty()) throw RequestError(RequestError::Code::kResourceExhausted, over);
      meta.id = jobs_.new_id();
      meta.seq = jobs_.next_seq();
      // Submits racing this one see it while its scene is checked: they cannot pass the
      // limits together (32 parallel submits under a limit of 2 were all accepted).
      // (An upload's bytes count as the upload's until the job takes it: not twice.)
      reserved.token = jobs_.reserve(owner, a.pixels, a.samples, req.upload_id().empty() ? a.scene_bytes : 0);
    }
    sub = prepare_submission(req, a, std::move(meta), scenes_, *store_, options_.data_dir, &uploads_);
  } catch (const RequestError&) {
    refused();
    throw;
  }
  const std::string id = sub.job ? sub.job->id() : sub.sequence->id();
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    jobs_.release(std::exchange(reserved.token, 0));  // the job counts itself from here
    const double now = clock_->now();
    ++counters_.jobs_submitted;
    fx.actor = owner;
    fx.event("job.submitted", id, "", submitted_detail(req));
    fx.changed = true;
    if (sub.sequence) {
      sub.sequence->submitted = now;
      jobs_.add(std::move(sub.sequence));
      return;
    }
    sub.job->submitted = sub.job->snaps.last_checkpoint = now;
    lifecycle_.finish_if_done(jobs_.add(sub.job), now, fx);  // nothing to render: its end is written at once
  });
  return id;
}

v1::SceneUpload Coordinator::upload_scene(const std::function<bool(v1::SceneChunk*)>& next, const std::string& owner) {
  uint64_t in_jobs;
  {
    MutexLock lock(mu_);
    in_jobs = jobs_.load(owner).client_scene_bytes;
  }
  return uploads_.receive(owner, next, in_jobs, options_.max_scene_bytes_per_client);  // the disk, without mu_
}

v1::JobStatus Coordinator::cancel(const std::string& id, const std::string& requester, bool any) {
  if (!archived_change(id, requester, any, "cancel"))  // (an archived job has ended: nothing to cancel)
    locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
      fx.actor = requester;
      lifecycle_.cancel(id, requester, any, clock_->now(), fx);
    });
  return status(id, false);
}

v1::JobStatus Coordinator::set_priority(const std::string& id, int32_t priority, const std::string& requester,
                                        bool any) {
  if (!archived_change(id, requester, any, "change the priority of"))
    locked([&](Effects&) TESSERA_REQUIRES(mu_) { jobs_.check_change(id, requester, any, "change the priority of"); });
  with_store([&] { store_->set_priority(id, priority); });  // the row first: a restart keeps it
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    fx.actor = requester;
    control_.set_priority(id, priority, fx);
  });
  return status(id, false);
}

v1::JobStatus Coordinator::requeue(const std::string& id, const std::string& requester, bool any) {
  std::optional<Recovery::Ended> back;  // an archived job, brought back into memory first
  const std::optional<StoredJob> row = archived_change(id, requester, any, "requeue");
  if (row) JobControl::refuse_requeue(id, row->state, true);  // (a DONE job's checkpoint is gone)
  if (row && begin_archived(id))
    back = undo_on_throw(
        [&] {
          if (!store_->job(id)) throw RequestError(RequestError::Code::kNotFound, "no job '" + id + "'");
          return Recovery::load_ended(*row, *store_, clock_->now());
        },
        [&](Effects&) TESSERA_REQUIRES(mu_) { control_.end_archived(id); });
  Reserved reserved{*this};
  JobControl::Requeue q = locked([&](Effects&) TESSERA_REQUIRES(mu_) {
    if (back) {
      control_.end_archived(id);
      if (!jobs_.knows(id)) Recovery::adopt(jobs_, *back);
    }
    JobControl::Requeue r = control_.begin_requeue(id, requester, any);
    // Bounded as a submit is, by its owner's limits: requeues of ended jobs made live jobs
    // and films without limit (and a restart restored them all).
    std::string owner;
    const Admission a = JobControl::requeue_admission(r, &owner);
    const std::string over = over_limit(a, jobs_.load(owner), options_, owner);
    if (!over.empty()) {
      control_.requeue_failed(r);
      throw RequestError(RequestError::Code::kResourceExhausted, over);
    }
    reserved.token = jobs_.reserve(owner, a.pixels, a.samples, a.scene_bytes);
    await([&] { return JobControl::quiet(r); });  // (an ended job's writers are done, or nearly)
    return r;
  });
  undo_on_throw([&] { load_requeue(q, *store_, scenes_, options_.data_dir); },  // the scene, the row, the films
                [&](Effects&) TESSERA_REQUIRES(mu_) { control_.requeue_failed(q); });
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    jobs_.release(std::exchange(reserved.token, 0));  // the jobs count themselves from here
    fx.actor = requester;
    control_.finish_requeue(q, clock_->now(), fx);
  });
  return status(id, false);
}

uint64_t Coordinator::remove(const std::string& id, const std::string& requester, bool any) {
  if (const std::optional<StoredJob> row = archived_change(id, requester, any, "delete"); row && begin_archived(id)) {
    const JobControl::Removal r = JobControl::archived_removal(*row);  // only its row and files
    const uint64_t bytes =
        undo_on_throw([&] { return finish_removal(r, false, *store_, *sink_, scenes_, options_.data_dir); },
                      [&](Effects&) TESSERA_REQUIRES(mu_) { control_.end_archived(id); });
    locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
      fx.actor = requester;
      control_.end_archived(id);
      control_.removed(r, fx);
    });
    return bytes;
  }
  bool holds_scene = false;
  const JobControl::Removal r = locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    fx.actor = requester;  // (a live job is cancelled first)
    JobControl::Removal r = control_.begin_delete(id, requester, any, clock_->now(), fx);
    await([&] { return JobControl::quiet(r); });  // a writer stops at its next band
    holds_scene = JobControl::holds_scene(r);
    return r;
  });
  const uint64_t bytes =
      undo_on_throw([&] { return finish_removal(r, holds_scene, *store_, *sink_, scenes_, options_.data_dir); },
                    [&](Effects& fx) TESSERA_REQUIRES(mu_) { control_.delete_failed(r, clock_->now(), fx); });
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    fx.actor = requester;
    control_.removed(r, fx);
  });
  return bytes;
}

// ---- workers ----

v1::RegisterResponse Coordinator::register_worker(const v1::RegisterRequest& request, const std::string& principal,
                                                  bool enrolled) {
  return locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    fx.actor = principal;
    return worker_lifecycle_.register_worker(request, principal, enrolled, clock_->now(), fx);
  });
}

void Coordinator::check_worker(uint64_t worker_id, const std::string& secret) const {
  MutexLock lock(mu_);
  worker_lifecycle_.check_worker(worker_id, secret);
}

v1::GetTaskResponse Coordinator::get_task(uint64_t worker_id, uint32_t max_tasks, uint64_t max_samples,
                                          uint32_t max_passes) {
  return locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    return dispatcher_.get_task(worker_id, max_tasks, max_samples, clock_->now(), fx, max_passes);
  });
}

v1::SceneManifest Coordinator::scene(const std::string& hash) const { return served_manifest(scenes_, hash); }

void Coordinator::scene_chunks(const v1::FetchSceneRequest& req,
                               const std::function<bool(const v1::SceneChunk&)>& write) const {
  serve_scene(scenes_, req, options_.scene_chunk_bytes, write);
}

std::vector<uint64_t> Coordinator::heartbeat(uint64_t worker_id, const std::vector<uint64_t>& task_ids,
                                             double round_trip) {
  // A worker holds at most --max-leases-per-worker; twice that leaves room for leases that
  // ended while it still worked on them. Checked before the lock: each id is a lookup.
  const uint64_t most = 2 * uint64_t(options_.max_leases_per_worker);
  if (task_ids.size() > most)
    throw RequestError(RequestError::Code::kInvalidArgument, "heartbeat: " + std::to_string(task_ids.size()) +
                                                                 " tasks listed; at most " + std::to_string(most) +
                                                                 " (twice --max-leases-per-worker)");
  MutexLock lock(mu_);
  return worker_lifecycle_.heartbeat(worker_id, task_ids, round_trip, clock_->now());
}

std::vector<v1::ResultAck> Coordinator::submit_results(const std::vector<const v1::TaskResult*>& results) {
  ResultIntake::Batch batch;
  {
    MutexLock lock(mu_);
    batch = intake_.screen(results);
  }
  // A slice at a time (bounded decoded bytes: ResultIntake::kDecodedBytesPerSlice), each
  // decoded outside the lock (the slow part), merged under it, then freed.
  for (size_t first = 0, last; first < batch.incoming.size(); first = last) {
    last = ResultIntake::slice_end(batch, first);
    ResultIntake::decode(batch, first, last);
    locked([&](Effects& fx) TESSERA_REQUIRES(mu_) { intake_.merge(batch, first, last, clock_->now(), fx); });
    ResultIntake::free_decoded(batch, first, last);
  }
  for (const auto& [i, lease] : batch.checks) batch.acks[i] = check_result(*results[i], lease);
  return std::move(batch.acks);
}

v1::ResultAck Coordinator::check_result(const v1::TaskResult& result, const Lease& lease) {
  v1::ResultAck ack;
  const std::optional<Check> check =
      locked([&](Effects&) TESSERA_REQUIRES(mu_) { return verifier_.pending(lease.check, result.task_id()); });
  if (!check) return ack;  // decided, or moot
  std::string why;
  const std::optional<uint64_t> digest = result_digest(result, *check, &why);
  if (!digest) {  // its lease stays: it expires, and the check goes to another worker
    locked([&](Effects&) TESSERA_REQUIRES(mu_) { ++counters_.results_rejected; });
    ack.set_refused(ResultIntake::refusal(why));
    spdlog::warn("check of job {} tile {} from worker {}: {}", check->job, check->tile, result.worker_id(),
                 ack.refused());
    return ack;
  }
  const Verifier::Verdict verdict = Verifier::judge(*check, *digest, result.worker_id(), referee_);
  ack.set_accepted(locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    return verifier_.decide(lease.check, result.task_id(), result.worker_id(), verdict, clock_->now(), fx);
  }));
  return ack;
}

void Coordinator::release(uint64_t worker_id, uint64_t task_id, const std::string& error) {
  locked([&](Effects& fx)
             TESSERA_REQUIRES(mu_) { worker_lifecycle_.release(worker_id, task_id, error, clock_->now(), fx); });
}

void Coordinator::drain_worker(uint64_t worker_id, bool drain, const std::string& requester) {
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    WorkerInfo* w = workers_.find(worker_id);
    if (!w) throw RequestError(RequestError::Code::kNotFound, "no worker " + std::to_string(worker_id));
    if (w->draining == drain) return;
    w->draining = drain;
    fx.actor = requester;
    fx.event(drain ? "worker.drained" : "worker.resumed", "", w->name, "");
    fx.changed = true;
  });
}

void Coordinator::unregister(uint64_t worker_id) {
  locked([&](Effects& fx) TESSERA_REQUIRES(mu_) { worker_lifecycle_.unregister(worker_id, clock_->now(), fx); });
}

size_t Coordinator::expire_leases() {
  if (const double now = clock_->now(); now - credentials_swept_ >= 60) {  // credentials unused for an hour go
    credentials_swept_ = now;
    credentials_.expire();
    uploads_.drop_expired();  // and uploads nobody submitted (off the disk: not under mu_)
  }
  return locked([&](Effects& fx) TESSERA_REQUIRES(mu_) {
    const double now = clock_->now();
    worker_lifecycle_.forget_silent(now, fx);  // here, on the reaper's tick, not in every GetTask
    const size_t expired = leasing_.expire(now);
    const size_t overrun = worker_lifecycle_.end_overrun(now, fx);
    fx.changed = fx.changed || expired > 0 || overrun > 0;  // (forget_silent may have set it)
    verifier_.skip_stale(now, fx);
    fx.prepare = sequences_.to_prepare(options_.max_live_pixels);  // made off every worker's path
    fx.archive = archive_.due(now);                                // ended jobs whole on disk leave memory
    return expired;
  });
}

void Coordinator::checkpoint_all() {
  std::vector<std::shared_ptr<Job>> mine, others;  // others: a writer is at work on them
  {
    MutexLock lock(mu_);
    for (const auto& [id, job] : jobs_.jobs())
      if (job->live() && job->plan.merges() != job->snaps.checkpoint_merges)
        (snapshotter_.checkpoint_if_changed(*job, clock_->now()) ? mine : others).push_back(job);
  }
  for (const std::shared_ptr<Job>& job : mine) write(job);
  MutexLock lock(mu_);  // the writers of the others take the checkpoint too
  await([&] { return none_writing(others); });
}

// ---- waiting ----

void Coordinator::wait_for_work(double timeout) const {
  MutexLock lock(mu_);
  changed_.wait_until(mu_, deadline_in(timeout));  // the first change: GetTask looks again
}

// ---- for operators ----

std::string Coordinator::unready_reason() const {
  try {
    store_->ping();
  } catch (const std::exception& e) {
    return without_dir(e.what(), options_.data_dir);
  }
  return "";
}

}  // namespace tessera
