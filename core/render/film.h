// The film: per-pixel double sums that merge by plain addition.
//
// Each pixel keeps the sum of its RGB samples, the sum of squared sample luminance and
// the sample count. A tile renders one pass into fresh sums; the film adds them. Addition
// happens per pixel in pass order, so any tiling, thread count or machine split gives the
// same bits.
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
  Film(Rect window) : window_(window), pixels_(size_t(window.area())) {}
  const Rect& window() const { return window_; }
  int width() const { return window_.w; }
  int height() const { return window_.h; }
  // (x, y) relative to the window, row 0 at the top.
  PixelSums& at(int x, int y) { return pixels_[size_t(y) * window_.w + x]; }
  const PixelSums& at(int x, int y) const { return pixels_[size_t(y) * window_.w + x]; }
  const std::vector<PixelSums>& pixels() const { return pixels_; }
  // Adds a tile's sums (rect in image coordinates, sums row-major over the rect).
  void add_tile(const Rect& rect, const std::vector<PixelSums>& sums);
  double mean_luminance() const;  // average over the film of per-pixel mean luminance

 private:
  Rect window_;
  std::vector<PixelSums> pixels_;
};

}  // namespace tessera
