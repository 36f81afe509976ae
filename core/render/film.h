// The film: per-pixel double sums that merge by plain addition.
//
// Each pixel keeps the sum of its RGB samples, the sum of squared sample luminance and
// the sample count. A tile renders one pass into fresh sums; the film adds them. Addition
// happens per pixel in pass order, so any tiling, thread count or machine split gives the
// same bits.
//
// With the half-buffers (--aov halves, for the denoiser) a film keeps a second plane: the
// sums of each pixel's odd-numbered samples only. A tile's sums are then two rect-sized
// planes, every sample's then the odd ones', and travel, merge and check as one vector
// (twice the pixels), so the second plane is added in pass order like the first. The
// even samples' sums are the difference.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/math/rect.h"
#include "core/math/vec.h"

namespace tessera {

struct PixelSums {
  double r = 0, g = 0, b = 0;
  double lum2 = 0;  // sum of squared luminance
  uint32_t n = 0;   // samples kept (NaN/Inf samples are dropped and counted elsewhere)

  void add(const PixelSums& o) {
    r += o.r;
    g += o.g;
    b += o.b;
    lum2 += o.lum2;
    n += o.n;
  }
  double lum_sum() const { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }
  Rgb mean() const { return n ? Rgb(float(r / n), float(g / n), float(b / n)) : Rgb(0); }
  // Unbiased per-sample variance of luminance.
  double sample_variance() const {
    if (n < 2) return 0;
    const double s1 = lum_sum();
    return std::max(0.0, (lum2 - s1 * s1 / n) / (n - 1));
  }
  // Variance of the pixel's mean: what its noise is.
  double mean_variance() const { return n ? sample_variance() / n : 0; }
};

class Film {
 public:
  Film(Rect window, bool halves = false)
      : window_(window), pixels_(size_t(window.area())), odd_(halves ? size_t(window.area()) : 0) {}
  const Rect& window() const { return window_; }
  int width() const { return window_.w; }
  int height() const { return window_.h; }
  // (x, y) relative to the window, row 0 at the top.
  PixelSums& at(int x, int y) { return pixels_[size_t(y) * window_.w + x]; }
  const PixelSums& at(int x, int y) const { return pixels_[size_t(y) * window_.w + x]; }
  const std::vector<PixelSums>& pixels() const { return pixels_; }
  // The odd-numbered samples' sums (the second plane): empty without half-buffers.
  bool halves() const { return !odd_.empty(); }
  PixelSums& odd_at(int x, int y) { return odd_[size_t(y) * window_.w + x]; }
  const PixelSums& odd_at(int x, int y) const { return odd_[size_t(y) * window_.w + x]; }
  const std::vector<PixelSums>& odd() const { return odd_; }
  // Adds a tile's sums (rect in image coordinates, sums row-major over the rect; with
  // half-buffers, two such planes).
  void add_tile(const Rect& rect, const std::vector<PixelSums>& sums);
  // Sets a tile's sums (in the same layout), or zeroes them (sums null).
  void set_tile(const Rect& rect, const PixelSums* sums);
  double mean_luminance() const;  // average over the film of per-pixel mean luminance

 private:
  Rect window_;
  std::vector<PixelSums> pixels_;
  std::vector<PixelSums> odd_;
};

// The means of a pixel's even- and odd-numbered samples (the EXR's even.* and odd.*, the
// denoiser's half-buffers): the one conversion, so every writer gives the same floats.
void half_means(const PixelSums& all, const PixelSums& odd, float even_rgb[3], float odd_rgb[3]);

}  // namespace tessera
