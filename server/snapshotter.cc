#include "server/snapshotter.h"

#include <fmt/format.h>

#include <chrono>

#include "core/render/aov.h"
#include "core/util/log.h"
#include "server/checkpoint.h"

namespace tessera {

std::string without_dir(std::string message, const std::string& dir) {
  for (size_t at; !dir.empty() && (at = message.find(dir)) != std::string::npos;)
    message.replace(at, dir.size(), "<data>");
  return message;
}

bool Snapshotter::request(Job& job, bool image, bool checkpoint) const {
  if (job.removed) return false;  // being deleted: nothing more of it is written
  job.snaps.image_due |= image;
  job.snaps.checkpoint_due |= checkpoint;
  if (job.snaps.writing) return false;
  job.snaps.writing = true;
  return true;
}

bool Snapshotter::after_merge(Job& j, double now) const {
  const uint32_t frame = j.plan.frame_passes_done();
  const double stretch = kWriteShare * j.snaps.write_seconds;
  const bool image =
      frame > j.snaps.image_frame_passes && now - j.snaps.last_image >= std::max(image_interval_, stretch);
  const bool checkpoint = now - j.snaps.last_checkpoint >= std::max(checkpoint_interval_, stretch);
  if (!image && !checkpoint) return false;
  if (image) {
    j.snaps.image_frame_passes = frame;
    j.snaps.last_image = now;
  }
  if (checkpoint) j.snaps.last_checkpoint = now;
  return request(j, image, checkpoint);
}

bool Snapshotter::final_snapshot(Job& job, double now) const {
  job.snaps.image_frame_passes = job.plan.frame_passes_done();
  job.snaps.last_image = job.snaps.last_checkpoint = now;
  return request(job, true, true);
}

bool Snapshotter::checkpoint_if_changed(Job& job, double now) const {
  if (!job.live() || job.plan.merges() == job.snaps.checkpoint_merges) return false;
  job.snaps.last_checkpoint = now;
  return request(job, false, true);
}

SnapshotPlan Snapshotter::next(Job& j, double now) const {
  SnapshotPlan p;
  Job::Snapshots& s = j.snaps;
  if (j.removed || !j.plan.has_film() || (!s.image_due && !s.checkpoint_due)) {  // nothing (more) to write
    s.image_due = s.checkpoint_due = s.writing = false;
    return p;
  }
  p.image = s.image_due;
  p.checkpoint = s.checkpoint_due;
  s.image_due = s.checkpoint_due = false;
  p.ended = !j.live();
  p.merges = j.plan.merges();
  p.resets = j.resets;
  p.checkpoint_on_disk = j.written.checkpoints > 0 && j.written.checkpoint_merges == p.merges;
  if (p.checkpoint) s.checkpoint_merges = p.merges;
  p.elapsed = j.started > 0 ? (j.live() ? now : j.finished_at) - j.started : 0;
  p.state = j.state();
  p.error = j.error;
  const RenderSettings& st = j.plan.settings();
  p.meta = {{"job", j.id()},
            {"scene", j.meta.name},
            {"seed", std::to_string(st.seed)},
            {"frame_passes", std::to_string(j.plan.frame_passes_done())}};
  if (j.started > 0) p.meta["render_seconds"] = std::to_string(p.elapsed);
  if (st.frame) {
    p.meta["frame"] = std::to_string(*st.frame);
    p.meta["time"] = fmt::format("{}", st.time());  // seconds: frame / fps, shortest exact
  }
  if (st.exposure != 0) p.meta[kExposureAttribute] = exposure_text(st.exposure);  // (PNGs made of it take it)
  if (st.aovs) p.meta["aovs"] = aov_names(st.aovs);                               // (as tessera render's)
  // The image of an ended DONE job (denoised where asked): a restart leaves it be
  // (Recovery::Parts::image_passes). An image with every pass merged can be written before
  // (the job waits on its checks), not denoised.
  if (p.ended && p.state == v1::JobStatus::DONE) p.meta["final"] = "1";
  return p;
}

bool Snapshotter::image_current(const Job& job, bool live, uint64_t merges) {
  return job.written.images > 0 && (live || job.written.image_merges == merges);
}

void Snapshotter::written(Job& job, const SnapshotPlan& plan, const SnapshotOutcome& out,
                          CoordinatorCounters& counters) const {
  using R = SnapshotOutcome::Result;
  Job::Written& w = job.written;
  if (out.image == R::kWritten) {
    ++w.images;
    w.image_merges = plan.merges;
    job.image_error.clear();
  }
  if (out.checkpoint == R::kWritten) {
    ++w.checkpoints;
    w.checkpoint_merges = plan.merges;
    job.checkpoint_error.clear();
  }
  if (out.image == R::kFailed) job.image_error = out.image_why;
  if (out.checkpoint == R::kFailed) job.checkpoint_error = out.checkpoint_why;
  if (out.image == R::kWritten || out.checkpoint == R::kWritten) job.snaps.write_seconds = out.seconds;
  counters.images_written += out.image == R::kWritten;
  counters.image_errors += out.image == R::kFailed;
  counters.checkpoints_written += out.checkpoint == R::kWritten;
  counters.checkpoint_errors += out.checkpoint == R::kFailed;
  // The image and checkpoint on disk hold an ended job's whole film: memory lets it go.
  if (plan.ended && job.end_recorded && w.images && w.image_merges == plan.merges && w.checkpoints &&
      w.checkpoint_merges == plan.merges)
    job.compact();
}

bool SnapshotWriter::record_end(const RowEnd& row, const std::string& scene_hash) const {
  try {
    store_.end(row.id, row.state, row.error, row.elapsed);
  } catch (const std::exception& e) {
    spdlog::error("job {}: recording its end: {}", row.id, e.what());
    return false;
  }
  if (hooks_.release_scene) hooks_.release_scene(scene_hash);
  return true;
}

bool SnapshotWriter::write_splats(Job& job, const SnapshotPlan& plan, CheckpointEncoder& encoder,
                                  const std::function<void(const std::function<void()>&)>& locked) const {
  std::optional<FrameSplats::Frozen> frozen;
  bool kept = true;
  locked([&] {
    // Results taken back since the write began, or a film gone (a job being deleted): the
    // checkpoint would not match the frame. A frame without splats has nothing to freeze.
    kept = job.resets == plan.resets && (!job.splats.any() || (job.plan.has_film() && !job.removed));
    if (kept && job.splats.any()) frozen = job.splats.freeze();
  });
  if (!frozen) return kept;
  // Whatever happens, the splats thaw (the records that came meanwhile are added).
  struct Thaw {
    const std::function<void(const std::function<void()>&)>& locked;
    Job& job;
    ~Thaw() {
      locked([this] { job.splats.thaw(); });
    }
  } thaw{locked, job};
  encoder.splats(*frozen);
  BandCopy band;
  for (uint32_t b = 0; b < job.plan.bands() && kept; ++b) {
    locked([&] {
      if (!(kept = job.plan.has_film() && !job.removed && job.resets == plan.resets)) return;
      job.plan.band_shape(b, &band);
      job.splats.copy_band(&band);
    });
    if (kept) encoder.splat_band(band);
  }
  return kept;
}

SnapshotOutcome SnapshotWriter::write(Job& job, const SnapshotPlan& plan,
                                      const std::function<bool(uint32_t, BandCopy*)>& copy_band,
                                      const std::function<void(const std::function<void()>&)>& locked) const {
  SnapshotOutcome out;
  if (!plan.image && !plan.checkpoint) return out;
  if (hooks_.before_image_write) hooks_.before_image_write();
  const auto t0 = std::chrono::steady_clock::now();
  auto failed = [&](const char* what, const std::exception& e, SnapshotOutcome::Result* r, std::string* why) {
    spdlog::warn("job {}: {}: {} (kept in memory; retried)", job.id(), what, e.what());
    *why = without_dir(e.what(), hooks_.data_dir);
    *r = SnapshotOutcome::kFailed;
  };
  // The plan's shape (settings, tiles, bands) never changes: read without the lock.
  const Rect w = job.plan.settings().effective_window();
  // A finished frame of a sequence: once its image is on disk its checkpoint need not hold
  // the film (nothing renders it again, and a restart reads only its progress), so it is
  // written after the image, in a pass of its own, and without the film where the image
  // was written. A sequence of 10,000 frames kept a film per frame on disk besides its
  // images (36 bytes a pixel before compression) until it was archived or deleted.
  const bool after_image =
      plan.image && plan.checkpoint && plan.ended && plan.state == v1::JobStatus::DONE && !job.sequence.empty();
  std::unique_ptr<ImageSink::Writer> image;
  std::unique_ptr<CheckpointFile> checkpoint;
  std::unique_ptr<CheckpointEncoder> encoder;
  if (plan.image) try {
      // A --denoise job's final image is denoised (its previews are not).
      const RenderSettings& s = job.plan.settings();
      image = sink_.begin(job.id(), w, s.image_rect(), plan.meta,
                          {s.aovs, s.denoise && plan.ended && plan.state == v1::JobStatus::DONE});
    } catch (const std::exception& e) {
      failed("image", e, &out.image, &out.image_why);
    }
  const auto begin_checkpoint = [&](bool film) {
    try {
      checkpoint = store_.begin_checkpoint(job.id());
      encoder = std::make_unique<CheckpointEncoder>(
          job.plan, plan.elapsed, [&](const std::string& bytes) { checkpoint->append(bytes); }, film);
    } catch (const std::exception& e) {
      checkpoint.reset();
      failed("checkpoint", e, &out.checkpoint, &out.checkpoint_why);
    }
  };
  // The bands: into the image and the checkpoint at once, or into one of them.
  BandCopy band;
  const auto bands = [&] {
    for (uint32_t b = 0; b < job.plan.bands() && (image || checkpoint); ++b) {
      if (!copy_band(b, &band)) return false;  // the film is gone: nothing to write
      if (checkpoint) try {                    // the film's sums as they are: the splats are written after the bands
          encoder->band(band);
        } catch (const std::exception& e) {
          checkpoint.reset();
          failed("checkpoint", e, &out.checkpoint, &out.checkpoint_why);
        }
      if (image) try {
          FrameSplats::fold(&band);  // the image's pixels hold the splats
          image->write_rows(band.pixels.data(), band.rows, band.aovs.empty() ? nullptr : band.aovs.data(),
                            band.odd.empty() ? nullptr : band.odd.data());
        } catch (const std::exception& e) {
          image.reset();
          failed("image", e, &out.image, &out.image_why);
        }
    }
    return true;
  };
  // A checkpoint with the film: the frame's splats, frozen after the bands (under `locked`).
  const auto checkpoint_splats = [&] {
    if (checkpoint && locked) try {
        if (!write_splats(job, plan, *encoder, locked))
          throw std::runtime_error("results were taken back from the film while it was written");
      } catch (const std::exception& e) {
        checkpoint.reset();
        failed("checkpoint", e, &out.checkpoint, &out.checkpoint_why);
      }
  };
  if (plan.checkpoint && !after_image) begin_checkpoint(true);
  if (!bands()) return SnapshotOutcome{};
  checkpoint_splats();
  if (image) try {
      image->commit();
      out.image = SnapshotOutcome::kWritten;
    } catch (const std::exception& e) {
      failed("image", e, &out.image, &out.image_why);
    }
  if (after_image) {
    // The film only where the image could not be written, or made durable (a restart
    // writes it from there): the checkpoint without it is.
    bool film = out.image != SnapshotOutcome::kWritten;
    if (!film) try {
        sink_.sync(job.id());
      } catch (const std::exception& e) {
        spdlog::warn("job {}: image: {} (its checkpoint keeps the film)", job.id(), e.what());
        film = true;
      }
    image.reset();
    begin_checkpoint(film);
    if (!bands()) return SnapshotOutcome{};
    if (film) checkpoint_splats();
  }
  if (checkpoint) try {
      encoder->finish();
      checkpoint->commit();
      out.checkpoint = SnapshotOutcome::kWritten;
    } catch (const std::exception& e) {
      failed("checkpoint", e, &out.checkpoint, &out.checkpoint_why);
    }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // A DONE job's end is recorded once a checkpoint holding its whole film is on disk (a
  // finished frame of a sequence: its progress, its final image made durable first), so
  // that a restart never finds a DONE job with part of a film. A cancelled or failed job's
  // end is recorded at once: nothing more will be rendered for it either way.
  const bool whole = out.checkpoint == SnapshotOutcome::kWritten || plan.checkpoint_on_disk;
  if (plan.ended && !job.end_recorded && (whole || plan.state != v1::JobStatus::DONE)) {
    try {
      if (job.sequence.empty()) {  // (a frame has no row; its sequence holds the scene)
        store_.end(job.id(), plan.state, plan.error, plan.elapsed);
        if (hooks_.release_scene) hooks_.release_scene(job.meta.scene_hash);
      }
      job.end_recorded = true;
      out.end_recorded = true;
    } catch (const std::exception& e) {
      spdlog::error("job {}: recording its end: {}", job.id(), e.what());
    }
  }
  return out;
}

}  // namespace tessera
