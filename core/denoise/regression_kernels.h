// The candidate filters' per-tile kernels (internal to core/denoise, included by
// regression.cc only), templated on the SIMD lane type V and always inlined into one
// function per lane width, so that the 8-lane copy is compiled for AVX2.
//
// A tile is filtered in two steps. First the NL-means weights of every pixel of the tile
// against every offset of the window, on each half, by box sums of per-pixel distances.
// Then, kWidth<V> pixels of a row at a time, the regression: a row of the window's design
// (feature differences, colours, weights) laid out, its terms added to the normal equations
// of the four filters (sums held in registers), those of the central 7 x 7 kept apart too,
// and at the end the intercepts solved for, over the whole window and over its centre.
#pragma once

#include <utility>
#include <vector>

#include "core/denoise/lanes.h"
#include "core/denoise/regression.h"

namespace tessera {
namespace nfor {

constexpr int kWindow = 2 * kWindowRadius + 1;
constexpr int kOffsets = kWindow * kWindow;
constexpr int kPatch = 2 * kPatchRadius + 1;
constexpr int round_up_to_lanes(int n) { return (n + kMaxLanes - 1) / kMaxLanes * kMaxLanes; }

// The NL-means distance is symmetric, so d(p, p - o) = d(p - o, p): the weights at offset -o
// are those at o, read at p - o. Offsets from the window's first one to its centre get a
// weight map each, over the tile and the tile shifted by -o; the other half of the window
// reads them. A map's columns are rounded up to whole lanes of the widest kind.
constexpr int kMaps = kOffsets / 2 + 1;
constexpr int kMapRows = kTileHeight + kWindowRadius;
constexpr int kMapCols = round_up_to_lanes(kTileWidth + kWindowRadius);
constexpr int kMapSize = kMapRows * kMapCols;
// Per-pixel distances a map's patches cover: its rows and columns and a patch radius around.
constexpr int kDistanceRows = kMapRows + 2 * kPatchRadius;
constexpr int kDistanceCols = round_up_to_lanes(kMapCols + 2 * kPatchRadius);

// NL-means distances (Rousselle et al. 2012, eq. 7): the squared difference less the part
// the noise explains, over the noise, averaged over the channels and the patch. Made
// symmetric (2 min(var p, var q) cancelled rather than var p + min(var p, var q)) so that
// the weight of (p, q) is the weight of (q, p).
constexpr float kVarianceEpsilon = 1e-10f;  // noise-free against noise-free: 0 / 0 counts as no difference
constexpr float kDistanceClamp = 1e4f;      // one noise-free mismatch already rules a neighbour out; stays finite
constexpr float kPatchScale = 1.f / (3 * kPatch * kPatch);
constexpr float kStoredK = 1;  // the weight maps' NL-means bandwidth, the wider candidate's (the other's is 0.5)

// The regression's unknowns: the colour's slope along each feature, then its value at the
// pixel, the intercept: last, so that eliminating the others leaves it alone in the last row.
// No slopes along screen x and y (NFOR has them): in a window this small, two more unknowns
// cost more variance than the gradients they follow are worth.
constexpr int kUnknowns = kFeatures + 1;
constexpr int kIntercept = kUnknowns - 1;
constexpr int kFilters = 4;  // [half filtered: even, odd][NL-means bandwidth k = 0.5, 1]

// A design row's columns are stored centre first, so that the central 7 x 7's terms are a
// contiguous run: window column i (offset dx = i - kWindowRadius) is at slot_of(i).
constexpr int kInner = 2 * kInnerRadius + 1;
constexpr int slot_of(int i) {
  const int dx = i - kWindowRadius;
  return dx < -kInnerRadius ? kInner + i : dx > kInnerRadius ? i : dx + kInnerRadius;
}

// Ridge on the slopes, relative to their own diagonal entry (scale-free: a feature's units
// do not matter) plus a little of the weight sum (so that a feature constant over the
// window, the background's or a flat albedo's, gets slope 0 instead of 0 / 0).
constexpr float kRidgeRelative = 1e-2f;
constexpr float kRidgeAbsolute = 1e-4f;
constexpr float kTiny = 1e-30f;  // pivots of pixels off the image (their lanes are not written)

// One pixel group's regression data over one row of the window (a row at a time keeps it in
// L1), by slot: the unknowns' coefficients (feature differences, 1), the neighbour's colour
// in each half, the filters' weights.
template <typename V>
struct Design {
  V x[kWindow][kFeatures];  // the intercept's 1 is implied
  V color[kWindow][6];      // even r, g, b, odd r, g, b
  V weight[kFilters][kWindow];
};

template <typename V>
struct Scratch {
  std::vector<float> patch_weight[2];  // [guide half][map][kMapRows][kMapCols]: exp(-max(0, distance) / k^2), k = 1
  std::vector<float> distance[2];      // [kDistanceRows][kDistanceCols] for the current map
  std::vector<float> row_sum[2];       // [kDistanceRows][kMapCols]: distances summed across the patch
  Design<V> design;

  Scratch() {
    for (int h = 0; h < 2; ++h) {
      patch_weight[h].resize(size_t(kMaps) * kMapSize);
      distance[h].resize(size_t(kDistanceRows) * kDistanceCols);
      row_sum[h].resize(size_t(kDistanceRows) * kMapCols);
    }
  }
};

NFOR_INLINE int dx_of(int offset) { return offset % kWindow - kWindowRadius; }
NFOR_INLINE int dy_of(int offset) { return offset / kWindow - kWindowRadius; }
NFOR_INLINE ptrdiff_t shift_of(const Grid& g, int offset) {
  return ptrdiff_t(dy_of(offset)) * g.stride + dx_of(offset);
}

// Where the weights at `offset` of the tile's pixel (0, 0) are in the maps: map o's region
// starts max(0, dx), max(0, dy) up and left of the tile; offset -o reads it at p - (-o).
NFOR_INLINE size_t map_base(int offset) {
  const int map = offset < kMaps ? offset : kOffsets - 1 - offset;
  const int dx = dx_of(offset), dy = dy_of(offset);
  return size_t(map) * kMapSize + size_t((dy > 0 ? dy : 0) * kMapCols + (dx > 0 ? dx : 0));
}

// The NL-means weight maps, on each half: each pixel's patch against the patch at offset o,
// over the tile and the tile shifted by -o (box sums: per-pixel distances, then across rows,
// then down).
template <typename V>
NFOR_INLINE void compute_patch_weights(const GuidePlanes& in, int tx0, int ty0, Scratch<V>& s) {
  constexpr int kW = kWidth<V>;
  constexpr float kScale = kPatchScale / (kStoredK * kStoredK);
  const Grid& g = in.grid;
  for (int o = 0; o < kMaps; ++o) {
    const int dx = dx_of(o), dy = dy_of(o);
    const int x0 = tx0 - (dx > 0 ? dx : 0), y0 = ty0 - (dy > 0 ? dy : 0);  // the map's region
    const int rows = kTileHeight + (dy < 0 ? -dy : dy), cols = round_up_to_lanes(kTileWidth + (dx < 0 ? -dx : dx));
    const int distance_rows = rows + 2 * kPatchRadius, distance_cols = round_up_to_lanes(cols + 2 * kPatchRadius);
    const ptrdiff_t shift = shift_of(g, o);
    for (int row = 0; row < distance_rows; ++row) {
      const size_t start = g.at(x0 - kPatchRadius, y0 - kPatchRadius + row);
      for (int x = 0; x < distance_cols; x += kW) {
        const size_t p = start + size_t(x), q = size_t(ptrdiff_t(p) + shift);
        V d[2] = {};
        for (int c = 0; c < 3; ++c) {
          const V vp = load<V>(&in.variance[c][p]), vq = load<V>(&in.variance[c][q]);
          const V cancel = 2.f * min<V>(vp, vq), norm = 1.f / (vp + vq + kVarianceEpsilon);
          for (int h = 0; h < 2; ++h) {
            const V diff = load<V>(&in.half[h][c][p]) - load<V>(&in.half[h][c][q]);
            d[h] += (diff * diff - cancel) * norm;
          }
        }
        for (int h = 0; h < 2; ++h)
          store<V>(&s.distance[h][size_t(row * kDistanceCols + x)], min<V>(d[h], splat<V>(kDistanceClamp)));
      }
    }
    for (int h = 0; h < 2; ++h) {
      for (int row = 0; row < distance_rows; ++row)
        for (int x = 0; x < cols; x += kW) {
          const float* t = &s.distance[h][size_t(row * kDistanceCols + x)];
          V sum = load<V>(t);
#pragma GCC unroll 8
          for (int i = 1; i < kPatch; ++i) sum += load<V>(t + i);
          store<V>(&s.row_sum[h][size_t(row * kMapCols + x)], sum);
        }
      float* out = &s.patch_weight[h][size_t(o) * kMapSize];
      for (int y = 0; y < rows; ++y)
        for (int x = 0; x < cols; x += kW) {
          const float* t = &s.row_sum[h][size_t(y * kMapCols + x)];
          V sum = load<V>(t);
#pragma GCC unroll 8
          for (int i = 1; i < kPatch; ++i) sum += load<V>(t + i * kMapCols);
          store<V>(out + y * kMapCols + x, exp_nonpositive<V>(-max<V>(sum * kScale, V{})));
        }
    }
  }
}

// The design of the kWidth<V> pixels from (x, y) on (`pixel` their index in a weight map) over
// row `dy` of the window.
template <typename V>
NFOR_INLINE void build_design(const GuidePlanes& in, const Scratch<V>& s, int x, int y, int pixel, int dy,
                              Design<V>& d) {
  const Grid& g = in.grid;
  const size_t p = g.at(x, y);
  V center[kFeatures];
#pragma GCC unroll 8
  for (int j = 0; j < kFeatures; ++j) center[j] = load<V>(&in.feature[j][p]);
  for (int i = 0; i < kWindow; ++i) {
    const int o = (dy + kWindowRadius) * kWindow + i, slot = slot_of(i);
    const size_t q = size_t(ptrdiff_t(p) + shift_of(g, o));
    V feature_distance = {};
#pragma GCC unroll 8
    for (int j = 0; j < kFeatures; ++j) {
      const V diff = load<V>(&in.feature[j][q]) - center[j];
      d.x[slot][j] = diff;
      feature_distance += diff * diff;  // the features are in units of their bandwidths
    }
    for (int h = 0; h < 2; ++h)
      for (int c = 0; c < 3; ++c) d.color[slot][3 * h + c] = load<V>(&in.half[h][c][q]);
    const V feature_weight = exp_nonpositive<V>(-feature_distance) * load<V>(&in.inside[q]);
    for (int h = 0; h < 2; ++h) {
      // Half h is filtered with the other half's patch weights (cross-filtering). They are
      // kept at k = 1; k = 0.5 multiplies the distance by 4, which raises the weight to the 4th power.
      const V w = load<V>(&s.patch_weight[1 - h][map_base(o) + size_t(pixel)]);
      const V w2 = w * w;
      d.weight[2 * h][slot] = w2 * w2 * feature_weight;
      d.weight[2 * h + 1][slot] = w * feature_weight;
    }
  }
}

// The weighted normal equations of one filter: N = sum w x x^T (upper triangle), R = sum w x c^T.
template <typename V>
struct NormalEquations {
  V n[kUnknowns][kUnknowns];
  V r[kUnknowns][3];
};

// Adds the terms of the design's slots [Begin, End) to row I of N and R, the sums held in
// registers meanwhile. The intercept's coefficient is 1: its column adds the weight times
// x_I, and its row the weight.
template <typename V, int Begin, int End, int I>
NFOR_INLINE void accumulate_row(const Design<V>& d, int filter, NormalEquations<V>& eq) {
  constexpr int kCount = kUnknowns - I;
  const int color = 3 * (filter / 2);
  V sum[kCount + 3];
#pragma GCC unroll 16
  for (int j = 0; j < kCount; ++j) sum[j] = eq.n[I][I + j];
#pragma GCC unroll 4
  for (int j = 0; j < 3; ++j) sum[kCount + j] = eq.r[I][j];
  for (int o = Begin; o < End; ++o) {
    V a = d.weight[filter][o];
    if constexpr (I < kIntercept) {
      a *= d.x[o][I];
#pragma GCC unroll 16
      for (int j = 0; j < kCount - 1; ++j) sum[j] += a * d.x[o][I + j];
    }
    sum[kCount - 1] += a;
    const V* c = &d.color[o][color];
#pragma GCC unroll 4
    for (int j = 0; j < 3; ++j) sum[kCount + j] += a * c[j];
  }
#pragma GCC unroll 16
  for (int j = 0; j < kCount; ++j) eq.n[I][I + j] = sum[j];
#pragma GCC unroll 4
  for (int j = 0; j < 3; ++j) eq.r[I][j] = sum[kCount + j];
}

template <typename V, int Begin, int End, int... I>
NFOR_INLINE void accumulate(const Design<V>& d, int filter, NormalEquations<V>& eq, std::integer_sequence<int, I...>) {
  (accumulate_row<V, Begin, End, I>(d, filter, eq), ...);
}
template <typename V, int Begin, int End>
NFOR_INLINE void accumulate(const Design<V>& d, int filter, NormalEquations<V>& eq) {
  accumulate<V, Begin, End>(d, filter, eq, std::make_integer_sequence<int, kUnknowns>());
}

// eq += other: the central window's sums joined to the rest of the window's.
template <typename V>
NFOR_INLINE void add(const NormalEquations<V>& other, NormalEquations<V>& eq) {
  for (int i = 0; i < kUnknowns; ++i) {
    for (int j = i; j < kUnknowns; ++j) eq.n[i][j] += other.n[i][j];
    for (int c = 0; c < 3; ++c) eq.r[i][c] += other.r[i][c];
  }
}

// The intercept of (N + ridge) beta = R: Gaussian elimination of the slopes (N is symmetric
// positive definite with the ridge, so no pivoting), then the last row. Where that is not
// finite, or is negative though the weighted mean (the zeroth-order fit) is not, a line
// extrapolated past what the window holds, the weighted mean instead.
template <typename V>
NFOR_INLINE void solve_intercept(NormalEquations<V>& eq, V (&out)[3]) {
  const V weight_sum = max<V>(eq.n[kIntercept][kIntercept], splat<V>(kTiny));
  V mean[3];
  for (int c = 0; c < 3; ++c) mean[c] = eq.r[kIntercept][c] / weight_sum;
  V floor[kIntercept];
  for (int i = 0; i < kIntercept; ++i) {
    const V ridge = kRidgeRelative * eq.n[i][i] + kRidgeAbsolute * weight_sum;
    eq.n[i][i] += ridge;
    floor[i] = max<V>(ridge, splat<V>(kTiny));
  }
  for (int k = 0; k < kIntercept; ++k) {
    const V inverse = 1.f / max<V>(eq.n[k][k], floor[k]);
    for (int i = k + 1; i < kUnknowns; ++i) {
      const V l = eq.n[k][i] * inverse;
      for (int j = i; j < kUnknowns; ++j) eq.n[i][j] -= l * eq.n[k][j];
      for (int c = 0; c < 3; ++c) eq.r[i][c] -= l * eq.r[k][c];
    }
  }
  // With the centre's weight 1, the intercept's pivot is at least 1 in exact arithmetic.
  const V pivot = max<V>(eq.n[kIntercept][kIntercept], splat<V>(kTiny));
  for (int c = 0; c < 3; ++c) {
    const V fit = eq.r[kIntercept][c] / pivot;
    out[c] = select<V>(finite<V>(fit) & ((fit >= V{}) | (mean[c] < V{})), fit, mean[c]);
  }
}

// Each candidate's colour (the mean of its filtered halves) and the MSE estimates for the
// pixels from (x, y) on, from the filtered halves f[window][filter] (NFOR section 5.3): the
// other half as the reference, less the halves' residual difference and the reference's own
// noise. That noise is the pixel's (even - odd)^2 / 2, not the smoothed variance: it is what
// the reference's squared difference holds at this pixel (a firefly's in full), and its
// estimate for the noisy colour, (even - odd)^2 / 4, is then on the same footing (the
// noisy colour is the candidate whose filtered halves are the halves). Errors are relative
// to even x odd, whose mean is the colour squared (the halves are independent): a scale that
// no candidate's smoothing moves (the filtered colour, on a texture no feature explains,
// would be brighter than the dark pixels it blurs, and weigh their error down). It is floored
// at a quarter of the first candidate's colour squared, so that where the halves straddle 0
// (a few samples) a pixel's scale is not near 0 and its error does not outweigh the rest.
template <typename V>
NFOR_INLINE void write_candidates(const GuidePlanes& in, int x, int y, const V (&f)[2][kFilters][3], Candidates& out) {
  constexpr int kW = kWidth<V>;
  constexpr float kRelativeEpsilon = 1e-2f;  // as in relMSE: dark pixels do not dominate the error
  const Grid& g = in.grid;
  const size_t p = g.at(x, y);
  float color[Candidates::kFiltered][3][kW], error[Candidates::kCount][kW];
  V relative_mse[Candidates::kCount] = {};
  for (int c = 0; c < 3; ++c) {
    const V even = load<V>(&in.half[0][c][p]), odd = load<V>(&in.half[1][c][p]);
    const V noise = 0.5f * (even - odd) * (even - odd);
    const V first = 0.5f * (f[0][0][c] + f[0][2][c]);
    const V inverse_scale = 1.f / (max<V>(even * odd, 0.25f * first * first) + kRelativeEpsilon);
    for (int b = 0; b < Candidates::kFiltered; ++b) {
      const V fe = f[b / 2][b % 2][c], fo = f[b / 2][2 + b % 2][c];  // [window][filter: half, k]
      const V mse =
          0.5f * ((fe - odd) * (fe - odd) + (fo - even) * (fo - even)) - 0.25f * (fe - fo) * (fe - fo) - noise;
      relative_mse[b] += mse * inverse_scale;
      store<V>(color[b][c], 0.5f * (fe + fo));
    }
    relative_mse[Candidates::kFiltered] += 0.5f * noise * inverse_scale;
  }
  for (int b = 0; b < Candidates::kCount; ++b) store<V>(error[b], relative_mse[b] * (1.f / 3));
  const int count = g.width - x < kW ? g.width - x : kW;
  const size_t at = size_t(y) * size_t(g.width) + size_t(x);
  for (int l = 0; l < count; ++l) {
    for (int b = 0; b < Candidates::kFiltered; ++b)
      for (int c = 0; c < 3; ++c) out.color[b][c][at + size_t(l)] = color[b][c][l];
    for (int b = 0; b < Candidates::kCount; ++b) out.error[b][at + size_t(l)] = error[b][l];
  }
}

template <typename V>
NFOR_INLINE void filter_tile(const GuidePlanes& in, int tx0, int ty0, Scratch<V>& s, Candidates& out) {
  compute_patch_weights<V>(in, tx0, ty0, s);
  for (int ty = 0; ty < kTileHeight && ty0 + ty < in.grid.height; ++ty)
    for (int tx = 0; tx < kTileWidth && tx0 + tx < in.grid.width; tx += kWidth<V>) {
      NormalEquations<V> eq[kFilters] = {}, inner[kFilters] = {};  // the window less its centre; the centre
      for (int dy = -kWindowRadius; dy <= kWindowRadius; ++dy) {
        build_design<V>(in, s, tx0 + tx, ty0 + ty, ty * kMapCols + tx, dy, s.design);
        for (int filter = 0; filter < kFilters; ++filter)
          if (dy < -kInnerRadius || dy > kInnerRadius) {
            accumulate<V, 0, kWindow>(s.design, filter, eq[filter]);
          } else {
            accumulate<V, 0, kInner>(s.design, filter, inner[filter]);
            accumulate<V, kInner, kWindow>(s.design, filter, eq[filter]);
          }
      }
      V f[2][kFilters][3];  // [window: whole, centre][filter][channel]
      for (int filter = 0; filter < kFilters; ++filter) {
        add<V>(inner[filter], eq[filter]);
        solve_intercept<V>(eq[filter], f[0][filter]);
        solve_intercept<V>(inner[filter], f[1][filter]);
      }
      write_candidates<V>(in, tx0 + tx, ty0 + ty, f, out);
    }
}

}  // namespace nfor
}  // namespace tessera
