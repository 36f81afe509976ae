#include "core/denoise/denoiser.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <thread>

#include "core/denoise/parallel.h"
#include "core/denoise/regression.h"

namespace tessera {

namespace {

using nfor::Candidates;
using nfor::Grid;
using nfor::GuidePlanes;
using nfor::parallel_for;

constexpr int kVarianceRadius = 3;   // 7 x 7: 49 samples of the dual-buffer variance a channel
constexpr int kErrorRadius = 2;      // 5 x 5: a pixel's MSE estimates are noisy; wider boxes miss detail
constexpr int kSelectionRadius = 2;  // 5 x 5: softens the seams between the candidates
constexpr float kMinDepth = 1e-6f;   // log depth stays finite at (or, wrongly, below) zero distance
constexpr float kMaxDepth = 1e10f;   // the background's depth; further counts as background
static_assert(kDenoiseReach ==
              kVarianceRadius + nfor::kPatchRadius + nfor::kWindowRadius + kErrorRadius + kSelectionRadius);

[[noreturn]] void refuse(const std::string& what) { throw std::invalid_argument("denoise: " + what); }

void check_plane(const char* name, const std::vector<float>& v, int channels, int w, int h, int first_row,
                 int first_column) {
  const size_t expected = size_t(channels) * size_t(w) * size_t(h);
  if (v.size() != expected)
    refuse("the '" + std::string(name) + "' buffer has " + std::to_string(v.size()) + " values, " +
           std::to_string(channels) + " x " + std::to_string(w) + " x " + std::to_string(h) + " = " +
           std::to_string(expected) + " expected");
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) {
      const size_t pixel = i / size_t(channels);
      refuse("the '" + std::string(name) + "' buffer has a non-finite value (" + std::to_string(v[i]) + ") at pixel (" +
             std::to_string(int64_t(pixel % size_t(w)) + first_column) + ", " +
             std::to_string(int64_t(pixel / size_t(w)) + first_row) + ")");
    }
}

void validate(const DenoiseBuffers& in) {
  if (in.width <= 0 || in.height <= 0)
    refuse("the image is " + std::to_string(in.width) + " x " + std::to_string(in.height) +
           " pixels; both sides must be at least 1");
  const int w = in.width, h = in.height;
  check_plane("color", in.color, 3, w, h, in.first_row, in.first_column);
  check_plane("even", in.even, 3, w, h, in.first_row, in.first_column);
  check_plane("odd", in.odd, 3, w, h, in.first_row, in.first_column);
  check_plane("albedo", in.albedo, 3, w, h, in.first_row, in.first_column);
  check_plane("normal", in.normal, 3, w, h, in.first_row, in.first_column);
  check_plane("depth", in.depth, 1, w, h, in.first_row, in.first_column);
}

// Channel `channel` of an image of `channels` floats a pixel, times `scale`, onto the grid;
// the border repeats the nearest edge pixel, or stays 0.
void to_grid(const Grid& g, const std::vector<float>& src, int channels, int channel, float scale, bool repeat_edges,
             std::vector<float>& plane, int threads) {
  plane.assign(g.size(), 0.f);
  const int x0 = repeat_edges ? -Grid::kMargin : 0, x1 = repeat_edges ? g.stride - Grid::kMargin : g.width;
  const int y0 = repeat_edges ? -Grid::kMargin : 0, y1 = repeat_edges ? g.rows - Grid::kMargin : g.height;
  parallel_for(y1 - y0, threads, [&](int row, int) {
    const int y = y0 + row, sy = std::clamp(y, 0, g.height - 1);
    for (int x = x0; x < x1; ++x) {
      const int sx = std::clamp(x, 0, g.width - 1);
      plane[g.at(x, y)] = scale * src[(size_t(sy) * size_t(g.width) + size_t(sx)) * size_t(channels) + size_t(channel)];
    }
  });
}

// The mean over the (2 radius + 1)^2 box around each pixel, of the part inside the image.
std::vector<float> box_filter(const std::vector<float>& src, int w, int h, int radius, int threads) {
  std::vector<float> across(src.size()), out(src.size());
  parallel_for(h, threads, [&](int y, int) {
    const float* row = &src[size_t(y) * size_t(w)];
    for (int x = 0; x < w; ++x) {
      const int a = std::max(0, x - radius), b = std::min(w - 1, x + radius);
      float sum = 0;
      for (int i = a; i <= b; ++i) sum += row[i];
      across[size_t(y) * size_t(w) + size_t(x)] = sum / float(b - a + 1);
    }
  });
  parallel_for(h, threads, [&](int y, int) {
    const int a = std::max(0, y - radius), b = std::min(h - 1, y + radius);
    for (int x = 0; x < w; ++x) {
      float sum = 0;
      for (int i = a; i <= b; ++i) sum += across[size_t(i) * size_t(w) + size_t(x)];
      out[size_t(y) * size_t(w) + size_t(x)] = sum / float(b - a + 1);
    }
  });
  return out;
}

GuidePlanes prepare(const DenoiseBuffers& in, int threads) {
  const int w = in.width, h = in.height;
  const size_t pixels = size_t(w) * size_t(h);
  GuidePlanes g;
  g.grid = Grid(w, h);
  for (int c = 0; c < 3; ++c) {
    to_grid(g.grid, in.even, 3, c, 1, true, g.half[0][c], threads);
    to_grid(g.grid, in.odd, 3, c, 1, true, g.half[1][c], threads);
    std::vector<float> variance(pixels);
    parallel_for(h, threads, [&](int y, int) {
      for (size_t i = size_t(y) * size_t(w); i < size_t(y + 1) * size_t(w); ++i) {
        const float d = in.even[3 * i + size_t(c)] - in.odd[3 * i + size_t(c)];
        variance[i] = 0.5f * d * d;  // E[(even - odd)^2] = 2 var(half)
      }
    });
    to_grid(g.grid, box_filter(variance, w, h, kVarianceRadius, threads), 1, 0, 1, true, g.variance[c], threads);
    to_grid(g.grid, in.albedo, 3, c, 1 / nfor::kAlbedoBandwidth, false, g.feature[c], threads);
    to_grid(g.grid, in.normal, 3, c, 1 / nfor::kNormalBandwidth, false, g.feature[3 + c], threads);
  }
  std::vector<float> log_depth(pixels);
  parallel_for(h, threads, [&](int y, int) {
    for (size_t i = size_t(y) * size_t(w); i < size_t(y + 1) * size_t(w); ++i)
      log_depth[i] = std::log(std::clamp(in.depth[i], kMinDepth, kMaxDepth));
  });
  to_grid(g.grid, log_depth, 1, 0, 1 / nfor::kDepthBandwidth, false, g.feature[6], threads);
  to_grid(g.grid, std::vector<float>(pixels, 1.f), 1, 0, 1, false, g.inside, threads);
  return g;
}

// Whether the pixel's smoothed variance is 0 in every channel: then it is kept as it is.
bool noise_free(const GuidePlanes& g, int x, int y) {
  const size_t p = g.grid.at(x, y);
  return g.variance[0][p] == 0 && g.variance[1][p] == 0 && g.variance[2][p] == 0;
}

// Blends the candidates, the noisy colour among them, by their smoothed errors: the one
// with the least per pixel, as a 0/1 map a candidate, each map smoothed by a box (which is
// counting, over the box, the pixels that chose each). Noise-free pixels keep their colour.
std::vector<float> combine(const DenoiseBuffers& in, const GuidePlanes& g, const Candidates& c, int threads) {
  const int w = in.width, h = in.height;
  const size_t pixels = size_t(w) * size_t(h);
  std::vector<float> least(pixels);
  std::vector<uint8_t> choice(pixels, 0);
  for (int b = 0; b < Candidates::kCount; ++b) {
    const std::vector<float> error = box_filter(c.error[b], w, h, kErrorRadius, threads);
    for (size_t i = 0; i < pixels; ++i)
      if (b == 0 || error[i] < least[i]) least[i] = error[i], choice[i] = uint8_t(b);
  }
  std::vector<float> out(in.color.size());
  parallel_for(h, threads, [&](int y, int) {
    const int y0 = std::max(0, y - kSelectionRadius), y1 = std::min(h - 1, y + kSelectionRadius);
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * size_t(w) + size_t(x);
      if (noise_free(g, x, y)) {
        for (size_t ch = 0; ch < 3; ++ch) out[3 * i + ch] = in.color[3 * i + ch];
        continue;
      }
      const int x0 = std::max(0, x - kSelectionRadius), x1 = std::min(w - 1, x + kSelectionRadius);
      int count[Candidates::kCount] = {};
      for (int v = y0; v <= y1; ++v)
        for (int u = x0; u <= x1; ++u) ++count[choice[size_t(v) * size_t(w) + size_t(u)]];
      float sum[3] = {};
      for (int b = 0; b < Candidates::kCount; ++b) {
        if (count[b] == 0) continue;
        for (size_t ch = 0; ch < 3; ++ch)
          sum[ch] += float(count[b]) * (b < Candidates::kFiltered ? c.color[b][ch][i] : in.color[3 * i + ch]);
      }
      const float area = float((x1 - x0 + 1) * (y1 - y0 + 1));
      // (Never below zero where the noisy colour is not: a hostile half-buffer, -3e38 at
      // one pixel, could pull a candidate's fit negative around it.)
      for (size_t ch = 0; ch < 3; ++ch)
        out[3 * i + ch] = in.color[3 * i + ch] >= 0 ? std::max(0.f, sum[ch] / area) : sum[ch] / area;
    }
  });
  return out;
}

// The power of two that brings the colours' largest magnitude to at most 2^40, or 1 where
// it is there already. The filters square differences of colours and sum them over windows:
// past about 2^63 (a light of 1e20) a variance overflowed float, every weight became 0 and
// the image was denoised to black. Scaling by a power of two is exact (short of subnormals),
// and an image within the bound is not touched.
float range_scale(const DenoiseBuffers& in) {
  float largest = 0;
  for (const std::vector<float>* v : {&in.color, &in.even, &in.odd})
    for (const float x : *v) largest = std::max(largest, std::fabs(x));
  if (largest <= kMaxDenoisedMagnitude) return 1;
  int e = 0;
  std::frexp(largest, &e);  // largest < 2^e
  return std::ldexp(1.0f, std::ilogb(kMaxDenoisedMagnitude) - e);
}

std::vector<float> denoise_in_range(const DenoiseBuffers& in, const DenoiseOptions& options) {
  const int threads = options.threads > 0 ? options.threads : std::max(1, int(std::thread::hardware_concurrency()));
  const GuidePlanes g = prepare(in, threads);
  bool any_noise = false;
  for (int y = 0; y < in.height && !any_noise; ++y)
    for (int x = 0; x < in.width && !any_noise; ++x) any_noise = !noise_free(g, x, y);
  if (!any_noise) return in.color;
  return combine(in, g, nfor::regress(g, threads, options.wide_lanes), threads);
}

}  // namespace

std::vector<float> denoise(const DenoiseBuffers& in, const DenoiseOptions& options) {
  validate(in);
  const float scale = range_scale(in);
  if (scale == 1) return denoise_in_range(in, options);
  DenoiseBuffers scaled = in;
  for (std::vector<float>* v : {&scaled.color, &scaled.even, &scaled.odd})
    for (float& x : *v) x *= scale;
  std::vector<float> out = denoise_in_range(scaled, options);
  for (float& x : out) x /= scale;  // (exact: a power of two)
  return out;
}

uint64_t denoise_working_bytes(int width, int rows) {
  // The guide planes on their grid (GuidePlanes: 2 x 3 halves, 3 variances, the features,
  // `inside`), and per pixel the buffers, the candidates, their errors and the temporaries.
  constexpr uint64_t kGridPlanes = 6 + 3 + nfor::kFeatures + 1,
                     kPixelFloats = 22;  // (docs/denoise.md: 155 bytes a pixel)
  const nfor::Grid grid(width, rows);
  return sizeof(float) * (kGridPlanes * grid.size() + kPixelFloats * uint64_t(width) * uint64_t(rows));
}

}  // namespace tessera
