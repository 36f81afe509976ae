#include "server/job.h"

namespace tessera {

v1::JobStatus Job::status(double now, uint32_t workers, bool with_tiles) const {
  v1::JobStatus s;
  s.set_id(id);
  s.set_name(name);
  s.set_state(state);
  // A job whose image cannot be written still renders (the film is in memory and writes
  // are retried with the next snapshot); the user is told why its image is missing.
  std::string e = error;
  auto add = [&](const char* what, const std::string& why) {
    if (!why.empty()) e += (e.empty() ? "" : "; ") + std::string(what) + why;
  };
  add("image not written: ", image_error);
  add("checkpoint not written: ", checkpoint_error);
  s.set_error(e);
  s.set_samples_done(plan.samples_merged());
  s.set_samples_total(plan.samples_total());
  s.set_tiles_done(plan.tiles_done());
  s.set_tiles_total(uint32_t(plan.tiles().size()));
  s.set_passes_total(uint32_t(plan.passes().size()));
  s.set_frame_passes_done(plan.frame_passes_done());
  s.set_priority(priority);
  const double elapsed = started > 0 ? (live() ? now : finished_at) - started : 0;
  s.set_elapsed_seconds(elapsed);
  s.set_owner(owner);
  const double f = plan.fraction_done();
  if (live() && f > 0) s.set_eta_seconds(elapsed * (1 - f) / f);
  s.set_active_workers(workers);
  *s.mutable_settings() = settings_proto;
  if (with_tiles)
    for (uint32_t i = 0; i < plan.tiles().size(); ++i) {
      const TileProgress& p = plan.progress(i);
      v1::TileProgress* t = s.add_tiles();
      *t->mutable_rect() = to_proto(plan.tiles()[i]);
      t->set_passes_done(p.passes_done);
      t->set_samples(p.passes_done ? plan.passes()[p.passes_done - 1].second : 0);
      t->set_relative_error(p.relative_error);
      t->set_finished(p.finished);
    }
  return s;
}

}  // namespace tessera
