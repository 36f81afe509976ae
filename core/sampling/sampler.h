// Deterministic low-discrepancy sampler: every number is a pure function of
// (seed, pixel, sample index, dimension).
//
// Each dimension (or pair of dimensions) is an Owen-scrambled Sobol (0,2)-sequence whose
// sample order is shuffled per pixel and dimension ("padding", Burley 2020, "Practical
// Hash-based Owen Scrambling"). This keeps the stratification of Sobol in every 2D
// projection we use without the correlation of a single high-dimensional sequence, needs
// no tables, and makes the value of a sample independent of which thread, tile or machine
// draws it. That is what lets the farm merge buffers bit-identically.
#pragma once

#include <cstdint>

#include "core/math/hash.h"
#include "core/math/vec.h"

namespace tessera {

constexpr uint32_t reverse_bits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);
  return __builtin_bswap32(x);  // (each byte is reversed: reverse their order)
}

// Laine-Karras style permutation: bit i of the result depends only on bits <= i of x.
// (Its multipliers are shared with the AVX2 form, sampler.cc; all even, so each step
// keeps the property.)
inline constexpr uint32_t kLaineKarrasMultipliers[4] = {0x6c50b47cu, 0xb82f1e52u, 0xc7afe638u, 0x8d22f6e6u};
inline uint32_t laine_karras_permutation(uint32_t x, uint32_t seed) {
  x += seed;
  for (const uint32_t m : kLaineKarrasMultipliers) x ^= x * m;
  return x;
}

// Owen (nested uniform) scrambling of a 32-bit fixed-point number in [0,1).
inline uint32_t nested_uniform_scramble(uint32_t x, uint32_t seed) {
  return reverse_bits(laine_karras_permutation(reverse_bits(x), seed));
}

// Second Sobol dimension (the first is reverse_bits(i)), bit by bit: the definition.
constexpr uint32_t sobol_dim1_reference(uint32_t i) {
  uint32_t v = 1u << 31, r = 0;
  for (; i; i >>= 1, v ^= v >> 1)
    if (i & 1) r ^= v;
  return r;
}

// The map is linear over GF(2), so it is the XOR of one table entry per input byte.
// Shuffled indices use all 32 bits; this is 4 lookups instead of 32 iterations.
// The sampler works on bit-reversed values (see Sampler), so the table holds
// reverse(sobol_dim1(reverse(x))), which is just as linear.
struct SobolDim1Table {
  uint32_t t[4][256];
  uint32_t rev[4][256];
  constexpr SobolDim1Table() : t(), rev() {
    for (int b = 0; b < 4; ++b)
      for (uint32_t v = 0; v < 256; ++v) {
        t[b][v] = sobol_dim1_reference(v << (8 * b));
        rev[b][v] = reverse_bits(sobol_dim1_reference(reverse_bits(v << (8 * b))));
      }
  }
};
inline constexpr SobolDim1Table kSobolDim1Table{};

inline uint32_t sobol_dim1(uint32_t i) {
  const auto& t = kSobolDim1Table.t;
  return t[0][i & 255] ^ t[1][(i >> 8) & 255] ^ t[2][(i >> 16) & 255] ^ t[3][i >> 24];
}

// reverse_bits(sobol_dim1(reverse_bits(r))).
inline uint32_t sobol_dim1_reversed(uint32_t r) {
  const auto& t = kSobolDim1Table.rev;
  return t[0][r & 255] ^ t[1][(r >> 8) & 255] ^ t[2][(r >> 16) & 255] ^ t[3][r >> 24];
}

// reverse_bits(x) >> 8: the low 24 bits of x reversed, as a 24-bit number, by three lookups
// in a table of reversed bytes. The sampler needs no more of a reversal than that: its
// floats keep the top 24 bits of a reversed number, and the Laine-Karras permutation's low
// 24 bits depend only on its input's low 24 bits, which are a reversal's top 24.
struct ByteReversalTable {
  uint8_t r[256];
  constexpr ByteReversalTable() : r() {
    for (uint32_t v = 0; v < 256; ++v) r[v] = uint8_t(reverse_bits(v) >> 24);
  }
};
inline constexpr ByteReversalTable kByteReversal{};
inline uint32_t reverse_low24(uint32_t x) {
  const auto& t = kByteReversal.r;
  return (uint32_t(t[x & 255]) << 16) | (uint32_t(t[(x >> 8) & 255]) << 8) | t[(x >> 16) & 255];
}

// A 24-bit number as a float in [0, 1): exact (24 bits fit the significand), so the largest
// is the largest float below 1 and no clamp is needed.
constexpr float unit_float24(uint32_t v) { return float(v) * 0x1p-24f; }
static_assert(unit_float24((1u << 24) - 1) == 0x1.fffffep-1f);

// One sample's 2D values of four consecutive dimensions at once: x[k], y[k] of dimension
// d + k, exactly what the one-at-a-time form (Sampler::value_at) gives. Integer arithmetic
// and an exact conversion, so every implementation has the same bits.
namespace sampler_batch {
constexpr uint32_t kDimensions = 4;
void fill_scalar(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y);
// The same with AVX2 (8 lanes: both coordinates of the four dimensions); false, writing
// nothing, where the CPU lacks AVX2.
bool fill_avx2(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y);
// The one the sampler uses: AVX2 where the CPU has it.
void fill(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y);
}  // namespace sampler_batch

class Sampler {
 public:
  // The first two batches now (every sample draws them): the first draw waits for nothing.
  Sampler(uint64_t seed, uint64_t pixel, uint32_t sample_index)
      : key_(pixel_key(seed, pixel)), reversed_index_(reverse_bits(sample_index)) {
    fill_from(1);
  }
  // The key of a pixel's samples (value_at's key).
  static uint64_t pixel_key(uint64_t seed, uint64_t pixel) { return mix64(seed * 0x9E3779B97F4A7C15ull + pixel); }

  // A 1D draw is the first coordinate of its dimension's 2D value.
  float next_1d() { return value(++dim_).x; }
  Vec2 next_2d() { return value(++dim_); }

  uint32_t dimension() const { return dim_; }
  // The next draw uses dimension d + 1 (dimensions are independent: any order is fine).
  void set_dimension(uint32_t d) { dim_ = d; }

  // Dimension d's 2D value of this sample, computed alone: the definition the batches
  // reproduce. Written in the bit-reversed domain, where Owen scrambling is a plain
  // Laine-Karras permutation. With r = LK(reverse(i)) the shuffled index is j = reverse(r);
  // scrambled dimension 0 is reverse(LK(j)) and dimension 1 a table lookup on r. Equal to
  // nested_uniform_scramble(sobol_d(nested_uniform_scramble(i, s0)), s_d) of the textbook
  // form (tested), with 3 bit reversals per 2D draw instead of 6.
  // Each reversal is a 24-bit table one (reverse_low24): the same bits as the full ones
  // (tested against them).
  static Vec2 value_at(uint64_t key, uint32_t reversed_index, uint32_t d) {
    const uint64_t h = dimension_hash(key, d);
    const uint64_t h2 = mix64(h);
    const uint32_t r = laine_karras_permutation(reversed_index, uint32_t(h));
    return {unit_float24(reverse_low24(laine_karras_permutation(reverse_low24(r >> 8), uint32_t(h >> 32)))),
            unit_float24(reverse_low24(laine_karras_permutation(sobol_dim1_reversed(r), uint32_t(h2))))};
  }
  // 64 well-mixed bits per (pixel key, dimension): the scrambling seeds.
  static constexpr uint64_t kDimensionMultiplier = 0xD1B54A32D192ED03ull;
  static uint64_t dimension_hash(uint64_t key, uint32_t d) { return mix64(key ^ (uint64_t(d) * kDimensionMultiplier)); }

 private:
  // Draws come from batches of kBatch consecutive dimensions, computed together (a vertex
  // of a path draws three or four): about half the instructions of computing them one by
  // one. Two batches are held, and the one after is computed as soon as a draw enters the
  // second: a batch is a chain of dependent multiplies, and computed ahead, while the path
  // goes on, nobody waits for it (5% of CBspheres' render time). A dimension's value does
  // not depend on which batch computed it.
  Vec2 value(uint32_t d) {
    uint32_t k = d - first_;
    if (k >= 2 * kBatch) {  // a jump (a split's own dimensions)
      fill_from(d);
      k = 0;
    }
    const Vec2 v{x_[k], y_[k]};
    if (k == kBatch) {  // into the second batch: it becomes the first, the next one now
      for (uint32_t i = 0; i < kBatch; ++i) x_[i] = x_[kBatch + i], y_[i] = y_[kBatch + i];
      first_ += kBatch;
      sampler_batch::fill(key_, reversed_index_, first_ + kBatch, x_ + kBatch, y_ + kBatch);
    }
    return v;
  }
  void fill_from(uint32_t d) {
    sampler_batch::fill(key_, reversed_index_, d, x_, y_);
    sampler_batch::fill(key_, reversed_index_, d + kBatch, x_ + kBatch, y_ + kBatch);
    first_ = d;
  }

  uint64_t key_;
  uint32_t reversed_index_;
  uint32_t dim_ = 0;
  static constexpr uint32_t kBatch = sampler_batch::kDimensions;
  uint32_t first_ = 0;  // x_[k], y_[k] hold dimension first_ + k (modulo 2^32, as dimensions)
  float x_[2 * kBatch], y_[2 * kBatch];
};

}  // namespace tessera
