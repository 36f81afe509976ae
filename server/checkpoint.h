// A job's checkpoint file: its frame plan's progress and its film's sums, checksummed
// (xxh64). docs/architecture.md has where and when.
//
// Version 6 is written band by band (FramePlan::copy_band: a row of tiles, each tile's sums
// with its progress), so a coordinator never holds a second copy of a large film, and read
// band by band into the plan's own film; every counter of the plan follows from its tiles.
//   header  "TSCK", u32 6, i32 window x y w h, u32 tiles, u32 bands, u8 adaptive, u8 film,
//           f64 elapsed
//   band    u32 band, u32 tiles, per tile (u32 passes, u8 finished, f32 relative error),
//           u64 samples, [film: [adaptive: u64 mask bytes, bytes zstd(mask)], bytes sums
//           (wire.h), [AOVs: bytes AOV sums], [half-buffers: bytes the second plane's sums]]
//   splats  u8 0, or u8 1, u64 paths, u64 odd paths, per tile u32 frontier, then per band in
//           order bytes zstd(its rows' SplatSums, 32 bytes each) [half-buffers: the odd
//           plane's too] (frame_splats.h: frozen after the bands); squared luminance in
//           2^-32 units (version 4, still read: the same in 2^-12 units)
//   end     u64 xxh64 of everything before it
// (bytes = u64 length + the bytes.) Without the film (u8 film 0: a finished frame of a
// sequence once its image is written, SnapshotWriter) a checkpoint holds the progress
// alone, a few bytes a tile, and no splats. Version 5 (no film flag: always the film),
// version 4 (see above), version 3 (no splats) and
// versions 1 and 2 (the whole PlanState, then the film in one or in 65,536-pixel pieces)
// are still read.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "core/render/frame_plan.h"
#include "server/frame_splats.h"

namespace tessera {

// Version 5, band by band: the header at construction, then band() for every band in
// order, then (a frame with splats) splats() and splat_band() for every band in order, then
// finish(); each piece of the file goes to `out` as it is made.
class CheckpointEncoder {
 public:
  // Without `film`, the progress alone (band() writes no sums; splats() may not be called).
  CheckpointEncoder(const FramePlan& plan, double elapsed, std::function<void(const std::string&)> out,
                    bool film = true);
  ~CheckpointEncoder();
  void band(const BandCopy& band);
  // The frozen splats' counts and frontier; then each band's splat rows (copy_band's).
  void splats(const FrameSplats::Frozen& frozen);
  void splat_band(const BandCopy& band);
  void finish();

 private:
  void emit(std::string bytes);
  std::function<void(const std::string&)> out_;
  struct Hash;
  std::unique_ptr<Hash> hash_;
  bool adaptive_;
  bool aovs_;    // the job has AOVs: each band carries their sums after the film's
  bool halves_;  // and half-buffers: then the film's second plane (film.h)
  bool film_;
  bool splats_ = false;
};

// The whole file for a plan (and its splats, if any), band by band (tests, and small plans).
std::string encode_checkpoint(const FramePlan& plan, double elapsed, FrameSplats* splats = nullptr);

// Reads a checkpoint of any version from `read` (which fills up to n bytes of its buffer
// and returns how many, 0 at the end) into `plan`, whose settings it must fit; returns the
// render seconds it was taken at. Without `with_film` only the progress is restored (an
// ended job's); with it, its splats into `splats` (when given). Throws std::runtime_error ("checkpoint: ...") when the
// bytes are damaged, cut short or do not fit the plan, or `with_film` asks for a film the
// checkpoint does not hold; the plan is then unusable.
double read_checkpoint(const std::function<size_t(char*, size_t)>& read, FramePlan& plan, bool with_film = true,
                       FrameSplats* splats = nullptr);
double read_checkpoint(const std::string& bytes, FramePlan& plan, bool with_film = true, FrameSplats* splats = nullptr);

// Versions 1 and 2: the file as one PlanState and film (exposed for tests and the fuzzer).
struct Checkpoint {
  PlanState state;
  Film film{Rect{}};
  double elapsed = 0;  // render seconds when it was taken
};
std::string encode_checkpoint_v2(const PlanState& state, const Film& film, double elapsed);
// `expected`: the job's film window, where known: a checkpoint of another is refused before
// its film is allocated (a crafted 104-byte file declared 2^32 pixels).
Checkpoint decode_checkpoint(const std::string& bytes, bool with_film = true, const Rect* expected = nullptr);

}  // namespace tessera
