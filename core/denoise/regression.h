// The denoiser's candidate filters (internal to core/denoise; denoiser.h says what they do
// and where they come from): per pixel, a weighted first-order regression of each half-buffer
// on the features, weighted by NL-means distances on the other half, at two NL-means
// bandwidths and over two window sizes, with each candidate's error (and the noisy colour's)
// estimated from the half-buffers.
#pragma once

#include <cstddef>
#include <vector>

namespace tessera {
namespace nfor {

constexpr int kWindowRadius = 6;  // the regression's window: 13 x 13 pixels (NFOR: 19 x 19; see denoiser.h)
constexpr int kInnerRadius = 3;   // and its central 7 x 7, fitted too: less bias where the features explain little
constexpr int kPatchRadius = 2;   // NL-means patches of 5 x 5 pixels (NFOR: 7 x 7)
constexpr int kTileWidth = 32;    // filter tiles: multiples of kMaxLanes wide, and small enough
constexpr int kTileHeight = 16;   // that their per-offset NL-means weights stay in L2
constexpr int kFeatures = 7;      // albedo r, g, b; normal x, y, z; log depth

// Feature weights, exp(-|difference|^2 / bandwidth^2) per feature group, are loose on
// purpose: the regression models the colour's linear dependence on the features; these
// only keep it from fitting one plane across very different surfaces (and rule the
// background out next to a hit). The feature planes hold features over their bandwidths.
constexpr float kAlbedoBandwidth = 1.0f;  // per |albedo difference| (rgb, each in [0, 1])
constexpr float kNormalBandwidth = 1.0f;  // per |normal difference| (2: opposite normals)
constexpr float kDepthBandwidth = 1.0f;   // in log depth: a factor e of distance
constexpr int kMaxLanes = 8;              // the widest SIMD kernels' (lanes.h)

// Planes with a border: pixel (x, y) of a width x height image, for x and y from -kMargin
// on, is at y' * stride + x' with x' = x + kMargin, y' = y + kMargin. The border reaches a
// window and a patch beyond the image on every side, and further right and down so that the
// tiles overhanging the image and their lane-rounded loads stay in the plane.
struct Grid {
  static constexpr int kMargin = kWindowRadius + kPatchRadius;
  int width = 0, height = 0;
  int stride = 0, rows = 0;

  Grid() = default;
  Grid(int w, int h);
  size_t at(int x, int y) const { return size_t(y + kMargin) * size_t(stride) + size_t(x + kMargin); }
  size_t size() const { return size_t(stride) * size_t(rows); }
};

// What the filters read, each plane on the grid.
struct GuidePlanes {
  Grid grid;
  std::vector<float> half[2][3];          // [even, odd][r, g, b]; the border repeats the edge pixels
  std::vector<float> variance[3];         // of one half's pixel mean, smoothed; the border repeats the edge
  std::vector<float> feature[kFeatures];  // over their bandwidths; 0 on the border
  std::vector<float> inside;              // 1 on the image, 0 on the border
};

// The candidate filters' results, width x height planes without a border.
struct Candidates {
  // NL-means bandwidths k = 0.5 and 1 over the 13 x 13 window, then k = 0.5 and 1 over its
  // central 7 x 7; then the noisy colour itself, which has an error but no plane here.
  static constexpr int kFiltered = 4;
  static constexpr int kCount = kFiltered + 1;
  std::vector<float> color[kFiltered][3];  // the mean of the two filtered halves
  std::vector<float> error[kCount];        // MSE estimate relative to colour^2, per pixel: noisy, smooth before use
};

// wide: the 8-lane AVX2 kernels where the CPU has them (the same bits as the 4-lane ones).
Candidates regress(const GuidePlanes& in, int threads, bool wide);

}  // namespace nfor
}  // namespace tessera
