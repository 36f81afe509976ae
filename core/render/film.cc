#include "core/render/film.h"

#include <algorithm>

namespace tessera {

void Film::add_tile(const Rect& rect, const std::vector<PixelSums>& sums) {
  const size_t area = size_t(rect.area());
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x) {
      const size_t k = size_t(y) * rect.w + x;
      at(rect.x - window_.x + x, rect.y - window_.y + y).add(sums[k]);
      if (halves()) odd_at(rect.x - window_.x + x, rect.y - window_.y + y).add(sums[area + k]);
    }
}

void Film::set_tile(const Rect& rect, const PixelSums* sums) {
  const size_t area = size_t(rect.area());
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x) {
      const size_t k = size_t(y) * rect.w + x;
      at(rect.x - window_.x + x, rect.y - window_.y + y) = sums ? sums[k] : PixelSums{};
      if (halves()) odd_at(rect.x - window_.x + x, rect.y - window_.y + y) = sums ? sums[area + k] : PixelSums{};
    }
}

void half_means(const PixelSums& all, const PixelSums& odd, float even_rgb[3], float odd_rgb[3]) {
  const uint32_t n_even = all.n - std::min(all.n, odd.n);
  // The difference of two sums of non-negative samples: never below zero but for rounding.
  const double e[3] = {std::max(0.0, all.r - odd.r), std::max(0.0, all.g - odd.g), std::max(0.0, all.b - odd.b)};
  const double o[3] = {odd.r, odd.g, odd.b};
  for (int c = 0; c < 3; ++c) {  // a half without samples (one sample a pixel) shows the other's
    even_rgb[c] = n_even ? float(e[c] / n_even) : odd.n ? float(o[c] / odd.n) : 0.0f;
    odd_rgb[c] = odd.n ? float(o[c] / odd.n) : even_rgb[c];
  }
}

}  // namespace tessera

namespace tessera {

double Film::mean_luminance() const {
  double sum = 0;
  for (const PixelSums& p : pixels_) sum += p.n ? p.lum_sum() / p.n : 0;
  return pixels_.empty() ? 0 : sum / double(pixels_.size());
}

}  // namespace tessera
