#include "core/denoise/regression.h"

// The 8-lane kernels return 32-byte vectors from functions that are always inlined into
// AVX2 code, so the ABI change GCC warns of (a by-value AVX vector crossing a call compiled
// without AVX) never happens. Ignored for the whole file: templates are instantiated at its end.
#pragma GCC diagnostic ignored "-Wpsabi"

#include <memory>

#include "core/denoise/parallel.h"
#include "core/denoise/regression_kernels.h"

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define NFOR_HAS_AVX2_KERNELS 1
#endif

namespace tessera {
namespace nfor {

Grid::Grid(int w, int h) : width(w), height(h) {
  const int tiles_w = (w + kTileWidth - 1) / kTileWidth * kTileWidth;
  const int tiles_h = (h + kTileHeight - 1) / kTileHeight * kTileHeight;
  stride = kMargin + tiles_w + kDistanceCols;  // the last tile's weight maps read up to kDistanceCols past it
  rows = kMargin + tiles_h + kMargin;
}

namespace {

// One function per lane width, the whole tile kernel inlined into each.
void filter_tile_4(const GuidePlanes& in, int x, int y, Scratch<Lanes4>& s, Candidates& out) {
  filter_tile<Lanes4>(in, x, y, s, out);
}
#ifdef NFOR_HAS_AVX2_KERNELS
__attribute__((target("avx2"))) void filter_tile_8(const GuidePlanes& in, int x, int y, Scratch<Lanes8>& s,
                                                   Candidates& out) {
  filter_tile<Lanes8>(in, x, y, s, out);
}
#endif

template <typename V>
void filter_tiles(const GuidePlanes& in, int threads,
                  void (*filter)(const GuidePlanes&, int, int, Scratch<V>&, Candidates&), Candidates& out) {
  const Grid& g = in.grid;
  const int tiles_x = (g.width + kTileWidth - 1) / kTileWidth, tiles_y = (g.height + kTileHeight - 1) / kTileHeight;
  std::vector<std::unique_ptr<Scratch<V>>> scratch(static_cast<size_t>(threads));
  parallel_for(tiles_x * tiles_y, threads, [&](int tile, int thread) {
    std::unique_ptr<Scratch<V>>& mine = scratch[size_t(thread)];
    if (!mine) mine = std::make_unique<Scratch<V>>();
    filter(in, tile % tiles_x * kTileWidth, tile / tiles_x * kTileHeight, *mine, out);
  });
}

}  // namespace

Candidates regress(const GuidePlanes& in, int threads, bool wide) {
  const size_t pixels = size_t(in.grid.width) * size_t(in.grid.height);
  Candidates out;
  for (int b = 0; b < Candidates::kFiltered; ++b)
    for (auto& plane : out.color[b]) plane.resize(pixels);
  for (auto& plane : out.error) plane.resize(pixels);
#ifdef NFOR_HAS_AVX2_KERNELS
  if (wide && __builtin_cpu_supports("avx2")) {
    filter_tiles<Lanes8>(in, threads, filter_tile_8, out);
    return out;
  }
#endif
  (void)wide;
  filter_tiles<Lanes4>(in, threads, filter_tile_4, out);
  return out;
}

}  // namespace nfor
}  // namespace tessera
