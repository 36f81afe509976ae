#include "server/snapshotter.h"

#include <chrono>

#include "core/util/log.h"

namespace tessera {

std::string without_dir(std::string message, const std::string& dir) {
  for (size_t at; !dir.empty() && (at = message.find(dir)) != std::string::npos;) message.replace(at, dir.size(), "<data>");
  return message;
}

ImageSnapshot Snapshotter::take(const std::shared_ptr<Job>& job, bool image, bool checkpoint, double now) const {
  ImageSnapshot snap;
  snap.job = job;
  Job& j = *job;
  if (!j.plan.has_film()) return snap;  // ended, written, released: nothing to write
  std::unique_ptr<Film> film = std::move(j.snaps.spare_film);
  if (film)
    *film = j.plan.film();  // into the mapped pages of the last snapshot
  else
    film = std::make_unique<Film>(j.plan.film());
  snap.film = std::move(film);
  snap.seq = ++j.snaps.taken;
  snap.merges = j.plan.merges();
  snap.image = image;
  snap.checkpoint = checkpoint;
  if (checkpoint) {
    snap.plan = j.plan.state();
    j.snaps.checkpoint_merges = snap.merges;
  }
  snap.elapsed = j.started > 0 ? (j.live() ? now : j.finished_at) - j.started : 0;
  snap.ended = !j.live();
  snap.state = j.state();
  snap.error = j.error;
  const RenderSettings& s = j.plan.settings();
  snap.meta = {{"job", j.id()},
               {"scene", j.meta.name},
               {"seed", std::to_string(s.seed)},
               {"frame_passes", std::to_string(j.plan.frame_passes_done())}};
  if (j.started > 0) snap.meta["render_seconds"] = std::to_string(snap.elapsed);
  if (s.frame) {
    snap.meta["frame"] = std::to_string(*s.frame);
    snap.meta["time"] = std::to_string(s.time());  // seconds: frame / fps
  }
  return snap;
}

std::optional<ImageSnapshot> Snapshotter::after_merge(const std::shared_ptr<Job>& job, double now) const {
  Job& j = *job;
  const uint32_t frame = j.plan.frame_passes_done();
  const double image_interval = std::max(image_interval_, kWriteShare * j.snaps.image_write_seconds);
  const double checkpoint_interval = std::max(checkpoint_interval_, kWriteShare * j.snaps.checkpoint_write_seconds);
  const bool image = frame > j.snaps.image_frame_passes && now - j.snaps.last_image >= image_interval;
  const bool checkpoint = now - j.snaps.last_checkpoint >= checkpoint_interval;
  if (!image && !checkpoint) return std::nullopt;
  if (image) {
    j.snaps.image_frame_passes = frame;
    j.snaps.last_image = now;
  }
  if (checkpoint) j.snaps.last_checkpoint = now;
  return take(job, image, checkpoint, now);
}

ImageSnapshot Snapshotter::final_snapshot(const std::shared_ptr<Job>& job, double now) const {
  job->snaps.image_frame_passes = job->plan.frame_passes_done();
  job->snaps.last_image = job->snaps.last_checkpoint = now;
  return take(job, true, true, now);
}

std::optional<ImageSnapshot> Snapshotter::checkpoint_if_changed(const std::shared_ptr<Job>& job, double now) const {
  if (!job->live() || job->plan.merges() == job->snaps.checkpoint_merges) return std::nullopt;
  job->snaps.last_checkpoint = now;
  return take(job, false, true, now);
}

void Snapshotter::written(ImageSnapshot& snap, const SnapshotOutcome& out, CoordinatorCounters& counters) const {
  if (!snap.film) return;
  Job& job = *snap.job;
  using R = SnapshotOutcome::Result;
  if (out.image == R::kWritten) job.snaps.image_write_seconds = out.image_seconds;
  if (out.checkpoint == R::kWritten) job.snaps.checkpoint_write_seconds = out.checkpoint_seconds;
  counters.images_written += out.image == R::kWritten;
  counters.image_errors += out.image == R::kFailed;
  counters.checkpoints_written += out.checkpoint == R::kWritten;
  counters.checkpoint_errors += out.checkpoint == R::kFailed;
  if (out.image == R::kWritten) job.image_error.clear();
  if (out.image == R::kFailed) job.image_error = out.image_why;
  if (out.checkpoint == R::kWritten) job.checkpoint_error.clear();
  if (out.checkpoint == R::kFailed) job.checkpoint_error = out.checkpoint_why;
  if (job.live())
    job.snaps.spare_film = std::move(snap.film);  // for the next snapshot
  else if (out.release_film)
    job.plan.release_film();  // the image and checkpoint on disk hold it all
}

SnapshotOutcome SnapshotWriter::write(ImageSnapshot& snap) const {
  SnapshotOutcome out;
  if (!snap.film) return out;
  if (hooks_.before_image_write) hooks_.before_image_write();
  Job& job = *snap.job;
  auto attempt = [&](const char* what, double* seconds, std::string* why, auto&& write) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      write();
      *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      return SnapshotOutcome::kWritten;
    } catch (const std::exception& e) {
      spdlog::warn("job {}: {}: {} (kept in memory; retried)", job.id(), what, e.what());
      *why = without_dir(e.what(), hooks_.data_dir);
      return SnapshotOutcome::kFailed;
    }
  };
  MutexLock wl(job.write_mu);
  Job::Written& w = job.written;
  if (snap.image && snap.seq > w.image_seq) {
    out.image = attempt("image", &out.image_seconds, &out.image_why, [&] { sink_.write(job.id(), *snap.film, snap.meta); });
    if (out.image == SnapshotOutcome::kWritten) {
      w.image_seq = snap.seq;
      w.image_merges = snap.merges;
    }
  }
  if (snap.checkpoint && snap.seq > w.checkpoint_seq) {
    out.checkpoint = attempt("checkpoint", &out.checkpoint_seconds, &out.checkpoint_why,
                             [&] { store_.write_checkpoint(job.id(), snap.plan, *snap.film, snap.elapsed); });
    if (out.checkpoint == SnapshotOutcome::kWritten) {
      w.checkpoint_seq = snap.seq;
      w.checkpoint_merges = snap.merges;
    }
  }
  // A DONE job's end is recorded once the checkpoint with its whole film is on disk, so
  // that a restart never finds a DONE job with part of a film. A cancelled or failed job's
  // end is recorded at once: nothing more will be rendered for it either way.
  const bool whole = w.checkpoint_merges == snap.merges;
  if (snap.ended && !job.end_recorded && (whole || snap.state != v1::JobStatus::DONE)) {
    try {
      if (job.sequence.empty()) {  // (a frame has no row; its sequence holds the scene)
        store_.end(job.id(), snap.state, snap.error, snap.elapsed);
        if (hooks_.release_scene) hooks_.release_scene(job.meta.scene_hash);
      }
      job.end_recorded = true;
    } catch (const std::exception& e) {
      spdlog::error("job {}: recording its end: {}", job.id(), e.what());
    }
  }
  out.release_film = snap.ended && job.end_recorded && whole && w.image_merges == snap.merges;
  return out;
}

namespace {
bool current_locked(const Job& job, bool live, uint64_t merges) TESSERA_REQUIRES(job.write_mu) {
  return job.written.image_seq > 0 && (live || job.written.image_merges == merges);
}
}  // namespace

bool SnapshotWriter::image_current(Job& job, bool live, uint64_t merges) {
  MutexLock wl(job.write_mu);
  return current_locked(job, live, merges);
}

bool SnapshotWriter::read_image(Job& job, bool live, uint64_t merges, bool exr, bool png, v1::Image* out) const {
  MutexLock wl(job.write_mu);  // no write replaces the files meanwhile
  if (!current_locked(job, live, merges)) return false;
  if (exr) out->set_exr(sink_.exr(job.id()));
  if (png) out->set_png(sink_.png(job.id()));
  return true;
}

}  // namespace tessera
