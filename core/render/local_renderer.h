// `tessera render`: a frame plan and a thread pool in this process. Each render thread
// takes a ready task from the plan, renders it, and merges it; there is no barrier between
// passes (a tile's next pass is ready as soon as its last one is merged).
#pragma once

#include <functional>

#include "core/render/film.h"
#include "core/render/frame_plan.h"
#include "core/render/tile_renderer.h"

namespace tessera {

struct RenderProgress {
  uint32_t frame_passes = 0, passes = 0;  // passes complete over the whole frame, of
  double fraction = 0;                    // of the work scheduled (adaptive sampling may end early)
  uint64_t samples = 0;
  double seconds = 0;
};
using ProgressCallback = std::function<void(const RenderProgress&)>;

struct RenderResult {
  Film film{Rect{}};
  AovFilm aovs;  // empty unless the settings ask for AOVs
  TileStats stats;
  double seconds = 0;
  // Light tracing (light_tracer.h): whether it ran and why; the light paths traced and the
  // splats dropped (over SplatSink::kMaxSplatValue or not finite). With it, `film` holds the
  // splats folded in (SplatFilm::fold_into).
  LightTracingDecision light_tracing;
  uint64_t light_paths = 0, dropped_splats = 0;
};

// threads <= 0 uses every core. The callback runs on the calling thread, about every
// quarter second and once at the end.
RenderResult render_image(const TileRenderer& renderer, int threads, const ProgressCallback& progress = nullptr);

}  // namespace tessera
