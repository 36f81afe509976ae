#include "core/render/film.h"

namespace tessera {

void Film::add_tile(const Rect& rect, const std::vector<PixelSums>& sums) {
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x)
      at(rect.x - window_.x + x, rect.y - window_.y + y).add(sums[size_t(y) * rect.w + x]);
}

}  // namespace tessera

namespace tessera {

double Film::mean_luminance() const {
  double sum = 0;
  for (const PixelSums& p : pixels_) sum += p.n ? p.lum_sum() / p.n : 0;
  return pixels_.empty() ? 0 : sum / double(pixels_.size());
}

}  // namespace tessera
