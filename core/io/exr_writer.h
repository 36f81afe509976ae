// An EXR of film sums, written band by band: a coordinator copies a large film a few rows
// at a time and never holds a second copy of it. R, G, B (the mean), spp and variance as
// float channels, metadata as tessera/KEY strings, ZIP-compressed (or not, `compress`
// false). The one conversion from sums to pixels: write_exr uses it too, so a farm's image
// has the bits of tessera render's.
#pragma once

#include <OpenEXR/ImfForward.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/io/interrupt_cleanup.h"
#include "core/render/aov.h"
#include "core/render/film.h"

namespace tessera {

using ImageMetadata = std::map<std::string, std::string>;

class ExrWriter {
 public:
  // Writes to PATH.tmp; commit() renames it into place. Throws std::runtime_error naming
  // the path. The file's pixels are `window` (image coordinates, row 0 at the top) of the
  // image `frame`: its data window and display window (a crop, -p, keeps its place in the
  // frame for a compositor; a whole image has window == frame).
  // `aovs` (aov.h's bits) adds their channels (aov_channels), each row's from write_rows'
  // `aov` sums; with kAovHalves, the half-buffers' (kHalfChannels) from its `odd` sums.
  ExrWriter(std::string path, const Rect& window, const Rect& frame, const ImageMetadata& metadata,
            bool compress = true, uint32_t aovs = 0);
  ~ExrWriter();  // removes the temporary file unless committed
  ExrWriter(const ExrWriter&) = delete;
  ExrWriter& operator=(const ExrWriter&) = delete;
  // The next `rows` rows of `width` sums each (row 0 the image's top), and their AOV sums
  // when the file has AOV channels, and the rows' odd-numbered samples' sums (the film's
  // second plane) when it has the half-buffers'.
  void write_rows(const PixelSums* sums, int rows, const AovSums* aov = nullptr, const PixelSums* odd = nullptr);
  int rows_written() const { return next_row_; }
  // Every row written: the file goes into place.
  void commit();

 private:
  std::string path_, tmp_;
  RemoveOnInterrupt cleanup_{tmp_};
  Rect window_;
  int width_, height_, next_row_ = 0;
  std::unique_ptr<Imf::OutputFile> file_;
  std::vector<float> r_, g_, b_, spp_, var_;
  uint32_t aovs_;
  std::vector<std::string> aov_names_;
  std::vector<std::vector<float>> aov_;   // one plane per AOV channel
  std::vector<std::vector<float>> half_;  // even.R/G/B, odd.R/G/B (kAovHalves)
};

}  // namespace tessera
