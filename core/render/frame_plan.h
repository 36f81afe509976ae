// The schedule of one frame, shared by `tessera render` and the coordinator: the one place
// that decides which samples of which pixels are rendered, and in which order they are
// added into the film.
//
// The frame is cut into tiles and the samples into passes (RenderSettings::passes()). A
// task is one tile for one pass. A tile's pass k+1 becomes ready only when its pass k was
// merged, so every pixel's sums are added in pass order, and the film's bits do not depend
// on threads, workers, task order or timing. After each merge the tile's pixels are
// checked for convergence (-a) and the tile against the noise target (--noise-target),
// from merged sums only, so those decisions are reproducible too.
//
// A task may also be a run of a tile's passes (a worker on a slow link sends a tile's sums
// once for several passes): it carries the tile's sums so far (`base`), the worker adds the
// passes to them in order, as the film would, and its result takes the tile's place in the
// film: the same bits as merging the passes one by one. Only where nothing is decided
// between passes (no -a, no noise target).
//
// Not thread-safe: the local renderer and the coordinator each hold it under their lock.
#pragma once

#include <algorithm>
#include <cstdint>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include "core/render/aov.h"
#include "core/render/film.h"
#include "core/render/settings.h"
#include "core/render/splats.h"

namespace tessera {

// Samples [sample_begin, sample_end) of the active pixels of one tile: passes [pass, pass
// + pass_count).
struct TileTask {
  uint32_t tile = 0, pass = 0, pass_count = 1;
  Rect rect;
  uint32_t sample_begin = 0, sample_end = 0;
  std::vector<uint8_t> active;  // rect-sized, row-major; empty: every pixel
  // A run of passes after the first: the tile's sums so far (as a result's: rect-sized, two
  // planes with half-buffers), to which the run's
  // passes are added (its result is the tile's sums after the run). Empty otherwise.
  std::vector<PixelSums> base;
};

struct TileProgress {
  uint32_t passes_done = 0;
  bool finished = false;
  float relative_error = 1;  // estimated from the merged film after the last pass
};

// What a plan has done besides its film: with the film, enough to rebuild the plan exactly
// (FramePlan::restore), so that a coordinator restarted from a checkpoint goes on as if it
// had never stopped. Everything else (the ready set, per-pass counts) follows from these.
struct PlanState {
  std::vector<TileProgress> progress;  // one per tile
  std::vector<uint8_t> active;         // per film pixel; empty unless adaptive sampling
  uint64_t samples_merged = 0, merges = 0;
  double work_done = 0, work_total = 0;
};

// One band of a plan: a row of tiles (tile_size rows of the film; the last band may be
// shorter), the unit in which a coordinator copies a film under its lock and writes it
// outside: each tile's sums and progress are copied together, so every tile is consistent
// however the plan moves on between bands.
struct BandCopy {
  uint32_t band = 0;
  int y0 = 0, rows = 0, width = 0;     // film rows [y0, y0 + rows), row 0 the film's first
  std::vector<PixelSums> pixels;       // rows x width, row-major
  std::vector<TileProgress> progress;  // the band's tiles, left to right
  std::vector<uint8_t> active;         // rows x width; empty unless adaptive sampling
  uint64_t samples = 0;                // the pixels' samples (n) together
  std::vector<AovSums> aovs;           // rows x width; empty unless the settings ask for AOVs
  std::vector<PixelSums> odd;          // rows x width: the film's second plane; empty without half-buffers
  // A frame with light paths' splats (server/frame_splats.h): the rows' splat sums (each
  // plane's) and what a unit of them adds to a mean (SplatFilm::scale); empty otherwise.
  std::vector<SplatSums> splats, odd_splats;
  double splat_scale = 0, odd_splat_scale = 0;
};

// A task's sums found fit for a pass of pass_len samples a pixel (FramePlan::check): the
// per-pixel check needs no plan, so a coordinator makes it before taking its lock.
class CheckedSums {
 public:
  const std::vector<PixelSums>& sums() const { return sums_; }
  uint32_t pass_len() const { return pass_len_; }
  uint64_t samples() const { return samples_; }

 private:
  friend class FramePlan;
  CheckedSums(std::vector<PixelSums> sums, uint32_t pass_len, uint64_t samples)
      : sums_(std::move(sums)), pass_len_(pass_len), samples_(samples) {}
  std::vector<PixelSums> sums_;
  uint32_t pass_len_;
  uint64_t samples_;
};

// The sample ranges of passes [first, first + count) of a frame with these settings; empty
// when they are not all passes of it.
std::vector<std::pair<uint32_t, uint32_t>> pass_run(const RenderSettings& settings, uint32_t first, uint32_t count);

// The tiles a frame with these settings is cut into, band by band (rows of tiles, from the
// window's first row): squares of --tile pixels, cut short at the window's edge.
std::vector<Rect> frame_tiles(const RenderSettings& settings);

class FramePlan {
 public:
  enum class Merge { kMerged, kDuplicate, kInvalid };

  // `settings` must be valid (RenderSettings::validate()).
  explicit FramePlan(const RenderSettings& settings);

  // The ready tile with the fewest passes merged (the frame refines evenly), taken out of
  // the ready set; nothing when every unfinished tile is taken. With max_passes > 1, as a
  // run of up to that many passes where runs() allows.
  std::optional<TileTask> take(uint32_t max_passes = 1);
  // Whether tasks may be runs of passes: nothing is decided between passes (no -a, no
  // noise target).
  bool runs() const { return !settings_.adaptive && settings_.noise_target <= 0; }
  // Samples a pixel at most in a result of passes [pass, pass + count): the pass's for one
  // pass, every pass's until the run's end for a run (its result holds the tile's sums);
  // 0 when no task could be that run (out of range, or several passes and not runs()).
  uint32_t run_samples(uint32_t pass, uint32_t count) const;
  // A taken tile's task once more, the same as take() gave (for a second worker at the
  // frame's end: whichever result comes first is merged, with the same bits); nothing if
  // the tile is finished or not taken.
  std::optional<TileTask> retake(uint32_t tile) const;
  // A taken tile's task was abandoned (its lease ended without a result): ready again.
  void put_back(uint32_t tile);
  // Whether a result for (tile, pass) would be merged now (tile and pass in range).
  bool wants(uint32_t tile, uint32_t pass) const;
  // Adds a task's sums into the film and advances the tile. kDuplicate: that pass of the
  // tile was already merged (or the tile is finished); kInvalid: the sums do not fit the
  // task (size, more samples in a pixel than the pass has, or not plausible()). Nothing
  // changes unless
  // kMerged. `samples` receives the samples merged.
  Merge merge(uint32_t tile, uint32_t pass, const std::vector<PixelSums>& sums, uint64_t* samples = nullptr);
  // The per-pixel part of merge()'s check: nothing unless no pixel has more than pass_len
  // samples and every one is plausible(); of `planes` planes (settings' sum_planes()), the
  // second's pixels with no more samples than the first's. samples() counts the first's.
  static std::optional<CheckedSums> check(std::vector<PixelSums> sums, uint32_t pass_len, uint32_t planes = 1);
  // merge() of checked sums of passes [pass, pass + pass_count): kInvalid unless they were
  // checked for that run's samples (run_samples()) and fit the tile, and a run's sums
  // hold the tile's (no pixel with fewer samples or smaller sums). `added` receives the
  // samples merged.
  Merge merge(uint32_t tile, uint32_t pass, const CheckedSums& sums, uint32_t pass_count = 1,
              uint64_t* added = nullptr);

  bool done() const { return tiles_done_ == tile_count_; }
  size_t ready() const { return ready_.size(); }  // tasks take() could hand out now
  const Film& film() const { return film_; }
  // AOVs (settings().aovs): their sums, beside the film; empty without. A task's AOV sums
  // are added once its result is merged (add_aovs after merge() said kMerged): integers,
  // so any grouping of passes gives the same bits.
  const AovFilm& aovs() const { return aovs_; }
  void add_aovs(uint32_t tile, const std::vector<AovSums>& sums);
  const RenderSettings& settings() const { return settings_; }
  const std::vector<Rect>& tiles() const { return tiles_; }
  const std::vector<std::pair<uint32_t, uint32_t>>& passes() const { return passes_; }
  const TileProgress& progress(uint32_t tile) const { return progress_[tile]; }
  uint32_t tiles_done() const { return tiles_done_; }
  uint32_t frame_passes_done() const { return frame_passes_; }  // passes every unfinished tile has merged
  uint64_t samples_merged() const { return samples_merged_; }
  uint64_t samples_total() const { return samples_total_; }  // an upper bound (-a, noise target)
  // Samples still to merge (an upper bound as samples_total is; 0 once merged passes it).
  uint64_t samples_left() const { return samples_total_ - std::min(samples_total_, samples_merged_); }
  uint64_t merges() const { return merges_; }  // the film's version
  // Fraction of the scheduled work done, 1 when done (adaptive sampling may end early).
  double fraction_done() const;

  // Forgets everything merged into one tile (its pixels back to zero, every pass to be
  // rendered again, its pixels active again): for results found to come from a worker that
  // lies. Rendering the tile's passes again gives the film the same bits as if the tile
  // had been rendered honestly the first time. A lease on the tile must be ended first.
  void reset_tile(uint32_t tile);

  // Bands (BandCopy): the frame's rows of tiles, top to bottom in film rows.
  uint32_t bands() const { return bands_; }
  uint32_t tiles_per_band() const { return tiles_per_band_; }
  // Copies band `band` into `out`, reusing its buffers.
  void copy_band(uint32_t band, BandCopy* out) const;
  // Band `band`'s place alone (out's band, y0, rows, width; also after compact()).
  void band_shape(uint32_t band, BandCopy* out) const;
  // Restoring band by band (a checkpoint read piece by piece, into this plan's own film):
  // restore_band() for every band once, in any order, then restore_finish(), which derives
  // the counters (samples, work, film version) from the tiles and rebuilds the ready set. A
  // band without pixels restores progress only (an ended job's: its film is kept on disk,
  // and has_film() stays false). Throws std::invalid_argument when a band does not fit;
  // the plan is then unusable (the caller makes a fresh one).
  void restore_band(const BandCopy& band);
  void restore_finish();

  PlanState state() const;
  // Takes up a saved state and film (from state() and film() of a plan with the same
  // settings) in place of this plan's; nothing is taken. An empty film (Film(Rect{}))
  // restores the progress only, as after release_film(): for an ended job, whose image is
  // kept elsewhere. Throws std::invalid_argument, changing nothing, when they do not fit
  // these settings or contradict themselves.
  void restore(const PlanState& state, Film film);
  // Frees the film of a plan whose image is kept elsewhere (an ended job's); film() is
  // then empty and has_film() false.
  void release_film() { film_ = Film(Rect{}); }
  // An ended job whose film and plan are on disk keeps only its counts: the film and every
  // per-tile table go, so an ended frame costs a few hundred bytes however big (a long
  // sequence, a farm of many jobs). Afterwards tiles() is empty and nothing is wanted;
  // tile_count() and the counts stay.
  void compact();
  uint32_t tile_count() const { return tile_count_; }
  // Tile t's rectangle and progress, also after compact(): the rectangle from the frame's
  // geometry, the progress then as the frame's (every pass of a done frame; else the frame
  // passes every tile has).
  Rect tile_rect(uint32_t t) const;
  TileProgress tile_progress(uint32_t t) const;
  bool has_film() const { return film_.window() == settings_.effective_window(); }

 private:
  TileTask task_of(uint32_t tile) const;  // the tile's task for its next pass
  void finish_passes(uint32_t tile, uint32_t count);
  // Moves frame_passes_ up to the lowest pass that still has unfinished tiles.
  void advance_frame_passes();

  RenderSettings settings_;
  Film film_;
  AovFilm aovs_;
  std::vector<Rect> tiles_;
  std::vector<std::pair<uint32_t, uint32_t>> passes_;
  std::vector<TileProgress> progress_;
  std::vector<uint8_t> active_;                    // per film pixel (adaptive sampling only)
  std::set<std::pair<uint32_t, uint32_t>> ready_;  // (passes merged, tile): O(log tiles)
  std::vector<uint32_t> unfinished_at_;            // [p]: unfinished tiles with p passes merged
  uint32_t frame_passes_ = 0;                      // the lowest p with any (passes_.size() if none)
  uint32_t tiles_done_ = 0, tile_count_ = 0;
  uint64_t samples_merged_ = 0, samples_total_ = 0, merges_ = 0;
  double work_done_ = 0, work_total_ = 0;  // pixel-samples scheduled
  uint32_t bands_ = 0, tiles_per_band_ = 0;
  uint64_t restored_samples_ = 0;  // of the bands restore_band() took, since restore_finish()
};

// A sample's radiance at most, per channel. Emitters are at most Scene::kMaxEmission
// (1e20) and every BSDF conserves energy; with MIS an area light's contribution stays
// within its radiance times a small factor, so an honest sample passes 1e30 only through
// the 1/d^2 of a delta light (or, with --no-mis, an area light) closer than 1e-5 to the
// shading point. The bound keeps every pixel's mean a finite float whatever a worker
// sends; lies within it are for verification by replay to find.
constexpr double kMaxSampleValue = 1e30;

// Whether a pixel's sums could come from rendering: finite, non-negative, zero without
// samples, at most n x kMaxSampleValue per channel (n x kMaxSampleValue^2 squared), and a
// squared-luminance sum that Cauchy-Schwarz allows for its luminance sum.
bool plausible(const PixelSums& p);

// CS184 adaptive stopping (format doc 7.1, dividing by the true count): a pixel stops when
// the 95% confidence half-width of its luminance is within tolerance x mean.
bool pixel_converged(const PixelSums& p, float tolerance);

}  // namespace tessera
