#include "worker/render_pool.h"

#include "worker/clock.h"

namespace tessera::worker {

RenderPool::RenderPool(TaskQueue& queue, int threads) : queue_(queue), pool_(threads) {
  for (int i = 0; i < pool_.size(); ++i) pool_.run([this] { render_loop(); });
}

void RenderPool::render_loop() {
  while (const std::optional<TaskQueue::Row> r = queue_.next_row()) {
    const Held& h = *r->task;
    const double t0 = now_seconds();
    TileStats stats;
    const Rect rect{h.rect.x, h.rect.y + r->row, h.rect.w, 1};
    std::vector<AovSums> aovs;
    std::vector<SplatRecord> splats;
    // The row's part of a run's base: of each plane of the tile's sums (film.h).
    std::vector<PixelSums> base;
    const size_t w = size_t(h.rect.w), area = size_t(h.rect.area()), at = size_t(r->row) * w;
    for (size_t plane = 0; plane < h.base.size() / area; ++plane)
      base.insert(base.end(), h.base.begin() + ptrdiff_t(plane * area + at),
                  h.base.begin() + ptrdiff_t(plane * area + at + w));
    const std::vector<PixelSums> sums = h.prepared->renderer->render_passes(
        rect, h.passes, base.empty() ? nullptr : base.data(), h.mask ? h.mask + size_t(r->row) * h.rect.w : nullptr,
        &stats, &h.cancel, h.aovs.empty() ? nullptr : &aovs, h.splats.empty() ? nullptr : &splats);
    queue_.row_done(*r, sums, stats, t0, now_seconds(), h.aovs.empty() ? nullptr : &aovs,
                    h.splats.empty() ? nullptr : &splats);
  }
}

}  // namespace tessera::worker
