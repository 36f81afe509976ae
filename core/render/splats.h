// Light paths' contributions ("splats") to the frame: they land on any pixel, whichever tile
// traced them, so they cannot be added in a tile's pass order as the film's doubles are.
// Their sums are fixed-point integers instead (as the AOVs', aov.h): integer addition is
// associative, so any thread count, task order or grouping gives the same bits.
//
// Per pixel: the sum of the splats' RGB values (2^-24 units) and of their squared luminance
// (2^-32 units, for the variance layer: a splat's value is typically 1e-3 to 1e-1 at
// 480x360, and scales with the image's pixel count; 2^-12 units, before, rounded three
// quarters of CBspheres' splats to no variance at all). A splat's value is what Camera::connect describes:
// a pixel's estimate from N light paths is (width x height / N) x the sum. A splat with a
// channel above kMaxSplatValue (or not finite) is dropped and counted, as a sample over
// kMaxSampleValue is; sums saturate rather than wrap.
//
// With the half-buffers each plane gets its own light paths: those traced for the pixels'
// odd-numbered samples go to the second plane too (film.h).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/math/rect.h"
#include "core/math/vec.h"
#include "core/render/film.h"
#include "core/scene/scene.h"
#include "core/util/mutex.h"

namespace tessera {

struct SplatSums {
  static constexpr double kUnit = double(1 << 24);
  static constexpr double kLum2Unit = 0x1p32;
  // The most a single splat adds to lum2 (2^62 units: a luminance of 2^15): brighter ones
  // add this, so the sum stays within int64 and still reads as a large variance.
  static constexpr int64_t kMaxLum2Units = int64_t(1) << 62;
  int64_t rgb[3] = {0, 0, 0};
  int64_t lum2 = 0;
  double r() const { return double(rgb[0]) / kUnit; }
  double g() const { return double(rgb[1]) / kUnit; }
  double b() const { return double(rgb[2]) / kUnit; }
  double lum_sq() const { return double(lum2) / kLum2Unit; }
};

// Where a light path's splats go: the frame's SplatFilm (one process, shared by its
// threads) or a task's SplatList (a farm worker: the task's splats, sent with its sums).
class SplatSink {
 public:
  static constexpr float kMaxSplatValue = float(1 << 20);
  virtual ~SplatSink() = default;
  // Adds a splat to image pixel (x, y) (row 0 at the top), and to the odd plane too when
  // `odd`; outside the frame's window it is not seen. False when the value was dropped.
  virtual bool add(int x, int y, Rgb value, bool odd) = 0;
  // One light path traced (whether or not it splatted), for the plane(s) it belongs to.
  virtual void count_path(bool odd) = 0;
};

// The power of two a frame's splats are scaled down by before they enter their fixed-point
// sums (RenderSettings::splat_exponent): 0 for everyday scenes (the same bits as before it),
// more where the brightest light a light path starts at would make splats pass
// kMaxSplatValue (a rect light of radiance 1.2e8 lost every caustic splat: 7% dark).
// Integer arithmetic on the lights' colours and the image's pixel count (frexp, no libm):
// the coordinator, its workers and tessera render compute the same.
int splat_exponent_for(const std::vector<Light>& lights, int64_t image_pixels);
inline constexpr int kMaxSplatExponent = 100;

// A splat's value in fixed-point units (r, g, b, squared luminance); false (nothing set)
// when it is dropped: not finite, negative, or a channel over kMaxSplatValue.
bool splat_units(Rgb value, int64_t out[4]);

// One pass of a task's splats, sparse: per pixel they landed on, their sums. `index` is
// plane x window area + the pixel's row-major index in the frame's window (plane 1: the odd
// samples' light paths, with half-buffers). Entries ascend by index, one per index.
struct SplatEntry {
  uint32_t index = 0;
  int64_t v[4] = {0, 0, 0, 0};  // r, g, b (2^-24 units), squared luminance (2^-32)
};
struct SplatRecord {
  uint64_t paths = 0, odd_paths = 0;  // light paths traced: all, and the odd plane's
  std::vector<SplatEntry> entries;
  // Takes in another record's paths and entries (sorted and merged by normalize()).
  void append(const SplatRecord& other);
  // Sorts the entries and adds those of one index together (saturating).
  void normalize();
  bool operator==(const SplatRecord& o) const;
};

// A task's splats as they are traced, for one pass: not thread-safe (one per row render).
class SplatList final : public SplatSink {
 public:
  SplatList(Rect window, bool halves) : window_(window), halves_(halves) {}
  bool add(int x, int y, Rgb value, bool odd) override;
  void count_path(bool odd) override;
  // The record, normalized; the list is empty afterwards.
  SplatRecord take();
  // The record as added (entries in the order they came, an index possibly repeated: what
  // SplatFilm::add_record takes as well), and its splats dropped; clear() empties both.
  const SplatRecord& pending() const { return record_; }
  uint64_t dropped() const { return dropped_; }
  void clear();

 private:
  Rect window_;
  bool halves_;
  SplatRecord record_;
  uint64_t dropped_ = 0;
};

// Every member is thread-safe (one lock). Splats come in as records: a farm task's
// SplatList, or a render thread's SplatBuffer, a batch at a time.
class SplatFilm {
 public:
  // A frame's splats: `window` the pixels rendered (image coordinates), `image_pixels` the
  // camera film's width x height (the estimate's scale), with a second plane for halves.
  // `exponent`: the frame's splat_exponent (its splats entered their sums scaled by 2^-it:
  // scale() gives them back).
  SplatFilm(Rect window, int64_t image_pixels, bool halves, int exponent = 0);
  const Rect& window() const { return window_; }
  bool halves() const { return halves_; }

  // A task's record (its entries' indices within this film's planes: checked by the
  // caller; in any order) and its paths, and `dropped` splats to count.
  void add_record(const SplatRecord& record, uint64_t dropped = 0);
  // Every sum and count back to zero.
  void clear();
  // Sets counts and the sums of rows [y0, y0 + rows) of a plane (a checkpoint read back).
  void set_paths(uint64_t paths, uint64_t odd_paths);
  void set_rows(int y0, int rows, bool odd, const SplatSums* sums);
  // Copies rows [y0, y0 + rows) of a plane (window rows) into `out`.
  void copy_rows(int y0, int rows, bool odd, std::vector<SplatSums>* out) const;
  // What a pixel's mean gains per unit of splat sum: image pixels / light paths (0 without).
  double scale(bool odd) const;
  uint64_t paths() const;
  uint64_t odd_paths() const;
  uint64_t dropped() const;
  // The memory its sums take: the chunks splats have landed in.
  uint64_t bytes() const;
  // (x, y) relative to the window.
  SplatSums at(int x, int y, bool odd = false) const;

  // The film with these splats folded into its sums: each pixel's mean gains (image
  // pixels / paths) x its splat sum, and its mean's variance (PixelSums::mean_variance)
  // gains (image pixels / paths)^2 x its squared-luminance sum (the splats taken as
  // independent: a light path's splats on one pixel are rare). A pixel without samples
  // keeps nothing. The film must cover this window.
  Film fold_into(const Film& film) const;
  // fold_into()'s step for n pixels and their splat sums, `scale` from scale().
  static void fold(PixelSums* pixels, const SplatSums* splats, size_t n, double scale);

 private:
  void add_to(size_t index, const int64_t v[4]) TESSERA_REQUIRES(mu_);
  SplatSums sums_at(size_t k) const TESSERA_REQUIRES(mu_);
  // Pixel k's four sums, its chunk made (zero) if it has none.
  int64_t* writable(size_t k) TESSERA_REQUIRES(mu_);
  Rect window_;
  int64_t image_pixels_;
  bool halves_;
  double gain_ = 1;  // 2^exponent
  mutable Mutex mu_;
  // Per plane, per pixel: r, g, b, lum2, in chunks of kChunkPixels pixels made at their
  // first splat (a missing one is all zero): a frame's splats often land on few pixels,
  // and an 8K frame's full planes took 1.06 GB of the coordinator's memory with none.
  static constexpr size_t kChunkPixels = size_t(1) << 14;
  std::vector<std::unique_ptr<int64_t[]>> chunks_ TESSERA_GUARDED_BY(mu_);
  uint64_t paths_[2] TESSERA_GUARDED_BY(mu_) = {0, 0};
  uint64_t dropped_ TESSERA_GUARDED_BY(mu_) = 0;
};

// One thread's splats on their way into a SplatFilm: gathered in a bounded list and added
// under the film's lock a batch at a time (a locked add per splat, and a counter shared
// by every thread per light path, were 3% of CBspheres' render time). Integer sums: when
// a batch lands does not change the bits. Not thread-safe: one per thread.
class SplatBuffer final : public SplatSink {
 public:
  static constexpr size_t kBatchEntries = 8192;
  explicit SplatBuffer(SplatFilm& film) : film_(film), list_(film.window(), film.halves()) {}
  ~SplatBuffer() { flush(); }
  bool add(int x, int y, Rgb value, bool odd) override;
  void count_path(bool odd) override { list_.count_path(odd); }
  // Adds what is gathered to the film (also when destroyed).
  void flush();

 private:
  SplatFilm& film_;
  SplatList list_;
};

}  // namespace tessera
