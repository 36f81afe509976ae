// Renders a whole frame in this process: passes in order, tiles of a pass in parallel.
#pragma once

#include <functional>

#include "core/render/film.h"
#include "core/render/tile_renderer.h"

namespace tessera {

struct RenderProgress {
  int pass = 0, passes = 0;
  double fraction = 0;  // of the work scheduled (adaptive sampling may end early)
  uint64_t samples = 0;
  double seconds = 0;
};
using ProgressCallback = std::function<void(const RenderProgress&)>;

struct RenderResult {
  Film film;
  TileStats stats;
  double seconds = 0;
};

// threads <= 0 uses every core. The callback runs on the calling thread.
RenderResult render_image(const TileRenderer& renderer, int threads, int tile_size,
                          const ProgressCallback& progress = nullptr);

// CS184 adaptive stopping (format doc 7.1, dividing by the true count): a pixel stops when
// the 95% confidence half-width of its luminance is within tolerance x mean.
bool pixel_converged(const PixelSums& p, float tolerance);

}  // namespace tessera
