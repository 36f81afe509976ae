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

// (n samples, sums, the mean variance they imply) -> the squared-luminance sum that gives
// `mean_variance` with these sums (PixelSums::mean_variance inverted).
double lum2_for(const PixelSums& p, double mean_variance) {
  if (p.n < 2) return p.n ? p.lum_sum() * p.lum_sum() : 0;
  const double s1 = p.lum_sum();
  return s1 * s1 / p.n + mean_variance * double(p.n) * double(p.n - 1);
}

// std::llround's result (halves away from zero) for 0 <= x <= 2^62, inline (llround is a
// libm call): x - trunc(x) is exact, so comparing it with 1/2 decides as llround does.
int64_t round_nonnegative(double x) {
  const int64_t t = int64_t(x);
  return t + (x - double(t) >= 0.5);
}

}  // namespace

int splat_exponent_for(const std::vector<Light>& lights, int64_t image_pixels) {
  // Splats are about 1e-3 to 1e-1 of the light's radiance at 480x360 (172,800 pixels) and
  // scale with the pixel count; 2^14 of headroom below kMaxSplatValue (2^20) is kept.
  double brightest = 0;
  for (const Light& l : lights)
    if (l.kind != Light::Kind::kDirectional && l.kind != Light::Kind::kAmbient && l.kind != Light::Kind::kEnvironment &&
        l.color.is_finite())
      brightest = std::max(brightest, double(l.color.max()));
  const double reach = brightest * std::max(1.0, double(image_pixels) / 172800.0);
  if (!(reach > 0x1p14)) return 0;
  int e = 0;
  const double m = std::frexp(reach, &e);  // reach = m 2^e, m in [1/2, 1)
  return std::min(kMaxSplatExponent, (m == 0.5 ? e - 1 : e) - 14);
}

bool splat_units(Rgb value, int64_t out[4]) {
  if (!(value.is_finite() && std::min(value.r, std::min(value.g, value.b)) >= 0 &&
        value.max() <= SplatSink::kMaxSplatValue))
    return false;
  // At most 2^44 (channels) and 2^62 (squared luminance, capped) units: round_nonnegative's range.
  const double lum = value.luminance();
  out[0] = round_nonnegative(value.r * SplatSums::kUnit);
  out[1] = round_nonnegative(value.g * SplatSums::kUnit);
  out[2] = round_nonnegative(value.b * SplatSums::kUnit);
  out[3] = round_nonnegative(std::min(lum * lum * SplatSums::kLum2Unit, double(SplatSums::kMaxLum2Units)));
  return true;
}

void SplatRecord::append(const SplatRecord& o) {
  paths += o.paths;
  odd_paths += o.odd_paths;
  entries.insert(entries.end(), o.entries.begin(), o.entries.end());
}

void SplatRecord::normalize() {
  // Sorted by pixel through 8-byte keys (the index, then the entry's place), not the 40-byte
  // entries themselves: a stable sort of those, with its merge buffer, was 1.2% of a
  // worker's render samples on a light-traced scene (this form: 0.6% less render CPU).
  // Entries of one index are added in any order: their sums are non-negative and
  // saturating, so the total is min(sum, maximum) whatever the order. (A record's entries
  // number far below 2^32: a task's light paths are bounded.)
  std::vector<uint64_t> keys(entries.size());
  for (size_t i = 0; i < entries.size(); ++i) keys[i] = (uint64_t(entries[i].index) << 32) | uint64_t(i);
  std::sort(keys.begin(), keys.end());
  std::vector<SplatEntry> merged;
  merged.reserve(entries.size());
  for (const uint64_t k : keys) {
    const SplatEntry& e = entries[size_t(k & 0xFFFFFFFFu)];
    if (!merged.empty() && merged.back().index == e.index) {
      for (int c = 0; c < 4; ++c) merged.back().v[c] = saturating_sum(merged.back().v[c], e.v[c]);
      continue;
    }
    merged.push_back(e);
  }
  entries.swap(merged);
}

bool SplatRecord::operator==(const SplatRecord& o) const {
  return paths == o.paths && odd_paths == o.odd_paths && entries.size() == o.entries.size() &&
         std::equal(entries.begin(), entries.end(), o.entries.begin(), [](const SplatEntry& a, const SplatEntry& b) {
           return a.index == b.index && std::equal(a.v, a.v + 4, b.v);
         });
}

bool SplatList::add(int x, int y, Rgb value, bool odd) {
  SplatEntry e;
  if (!splat_units(value, e.v)) {
    ++dropped_;
    return false;
  }
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
  dropped_ = 0;
  r.normalize();
  return r;
}

void SplatList::clear() {
  record_.entries.clear();  // (keeps its capacity)
  record_.paths = record_.odd_paths = 0;
  dropped_ = 0;
}

bool SplatBuffer::add(int x, int y, Rgb value, bool odd) {
  const bool kept = list_.add(x, y, value, odd);
  if (list_.pending().entries.size() >= kBatchEntries) flush();
  return kept;
}

void SplatBuffer::flush() {
  const SplatRecord& r = list_.pending();
  if (r.entries.empty() && r.paths == 0 && list_.dropped() == 0) return;
  film_.add_record(r, list_.dropped());
  list_.clear();
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

SplatFilm::SplatFilm(Rect window, int64_t image_pixels, bool halves, int exponent)
    : window_(window),
      image_pixels_(image_pixels),
      halves_(halves),
      gain_(std::ldexp(1.0, exponent)),
      chunks_((size_t(window.area()) * (halves ? 2 : 1) + kChunkPixels - 1) / kChunkPixels) {}

int64_t* SplatFilm::writable(size_t k) {
  std::unique_ptr<int64_t[]>& chunk = chunks_[k / kChunkPixels];
  if (!chunk) chunk = std::make_unique<int64_t[]>(kChunkPixels * 4);  // (zeroed)
  return &chunk[(k % kChunkPixels) * 4];
}

void SplatFilm::add_to(size_t index, const int64_t v[4]) {
  int64_t* sums = writable(index);
  for (int c = 0; c < 4; ++c) sums[c] = saturating_sum(sums[c], v[c]);
}

void SplatFilm::add_record(const SplatRecord& record, uint64_t dropped) {
  MutexLock lock(mu_);
  for (const SplatEntry& e : record.entries) add_to(e.index, e.v);
  paths_[0] += record.paths;
  paths_[1] += record.odd_paths;
  dropped_ += dropped;
}

void SplatFilm::clear() {
  MutexLock lock(mu_);
  for (std::unique_ptr<int64_t[]>& chunk : chunks_) chunk.reset();
  paths_[0] = paths_[1] = 0;
  dropped_ = 0;
}

void SplatFilm::set_paths(uint64_t paths, uint64_t odd_paths) {
  MutexLock lock(mu_);
  paths_[0] = paths;
  paths_[1] = odd_paths;
}

void SplatFilm::set_rows(int y0, int rows, bool odd, const SplatSums* sums) {
  MutexLock lock(mu_);
  const size_t at = (odd ? size_t(window_.area()) : 0) + size_t(y0) * size_t(window_.w);
  for (size_t i = 0; i < size_t(rows) * size_t(window_.w); ++i) {
    const SplatSums& v = sums[i];
    const bool zero = v.rgb[0] == 0 && v.rgb[1] == 0 && v.rgb[2] == 0 && v.lum2 == 0;
    if (zero && !chunks_[(at + i) / kChunkPixels]) continue;  // (no chunk: zero already)
    int64_t* out = writable(at + i);
    for (int c = 0; c < 3; ++c) out[c] = v.rgb[c];
    out[3] = v.lum2;
  }
}

void SplatFilm::copy_rows(int y0, int rows, bool odd, std::vector<SplatSums>* out) const {
  MutexLock lock(mu_);
  const size_t at = (odd ? size_t(window_.area()) : 0) + size_t(y0) * size_t(window_.w);
  out->resize(size_t(rows) * size_t(window_.w));
  for (size_t i = 0; i < out->size(); ++i) (*out)[i] = sums_at(at + i);
}

uint64_t SplatFilm::paths() const {
  MutexLock lock(mu_);
  return paths_[0];
}

uint64_t SplatFilm::odd_paths() const {
  MutexLock lock(mu_);
  return paths_[1];
}

uint64_t SplatFilm::bytes() const {
  MutexLock lock(mu_);
  uint64_t n = 0;
  for (const std::unique_ptr<int64_t[]>& chunk : chunks_) n += chunk ? kChunkPixels * 4 * sizeof(int64_t) : 0;
  return n;
}

uint64_t SplatFilm::dropped() const {
  MutexLock lock(mu_);
  return dropped_;
}

double SplatFilm::scale(bool odd) const {
  const uint64_t n = odd ? odd_paths() : paths();
  return n ? double(image_pixels_) / double(n) * gain_ : 0;
}

SplatSums SplatFilm::sums_at(size_t k) const {
  SplatSums s;
  const std::unique_ptr<int64_t[]>& chunk = chunks_[k / kChunkPixels];
  if (!chunk) return s;
  const int64_t* sums = &chunk[(k % kChunkPixels) * 4];
  for (int c = 0; c < 3; ++c) s.rgb[c] = sums[c];
  s.lum2 = sums[3];
  return s;
}

SplatSums SplatFilm::at(int x, int y, bool odd) const {
  MutexLock lock(mu_);
  return sums_at((odd ? size_t(window_.area()) : 0) + size_t(y) * size_t(window_.w) + size_t(x));
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
