#include "core/render/frame_plan.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera {

bool pixel_converged(const PixelSums& p, float tolerance) {
  if (p.n < 2) return false;
  const double mu = p.lum_sum() / p.n;
  const double half_width = 1.96 * std::sqrt(p.sample_variance() / p.n);
  return half_width <= tolerance * mu;
}

bool plausible(const PixelSums& p) {
  if (!(std::isfinite(p.r) && std::isfinite(p.g) && std::isfinite(p.b) && std::isfinite(p.lum2))) return false;
  if (p.r < 0 || p.g < 0 || p.b < 0 || p.lum2 < 0) return false;  // radiance is never negative
  if (p.n == 0) return p.r == 0 && p.g == 0 && p.b == 0 && p.lum2 == 0;
  const double cap = double(p.n) * kMaxSampleValue;
  if (p.r > cap || p.g > cap || p.b > cap || p.lum2 > cap * kMaxSampleValue) return false;
  // Cauchy-Schwarz: (sum l)^2 <= n sum l^2. The slack covers the float luminance of each
  // sample against the double weights of lum_sum(); no honest pixel comes near it.
  const double s = p.lum_sum();
  return s * s <= double(p.n) * p.lum2 * (1 + 1e-5) + 1e-300;
}

namespace {
// Whether a run's result holds what the film had of a pixel (sums only grow).
bool grown(const PixelSums& old, const PixelSums& now) {
  return now.n >= old.n && now.r >= old.r && now.g >= old.g && now.b >= old.b && now.lum2 >= old.lum2;
}

// The tile whose lower-left pixel is (x, y): `tile` square, cut short at the window's edge.
Rect tile_from(const Rect& w, int tile, int x, int y) {
  return {x, y, std::min(tile, w.x + w.w - x), std::min(tile, w.y + w.h - y)};
}
}  // namespace

std::vector<std::pair<uint32_t, uint32_t>> pass_run(const RenderSettings& settings, uint32_t first, uint32_t count) {
  const std::vector<std::pair<uint32_t, uint32_t>> all = settings.passes();
  if (count == 0 || first >= all.size() || count > all.size() - first) return {};
  return {all.begin() + first, all.begin() + first + count};
}

std::vector<Rect> frame_tiles(const RenderSettings& settings) {
  const Rect w = settings.effective_window();
  const int ts = std::max(1, settings.tile_size);
  std::vector<Rect> tiles;
  for (int y = w.y; y < w.y + w.h; y += ts)
    for (int x = w.x; x < w.x + w.w; x += ts) tiles.push_back(tile_from(w, ts, x, y));
  return tiles;
}

FramePlan::FramePlan(const RenderSettings& settings)
    : settings_(settings),
      film_(settings.effective_window(), settings.halves()),
      aovs_(settings.aovs ? AovFilm(settings.effective_window()) : AovFilm()),
      passes_(settings.passes()) {
  const Rect w = film_.window();
  const int ts = std::max(1, settings.tile_size);
  tiles_ = frame_tiles(settings);
  bands_ = w.h > 0 ? uint32_t((int64_t(w.h) + ts - 1) / ts) : 0;
  tiles_per_band_ = bands_ ? uint32_t(tiles_.size() / bands_) : 0;
  tile_count_ = uint32_t(tiles_.size());
  progress_.resize(tiles_.size());
  if (settings.adaptive) active_.assign(size_t(w.area()), 1);  // (1 byte a pixel: only when needed)
  for (uint32_t t = 0; t < tiles_.size(); ++t) ready_.emplace(0, t);
  unfinished_at_.assign(passes_.size() + 1, 0);
  unfinished_at_[0] = passes_.empty() ? 0 : uint32_t(tiles_.size());
  for (const auto& [s0, s1] : passes_) samples_total_ += uint64_t(s1 - s0) * uint64_t(w.area());
  work_total_ = double(samples_total_);
  if (passes_.empty()) tiles_done_ = uint32_t(tiles_.size());  // nothing to render
  advance_frame_passes();
}

std::optional<TileTask> FramePlan::take(uint32_t max_passes) {
  if (ready_.empty()) return std::nullopt;
  const uint32_t t = ready_.begin()->second;
  ready_.erase(ready_.begin());
  TileTask task = task_of(t);
  if (max_passes > 1 && runs() && task.pass + 1 < passes_.size()) {
    task.pass_count = std::min<uint32_t>(max_passes, uint32_t(passes_.size()) - task.pass);
    task.sample_end = passes_[task.pass + task.pass_count - 1].second;
    if (task.pass > 0) {
      const Rect& r = task.rect;
      const Rect& w = film_.window();
      const size_t area = size_t(r.area());
      task.base.resize(area * settings_.sum_planes());
      for (int y = 0; y < r.h; ++y) {
        std::copy_n(&film_.at(r.x - w.x, r.y - w.y + y), r.w, &task.base[size_t(y) * r.w]);
        if (film_.halves())
          std::copy_n(&film_.odd_at(r.x - w.x, r.y - w.y + y), r.w, &task.base[area + size_t(y) * r.w]);
      }
    }
  }
  return task;
}

uint32_t FramePlan::run_samples(uint32_t pass, uint32_t count) const {
  if (count == 0 || pass >= passes_.size() || count > passes_.size() - pass) return 0;
  if (count == 1) return passes_[pass].second - passes_[pass].first;
  return runs() ? passes_[pass + count - 1].second : 0;
}

std::optional<TileTask> FramePlan::retake(uint32_t tile) const {
  if (tile >= tiles_.size() || progress_[tile].finished || ready_.count({progress_[tile].passes_done, tile}))
    return std::nullopt;
  return task_of(tile);
}

TileTask FramePlan::task_of(uint32_t t) const {
  TileTask task;
  task.tile = t;
  task.pass = progress_[t].passes_done;
  task.rect = tiles_[t];
  task.sample_begin = passes_[task.pass].first;
  task.sample_end = passes_[task.pass].second;
  if (settings_.adaptive) {
    const Rect& r = task.rect;
    const Rect& w = film_.window();
    task.active.resize(size_t(r.area()));
    for (int y = 0; y < r.h; ++y)
      std::copy_n(&active_[size_t(r.y - w.y + y) * w.w + (r.x - w.x)], r.w, &task.active[size_t(y) * r.w]);
  }
  return task;
}

void FramePlan::put_back(uint32_t tile) {
  if (tile < tiles_.size() && !progress_[tile].finished) ready_.emplace(progress_[tile].passes_done, tile);
}

bool FramePlan::wants(uint32_t tile, uint32_t pass) const {
  return tile < tiles_.size() && !progress_[tile].finished && progress_[tile].passes_done == pass;
}

std::optional<CheckedSums> FramePlan::check(std::vector<PixelSums> sums, uint32_t pass_len, uint32_t planes) {
  if (planes < 1 || planes > 2 || sums.size() % planes) return std::nullopt;
  const size_t area = sums.size() / planes;
  uint64_t n = 0;
  for (size_t i = 0; i < sums.size(); ++i) {
    const PixelSums& p = sums[i];
    if (p.n > pass_len || !plausible(p)) return std::nullopt;
    if (i < area)
      n += p.n;
    else if (p.n > sums[i - area].n)  // the odd samples are some of the pixel's
      return std::nullopt;
  }
  return CheckedSums(std::move(sums), pass_len, n);
}

FramePlan::Merge FramePlan::merge(uint32_t tile, uint32_t pass, const std::vector<PixelSums>& sums, uint64_t* samples) {
  if (!wants(tile, pass)) return Merge::kDuplicate;
  std::optional<CheckedSums> checked = check(sums, passes_[pass].second - passes_[pass].first, settings_.sum_planes());
  if (!checked) return Merge::kInvalid;
  const Merge m = merge(tile, pass, *checked);
  if (m == Merge::kMerged && samples) *samples = checked->samples();
  return m;
}

FramePlan::Merge FramePlan::merge(uint32_t tile, uint32_t pass, const CheckedSums& checked, uint32_t pass_count,
                                  uint64_t* added) {
  if (!wants(tile, pass)) return Merge::kDuplicate;
  const Rect& r = tiles_[tile];
  const uint32_t run_len = run_samples(pass, pass_count);
  const size_t area = size_t(r.area());
  if (run_len == 0 || checked.sums().size() != area * settings_.sum_planes() || checked.pass_len() != run_len)
    return Merge::kInvalid;
  const Rect& w = film_.window();
  uint64_t before = 0;
  if (pass_count > 1) {  // a run's result holds the tile's sums: all of them, grown
    const std::vector<PixelSums>& s = checked.sums();
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x) {
        const size_t k = size_t(y) * r.w + x;
        const PixelSums& old = film_.at(r.x - w.x + x, r.y - w.y + y);
        if (!grown(old, s[k]) || (film_.halves() && !grown(film_.odd_at(r.x - w.x + x, r.y - w.y + y), s[area + k])))
          return Merge::kInvalid;
        before += old.n;
      }
  }
  ready_.erase({pass, tile});  // a late result for a tile waiting to be re-issued
  if (pass_count > 1)
    film_.set_tile(r, checked.sums().data());
  else
    film_.add_tile(r, checked.sums());
  ++merges_;
  samples_merged_ += checked.samples() - before;
  if (added) *added = checked.samples() - before;
  for (uint32_t p = pass; p < pass + pass_count; ++p)
    work_done_ += double(passes_[p].second - passes_[p].first) * double(r.area());
  finish_passes(tile, pass_count);
  return Merge::kMerged;
}

void FramePlan::advance_frame_passes() {
  while (frame_passes_ < passes_.size() && unfinished_at_[frame_passes_] == 0) ++frame_passes_;
}

void FramePlan::finish_passes(uint32_t tile, uint32_t count) {
  TileProgress& t = progress_[tile];
  --unfinished_at_[t.passes_done];
  t.passes_done += count;
  const Rect& r = tiles_[tile];
  const Rect& win = film_.window();
  // Estimated relative error of the tile: sqrt of mean var/(mean^2 + 0.01), the relMSE
  // the accuracy benchmarks use, predicted from the film's own variance.
  double rel = 0;
  bool any_active = false;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x) {
      const size_t k = size_t(r.y - win.y + y) * win.w + (r.x - win.x + x);
      const PixelSums& p = film_.pixels()[k];
      const double mu = p.n ? p.lum_sum() / p.n : 0;
      rel += p.mean_variance() / (mu * mu + 0.01);
      if (!settings_.adaptive) {
        any_active = true;
      } else {
        if (active_[k] && pixel_converged(p, settings_.adaptive_tolerance)) active_[k] = 0;
        any_active |= active_[k] != 0;
      }
    }
  t.relative_error = float(std::sqrt(rel / double(std::max<int64_t>(1, r.area()))));
  const bool noise_met = settings_.noise_target > 0 && t.passes_done >= 2 && t.relative_error <= settings_.noise_target;
  if (t.passes_done >= passes_.size() || !any_active || noise_met) {
    t.finished = true;
    ++tiles_done_;
    for (uint32_t p = t.passes_done; p < passes_.size(); ++p)  // work that will not be done
      work_total_ -= double(passes_[p].second - passes_[p].first) * double(r.area());
  } else {
    ready_.emplace(t.passes_done, tile);
    ++unfinished_at_[t.passes_done];
  }
  // Tiles only move up, so the lowest pass with unfinished tiles only moves up too.
  advance_frame_passes();
}

double FramePlan::fraction_done() const {
  if (done()) return 1;
  return work_total_ > 0 ? std::min(1.0, work_done_ / work_total_) : 0;
}

void FramePlan::reset_tile(uint32_t tile) {
  if (tile >= tiles_.size() || passes_.empty()) return;
  TileProgress& t = progress_[tile];
  const Rect& r = tiles_[tile];
  const double area = double(r.area());
  if (t.finished) {
    --tiles_done_;
    for (uint32_t p = t.passes_done; p < passes_.size(); ++p)  // scheduled again
      work_total_ += double(passes_[p].second - passes_[p].first) * area;
  } else {
    --unfinished_at_[t.passes_done];
    ready_.erase({t.passes_done, tile});
  }
  for (uint32_t p = 0; p < t.passes_done; ++p) work_done_ -= double(passes_[p].second - passes_[p].first) * area;
  const Rect& w = film_.window();
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x) {
      samples_merged_ -= film_.at(r.x - w.x + x, r.y - w.y + y).n;
      if (settings_.adaptive) active_[size_t(r.y - w.y + y) * w.w + (r.x - w.x + x)] = 1;
    }
  film_.set_tile(r, nullptr);
  if (!aovs_.empty()) aovs_.clear(r);
  t = TileProgress{};
  ++unfinished_at_[0];
  ready_.emplace(0, tile);
  ++merges_;          // the film changed
  frame_passes_ = 0;  // a reset tile moves it down
  advance_frame_passes();
}

void FramePlan::band_shape(uint32_t band, BandCopy* out) const {
  const Rect w = settings_.effective_window();
  const Rect first = tile_rect(band * tiles_per_band_);
  out->band = band;
  out->y0 = first.y - w.y;
  out->rows = first.h;
  out->width = w.w;
}

void FramePlan::copy_band(uint32_t band, BandCopy* out) const {
  const Rect& w = film_.window();
  band_shape(band, out);
  const size_t n = size_t(out->rows) * size_t(w.w), at = size_t(out->y0) * size_t(w.w);
  out->pixels.assign(film_.pixels().begin() + ptrdiff_t(at), film_.pixels().begin() + ptrdiff_t(at + n));
  out->progress.assign(progress_.begin() + ptrdiff_t(size_t(band) * tiles_per_band_),
                       progress_.begin() + ptrdiff_t(size_t(band + 1) * tiles_per_band_));
  if (settings_.adaptive)
    out->active.assign(active_.begin() + ptrdiff_t(at), active_.begin() + ptrdiff_t(at + n));
  else
    out->active.clear();
  out->samples = 0;
  for (const PixelSums& p : out->pixels) out->samples += p.n;
  if (!aovs_.empty())
    out->aovs.assign(aovs_.pixels().begin() + ptrdiff_t(at), aovs_.pixels().begin() + ptrdiff_t(at + n));
  else
    out->aovs.clear();
  if (film_.halves())
    out->odd.assign(film_.odd().begin() + ptrdiff_t(at), film_.odd().begin() + ptrdiff_t(at + n));
  else
    out->odd.clear();
}

void FramePlan::add_aovs(uint32_t tile, const std::vector<AovSums>& sums) {
  if (aovs_.empty() || tile >= tiles_.size() || sums.size() != size_t(tiles_[tile].area()))
    throw std::invalid_argument("frame plan: AOV sums that do not fit tile " + std::to_string(tile));
  aovs_.add_tile(tiles_[tile], sums);
}

void FramePlan::restore_band(const BandCopy& b) {
  auto bad = [](const std::string& why) { throw std::invalid_argument("saved frame plan: " + why); };
  const Rect& w = settings_.effective_window();
  if (b.band >= bands_) bad("band " + std::to_string(b.band) + " of " + std::to_string(bands_));
  const Rect& first = tiles_[size_t(b.band) * tiles_per_band_];
  const size_t n = size_t(first.h) * size_t(w.w);
  const bool with_film = !b.pixels.empty();
  if (b.y0 != first.y - w.y || b.rows != first.h || b.width != w.w || (with_film && b.pixels.size() != n) ||
      b.progress.size() != tiles_per_band_ || b.active.size() != (settings_.adaptive && with_film ? n : 0) ||
      b.aovs.size() != (settings_.aovs && with_film ? n : 0) ||
      b.odd.size() != (settings_.halves() && with_film ? n : 0))
    bad("band " + std::to_string(b.band) + " does not fit the frame");
  for (const TileProgress& t : b.progress)
    if (t.passes_done > passes_.size() || (!t.finished && t.passes_done == passes_.size() && !passes_.empty()))
      bad("a tile has " + std::to_string(t.passes_done) + " passes merged of " + std::to_string(passes_.size()));
  std::copy(b.progress.begin(), b.progress.end(), progress_.begin() + ptrdiff_t(size_t(b.band) * tiles_per_band_));
  restored_samples_ += b.samples;
  if (!with_film) {
    film_ = Film(Rect{});
    aovs_ = AovFilm();
    return;
  }
  if (!(film_.window() == w)) film_ = Film(w, settings_.halves());
  std::copy(b.pixels.begin(), b.pixels.end(), &film_.at(0, b.y0));
  if (settings_.halves()) std::copy(b.odd.begin(), b.odd.end(), &film_.odd_at(0, b.y0));
  if (settings_.aovs) {
    if (!(aovs_.window() == w) || aovs_.empty()) aovs_ = AovFilm(w);
    std::copy(b.aovs.begin(), b.aovs.end(), aovs_.row(b.y0));
  }
  if (settings_.adaptive)
    std::copy(b.active.begin(), b.active.end(), active_.begin() + ptrdiff_t(size_t(b.y0) * size_t(w.w)));
}

void FramePlan::restore_finish() {
  std::vector<uint32_t> unfinished(passes_.size() + 1, 0);
  uint32_t done = 0;
  samples_merged_ = 0;
  merges_ = 0;
  work_done_ = 0;
  work_total_ = double(samples_total_);
  for (uint32_t t = 0; t < tiles_.size(); ++t) {
    const TileProgress& p = progress_[t];
    const double area = double(tiles_[t].area());
    for (uint32_t k = 0; k < passes_.size(); ++k) {
      const double len = double(passes_[k].second - passes_[k].first) * area;
      if (k < p.passes_done)
        work_done_ += len;
      else if (p.finished)
        work_total_ -= len;  // work that will not be done
    }
    merges_ += p.passes_done;
    if (p.finished)
      ++done;
    else
      ++unfinished[p.passes_done];
  }
  if (has_film())
    for (const PixelSums& px : film_.pixels()) samples_merged_ += px.n;
  else
    samples_merged_ = restored_samples_;
  restored_samples_ = 0;
  unfinished_at_ = std::move(unfinished);
  tiles_done_ = passes_.empty() ? uint32_t(tiles_.size()) : done;
  ready_.clear();
  for (uint32_t t = 0; t < tiles_.size() && !passes_.empty(); ++t)
    if (!progress_[t].finished) ready_.emplace(progress_[t].passes_done, t);
  frame_passes_ = 0;
  advance_frame_passes();
}

PlanState FramePlan::state() const {
  PlanState s;
  s.progress = progress_;
  if (settings_.adaptive) s.active = active_;
  s.samples_merged = samples_merged_;
  s.merges = merges_;
  s.work_done = work_done_;
  s.work_total = work_total_;
  return s;
}

void FramePlan::restore(const PlanState& s, Film film) {
  const Rect w = settings_.effective_window();
  auto bad = [](const std::string& why) { throw std::invalid_argument("saved frame plan: " + why); };
  if (!(film.window() == w) && !(film.window() == Rect{})) bad("the film does not fit the frame");
  if (film.window() == w && film.halves() != settings_.halves()) bad("the film's half-buffers do not fit the settings");
  if (s.progress.size() != tiles_.size())
    bad("tile count " + std::to_string(s.progress.size()) + ", expected " + std::to_string(tiles_.size()));
  if (s.active.size() != (settings_.adaptive ? size_t(w.area()) : 0)) bad("the active-pixel mask does not fit");
  if (!(std::isfinite(s.work_done) && std::isfinite(s.work_total))) bad("work is not finite");
  std::vector<uint32_t> unfinished(passes_.size() + 1, 0);
  uint32_t done = 0;
  for (const TileProgress& t : s.progress) {
    if (t.passes_done > passes_.size() || (!t.finished && t.passes_done == passes_.size() && !passes_.empty()))
      bad("a tile has " + std::to_string(t.passes_done) + " passes merged of " + std::to_string(passes_.size()));
    if (t.finished)
      ++done;
    else
      ++unfinished[t.passes_done];
  }
  progress_ = s.progress;
  if (settings_.adaptive) active_ = s.active;
  samples_merged_ = s.samples_merged;
  merges_ = s.merges;
  work_done_ = s.work_done;
  work_total_ = s.work_total;
  film_ = std::move(film);
  unfinished_at_ = std::move(unfinished);
  tiles_done_ = passes_.empty() ? uint32_t(tiles_.size()) : done;  // nothing to render: done
  ready_.clear();
  for (uint32_t t = 0; t < tiles_.size() && !passes_.empty(); ++t)
    if (!progress_[t].finished) ready_.emplace(progress_[t].passes_done, t);
  frame_passes_ = 0;
  advance_frame_passes();
}

Rect FramePlan::tile_rect(uint32_t t) const {
  if (t < tiles_.size()) return tiles_[t];
  const Rect w = settings_.effective_window();
  const int ts = std::max(1, settings_.tile_size);
  return tile_from(w, ts, w.x + int(t % tiles_per_band_) * ts, w.y + int(t / tiles_per_band_) * ts);
}

TileProgress FramePlan::tile_progress(uint32_t t) const {
  if (t < progress_.size()) return progress_[t];
  TileProgress p;
  p.finished = done();
  p.passes_done = done() ? uint32_t(passes_.size()) : frame_passes_;
  p.relative_error = 0;
  return p;
}

void FramePlan::compact() {
  release_film();
  std::vector<Rect>().swap(tiles_);
  std::vector<TileProgress>().swap(progress_);
  std::vector<uint8_t>().swap(active_);
  std::vector<uint32_t>().swap(unfinished_at_);
  ready_.clear();
}

}  // namespace tessera
