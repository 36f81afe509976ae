// The splats of a frame rendered through the farm (core/render/light_tracer.h, splats.h):
// each task's records, one per pass, added once its sums are merged into the frame plan, to
// one SplatFilm of the frame's window (fixed-point integers: any order of tasks gives the
// same bits). The film is made at the first record: a frame without light paths has none.
//
// Checkpoints. A checkpoint copies the film band by band while merges go on, so a copy of
// the splat film cannot be matched to the bands' tile progress. Each tile has a splat
// frontier instead: the passes whose records are in the splat film. After every band, the
// checkpoint writer freezes the splats (records that come meanwhile wait; thaw() adds
// them) and writes them with the frontier as of the freeze, never behind any band's
// progress. Restored, a tile's passes past its band's progress are rendered again and their
// records, already under the frontier, are not added twice (rendering is deterministic).
//
// Under the coordinator's lock, as the plan.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/render/frame_plan.h"
#include "core/render/splats.h"

namespace tessera {

class FrameSplats {
 public:
  FrameSplats(const RenderSettings& settings, uint32_t tiles);

  bool any() const { return film_ != nullptr; }
  const SplatFilm* film() const { return film_.get(); }
  // A merged task's records, for passes [pass, pass + records.size()) of `tile`, their
  // indices fit for this frame (decode_splats). Records of passes under the tile's frontier
  // are in already: skipped.
  void add(uint32_t tile, uint32_t pass, std::vector<SplatRecord> records);
  // Every splat and frontier forgotten: a liar's records are among them, and every tile of
  // the frame is rendered again.
  void reset();
  // Band `band.band`'s rows (band.y0, band.rows: copy_band's) of the splats and their
  // scales, into `band`; left empty without splats.
  void copy_band(BandCopy* band) const;
  // A band's pixels with its splats folded in (SplatFilm::fold_into's, row by row): the
  // image's; the band keeps its film sums otherwise.
  static void fold(BandCopy* band);

  // Checkpoints: what a frozen frame's splats are (paths, frontier; the rows by copy_band).
  struct Frozen {
    uint64_t paths = 0, odd_paths = 0;
    std::vector<uint32_t> frontier;  // per tile
  };
  Frozen freeze();  // any() only
  void thaw();
  bool frozen() const { return frozen_; }
  uint32_t frontier(uint32_t tile) const { return tile < frontier_.size() ? frontier_[tile] : 0; }
  // Restoring a checkpoint: the counts and frontier, then rows of either plane.
  void restore(const Frozen& f);
  void restore_rows(int y0, int rows, bool odd, const SplatSums* sums);
  // An ended frame whose image is on disk: nothing is kept.
  void release();

 private:
  void make_film();

  Rect window_;
  int64_t image_pixels_;
  bool halves_;
  int exponent_;  // the job's splat_exponent
  std::unique_ptr<SplatFilm> film_;
  std::vector<uint32_t> frontier_;
  bool frozen_ = false;
  std::vector<SplatRecord> pending_;  // records that came while frozen
};

}  // namespace tessera
