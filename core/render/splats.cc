#include "core/render/splats.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tessera {
namespace {

// a + b for b >= 0, at most INT64_MAX.
void saturating_add(std::atomic<int64_t>& a, int64_t b) {
  int64_t cur = a.load(std::memory_order_relaxed);
  for (;;) {
    const int64_t next = cur > std::numeric_limits<int64_t>::max() - b ? std::numeric_limits<int64_t>::max() : cur + b;
    if (a.compare_exchange_weak(cur, next, std::memory_order_relaxed)) return;
  }
}

// (n samples, sums, the mean variance they imply) -> the squared-luminance sum that gives
// `mean_variance` with these sums (PixelSums::mean_variance inverted).
double lum2_for(const PixelSums& p, double mean_variance) {
  if (p.n < 2) return p.n ? p.lum_sum() * p.lum_sum() : 0;
  const double s1 = p.lum_sum();
  return s1 * s1 / p.n + mean_variance * double(p.n) * double(p.n - 1);
}

void fold(PixelSums& p, const SplatSums& s, double scale) {
  if (p.n == 0) return;
  const double mv = p.mean_variance() + scale * scale * s.lum_sq();
  p.r += double(p.n) * scale * s.r();
  p.g += double(p.n) * scale * s.g();
  p.b += double(p.n) * scale * s.b();
  p.lum2 = lum2_for(p, mv);
}

}  // namespace

SplatFilm::SplatFilm(Rect window, int64_t image_pixels, bool halves)
    : window_(window),
      image_pixels_(image_pixels),
      halves_(halves),
      sums_(size_t(window.area()) * 4 * (halves ? 2 : 1)) {}

void SplatFilm::add_to(size_t index, const int64_t v[4]) {
  for (int c = 0; c < 4; ++c)
    if (v[c]) saturating_add(sums_[index * 4 + c], v[c]);
}

bool SplatFilm::add(int x, int y, Rgb value, bool odd) {
  if (!(value.is_finite() && std::min(value.r, std::min(value.g, value.b)) >= 0 && value.max() <= kMaxSplatValue)) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  x -= window_.x;
  y -= window_.y;
  if (x < 0 || y < 0 || x >= window_.w || y >= window_.h) return true;
  const double lum = value.luminance();
  const int64_t v[4] = {std::llround(value.r * SplatSums::kUnit), std::llround(value.g * SplatSums::kUnit),
                        std::llround(value.b * SplatSums::kUnit), std::llround(lum * lum * SplatSums::kLum2Unit)};
  const size_t k = size_t(y) * size_t(window_.w) + size_t(x);
  add_to(k, v);
  if (halves_ && odd) add_to(size_t(window_.area()) + k, v);
  return true;
}

void SplatFilm::count_path(bool odd) {
  paths_[0].fetch_add(1, std::memory_order_relaxed);
  if (odd) paths_[1].fetch_add(1, std::memory_order_relaxed);
}

SplatSums SplatFilm::at(int x, int y, bool odd) const {
  const size_t k = (odd ? size_t(window_.area()) : 0) + size_t(y) * size_t(window_.w) + size_t(x);
  SplatSums s;
  for (int c = 0; c < 3; ++c) s.rgb[c] = sums_[k * 4 + c].load(std::memory_order_relaxed);
  s.lum2 = sums_[k * 4 + 3].load(std::memory_order_relaxed);
  return s;
}

Film SplatFilm::fold_into(const Film& film) const {
  if (!(film.window() == window_) || film.halves() != halves_)
    throw std::logic_error("SplatFilm::fold_into: the film does not cover the splats' window");
  Film out = film;
  const double all = paths() ? double(image_pixels_) / double(paths()) : 0;
  const double odd = odd_paths() ? double(image_pixels_) / double(odd_paths()) : 0;
  for (int y = 0; y < window_.h; ++y)
    for (int x = 0; x < window_.w; ++x) {
      fold(out.at(x, y), at(x, y), all);
      if (halves_) fold(out.odd_at(x, y), at(x, y, true), odd);
    }
  return out;
}

}  // namespace tessera
