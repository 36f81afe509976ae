#include "core/render/film.h"

namespace tessera {

void Film::add_tile(const Rect& rect, const std::vector<PixelSums>& sums) {
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x)
      at(rect.x - window_.x + x, rect.y - window_.y + y).add(sums[size_t(y) * rect.w + x]);
}

Rgb Film::mean_radiance() const {
  double r = 0, g = 0, b = 0;
  for (const PixelSums& p : pixels_) {
    const Rgb m = p.mean();
    r += m.r;
    g += m.g;
    b += m.b;
  }
  const double n = double(pixels_.size());
  return n ? Rgb(float(r / n), float(g / n), float(b / n)) : Rgb(0);
}

}  // namespace tessera

namespace tessera {

double Film::mean_luminance() const {
  double sum = 0;
  for (const PixelSums& p : pixels_) sum += p.n ? p.lum_sum() / p.n : 0;
  return pixels_.empty() ? 0 : sum / double(pixels_.size());
}

}  // namespace tessera
