#include "server/frame_splats.h"

#include <stdexcept>

namespace tessera {

FrameSplats::FrameSplats(const RenderSettings& s, uint32_t tiles)
    : window_(s.effective_window()),
      image_pixels_(int64_t(s.camera.width) * s.camera.height),
      halves_(s.halves()),
      exponent_(s.splat_exponent.value_or(0)),
      frontier_(tiles, 0) {}

void FrameSplats::make_film() {
  if (!film_) film_ = std::make_unique<SplatFilm>(window_, image_pixels_, halves_, exponent_);
}

void FrameSplats::add(uint32_t tile, uint32_t pass, std::vector<SplatRecord> records) {
  if (tile >= frontier_.size()) return;
  make_film();
  for (size_t i = 0; i < records.size(); ++i) {
    const uint32_t p = pass + uint32_t(i);
    if (p < frontier_[tile]) continue;  // in already (restored from a checkpoint)
    frontier_[tile] = p + 1;
    if (frozen_)
      pending_.push_back(std::move(records[i]));
    else
      film_->add_record(records[i]);
  }
}

void FrameSplats::reset() {
  if (film_) film_->clear();
  std::fill(frontier_.begin(), frontier_.end(), 0);
  pending_.clear();
}

void FrameSplats::copy_band(BandCopy* band) const {
  band->splats.clear();
  band->odd_splats.clear();
  band->splat_scale = band->odd_splat_scale = 0;
  if (!film_) return;
  film_->copy_rows(band->y0, band->rows, false, &band->splats);
  band->splat_scale = film_->scale(false);
  if (halves_) {
    film_->copy_rows(band->y0, band->rows, true, &band->odd_splats);
    band->odd_splat_scale = film_->scale(true);
  }
}

void FrameSplats::fold(BandCopy* band) {
  if (band->splats.size() == band->pixels.size())
    SplatFilm::fold(band->pixels.data(), band->splats.data(), band->pixels.size(), band->splat_scale);
  if (!band->odd.empty() && band->odd_splats.size() == band->odd.size())
    SplatFilm::fold(band->odd.data(), band->odd_splats.data(), band->odd.size(), band->odd_splat_scale);
}

FrameSplats::Frozen FrameSplats::freeze() {
  if (!film_) throw std::logic_error("FrameSplats::freeze: no splats");
  Frozen f{film_->paths(), film_->odd_paths(), frontier_};  // (a copy that may throw: before the flag)
  frozen_ = true;
  return f;
}

void FrameSplats::thaw() {
  frozen_ = false;
  if (film_)
    for (const SplatRecord& r : pending_) film_->add_record(r);
  std::vector<SplatRecord>().swap(pending_);
}

void FrameSplats::restore(const Frozen& f) {
  if (f.frontier.size() != frontier_.size()) throw std::invalid_argument("splats of another number of tiles");
  make_film();
  film_->clear();
  film_->set_paths(f.paths, f.odd_paths);
  frontier_ = f.frontier;
}

void FrameSplats::restore_rows(int y0, int rows, bool odd, const SplatSums* sums) {
  if (!film_ || y0 < 0 || rows < 0 || y0 + rows > window_.h || (odd && !halves_))
    throw std::invalid_argument("splat rows that do not fit the frame");
  film_->set_rows(y0, rows, odd, sums);
}

void FrameSplats::release() {
  film_.reset();
  std::vector<uint32_t>().swap(frontier_);
  std::vector<SplatRecord>().swap(pending_);
  frozen_ = false;
}

}  // namespace tessera
