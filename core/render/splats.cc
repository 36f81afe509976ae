#include "core/render/splats.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tessera {
namespace {

int64_t saturating_sum(int64_t a, int64_t b) {
  return a > std::numeric_limits<int64_t>::max() - b ? std::numeric_limits<int64_t>::max() : a + b;
}

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

}  // namespace

bool splat_units(Rgb value, int64_t out[4]) {
  if (!(value.is_finite() && std::min(value.r, std::min(value.g, value.b)) >= 0 &&
        value.max() <= SplatSink::kMaxSplatValue))
    return false;
  const double lum = value.luminance();
  out[0] = std::llround(value.r * SplatSums::kUnit);
  out[1] = std::llround(value.g * SplatSums::kUnit);
  out[2] = std::llround(value.b * SplatSums::kUnit);
  out[3] = std::llround(lum * lum * SplatSums::kLum2Unit);
  return true;
}

void SplatRecord::append(const SplatRecord& o) {
  paths += o.paths;
  odd_paths += o.odd_paths;
  entries.insert(entries.end(), o.entries.begin(), o.entries.end());
}

void SplatRecord::normalize() {
  std::stable_sort(entries.begin(), entries.end(),
                   [](const SplatEntry& a, const SplatEntry& b) { return a.index < b.index; });
  size_t out = 0;
  for (size_t i = 0; i < entries.size(); ++i) {
    if (out > 0 && entries[out - 1].index == entries[i].index) {
      for (int c = 0; c < 4; ++c) entries[out - 1].v[c] = saturating_sum(entries[out - 1].v[c], entries[i].v[c]);
      continue;
    }
    entries[out++] = entries[i];
  }
  entries.resize(out);
}

bool SplatRecord::operator==(const SplatRecord& o) const {
  return paths == o.paths && odd_paths == o.odd_paths && entries.size() == o.entries.size() &&
         std::equal(entries.begin(), entries.end(), o.entries.begin(), [](const SplatEntry& a, const SplatEntry& b) {
           return a.index == b.index && std::equal(a.v, a.v + 4, b.v);
         });
}

bool SplatList::add(int x, int y, Rgb value, bool odd) {
  SplatEntry e;
  if (!splat_units(value, e.v)) return false;
  x -= window_.x;
  y -= window_.y;
  if (x < 0 || y < 0 || x >= window_.w || y >= window_.h) return true;
  e.index = uint32_t(y) * uint32_t(window_.w) + uint32_t(x);
  record_.entries.push_back(e);
  if (halves_ && odd) {
    e.index += uint32_t(window_.area());
    record_.entries.push_back(e);
  }
  return true;
}

void SplatList::count_path(bool odd) {
  ++record_.paths;
  if (halves_ && odd) ++record_.odd_paths;
}

SplatRecord SplatList::take() {
  SplatRecord r = std::move(record_);
  record_ = SplatRecord{};
  r.normalize();
  return r;
}

void SplatFilm::fold(PixelSums* pixels, const SplatSums* splats, size_t n, double scale) {
  for (size_t i = 0; i < n; ++i) {
    PixelSums& p = pixels[i];
    const SplatSums& s = splats[i];
    if (p.n == 0) continue;
    const double mv = p.mean_variance() + scale * scale * s.lum_sq();
    p.r += double(p.n) * scale * s.r();
    p.g += double(p.n) * scale * s.g();
    p.b += double(p.n) * scale * s.b();
    p.lum2 = lum2_for(p, mv);
  }
}

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
  int64_t v[4];
  if (!splat_units(value, v)) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  x -= window_.x;
  y -= window_.y;
  if (x < 0 || y < 0 || x >= window_.w || y >= window_.h) return true;
  const size_t k = size_t(y) * size_t(window_.w) + size_t(x);
  add_to(k, v);
  if (halves_ && odd) add_to(size_t(window_.area()) + k, v);
  return true;
}

void SplatFilm::count_path(bool odd) {
  paths_[0].fetch_add(1, std::memory_order_relaxed);
  if (odd) paths_[1].fetch_add(1, std::memory_order_relaxed);
}

void SplatFilm::add_record(const SplatRecord& record) {
  for (const SplatEntry& e : record.entries) add_to(e.index, e.v);
  paths_[0].fetch_add(record.paths, std::memory_order_relaxed);
  paths_[1].fetch_add(record.odd_paths, std::memory_order_relaxed);
}

void SplatFilm::clear() {
  for (std::atomic<int64_t>& v : sums_) v.store(0, std::memory_order_relaxed);
  set_paths(0, 0);
  dropped_.store(0);
}

void SplatFilm::set_paths(uint64_t paths, uint64_t odd_paths) {
  paths_[0].store(paths);
  paths_[1].store(odd_paths);
}

void SplatFilm::set_rows(int y0, int rows, bool odd, const SplatSums* sums) {
  const size_t at = (odd ? size_t(window_.area()) : 0) + size_t(y0) * size_t(window_.w);
  for (size_t i = 0; i < size_t(rows) * size_t(window_.w); ++i) {
    for (int c = 0; c < 3; ++c) sums_[(at + i) * 4 + c].store(sums[i].rgb[c], std::memory_order_relaxed);
    sums_[(at + i) * 4 + 3].store(sums[i].lum2, std::memory_order_relaxed);
  }
}

void SplatFilm::copy_rows(int y0, int rows, bool odd, std::vector<SplatSums>* out) const {
  out->resize(size_t(rows) * size_t(window_.w));
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < window_.w; ++x) (*out)[size_t(y) * size_t(window_.w) + size_t(x)] = at(x, y0 + y, odd);
}

double SplatFilm::scale(bool odd) const {
  const uint64_t n = odd ? odd_paths() : paths();
  return n ? double(image_pixels_) / double(n) : 0;
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
  std::vector<SplatSums> row;
  for (int y = 0; y < window_.h; ++y)
    for (bool odd : {false, true}) {
      if (odd && !halves_) continue;
      copy_rows(y, 1, odd, &row);
      fold(odd ? &out.odd_at(0, y) : &out.at(0, y), row.data(), row.size(), scale(odd));
    }
  return out;
}

}  // namespace tessera
