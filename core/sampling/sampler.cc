// The sampler's batches: four consecutive dimensions of one sample at once (sampler.h).
#include "core/sampling/sampler.h"

#include <immintrin.h>

namespace tessera::sampler_batch {

// (Not inlined into fill: its registers would be saved on the AVX2 path too.)
[[gnu::noinline]] void fill_scalar(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y) {
  for (uint32_t k = 0; k < kDimensions; ++k) {
    const Vec2 v = Sampler::value_at(key, reversed_index, d + k);
    x[k] = v.x;
    y[k] = v.y;
  }
}

namespace {

// a * c modulo 2^64 in each 64-bit lane (AVX2 multiplies 32 x 32 -> 64 bits).
[[gnu::target("avx2")]] inline __m256i mul64(__m256i a, uint64_t c) {
  const __m256i c_lo = _mm256_set1_epi64x(int64_t(c & 0xFFFFFFFFu)), c_hi = _mm256_set1_epi64x(int64_t(c >> 32));
  const __m256i cross = _mm256_add_epi64(_mm256_mul_epu32(_mm256_srli_epi64(a, 32), c_lo), _mm256_mul_epu32(a, c_hi));
  return _mm256_add_epi64(_mm256_mul_epu32(a, c_lo), _mm256_slli_epi64(cross, 32));
}

// mix64 (hash.h) in each 64-bit lane.
[[gnu::target("avx2")]] inline __m256i mix64x4(__m256i z) {
  z = mul64(_mm256_xor_si256(z, _mm256_srli_epi64(z, 30)), kMix64Multipliers[0]);
  z = mul64(_mm256_xor_si256(z, _mm256_srli_epi64(z, 27)), kMix64Multipliers[1]);
  return _mm256_xor_si256(z, _mm256_srli_epi64(z, 31));
}

// laine_karras_permutation in each 32-bit lane.
[[gnu::target("avx2")]] inline __m256i laine_karras8(__m256i x, __m256i seed) {
  x = _mm256_add_epi32(x, seed);
  for (const uint32_t m : kLaineKarrasMultipliers)
    x = _mm256_xor_si256(x, _mm256_mullo_epi32(x, _mm256_set1_epi32(int32_t(m))));
  return x;
}

// reverse_bits in each 32-bit lane: the bytes' order by a shuffle, each byte's bits by a
// 16-entry table of reversed nibbles.
[[gnu::target("avx2")]] inline __m256i reverse_bits8(__m256i x) {
  const __m256i byte_order = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6, 5,
                                              4, 11, 10, 9, 8, 15, 14, 13, 12);
  const __m256i nibble =
      _mm256_setr_epi8(0x0, 0x8, 0x4, 0xC, 0x2, 0xA, 0x6, 0xE, 0x1, 0x9, 0x5, 0xD, 0x3, 0xB, 0x7, 0xF, 0x0, 0x8, 0x4,
                       0xC, 0x2, 0xA, 0x6, 0xE, 0x1, 0x9, 0x5, 0xD, 0x3, 0xB, 0x7, 0xF);
  const __m256i low4 = _mm256_set1_epi8(0x0F);
  x = _mm256_shuffle_epi8(x, byte_order);
  const __m256i lo = _mm256_shuffle_epi8(nibble, _mm256_and_si256(x, low4));
  const __m256i hi = _mm256_shuffle_epi8(nibble, _mm256_and_si256(_mm256_srli_epi16(x, 4), low4));
  return _mm256_or_si256(_mm256_slli_epi16(lo, 4), hi);  // (lo < 16: nothing crosses a byte)
}

// sobol_dim1_reversed(r) = Z(reverse_bits(r)), Z the superset transform over GF(2): bit k of
// Z(y) is the XOR of the bits j of y whose binary digits include k's (Lucas: C(j, k) is odd,
// the Pascal matrix that generates Sobol's second dimension). Tested against the table.
[[gnu::target("avx2")]] inline __m256i superset_xor8(__m256i y) {
  y = _mm256_xor_si256(y, _mm256_srli_epi32(_mm256_and_si256(y, _mm256_set1_epi32(int32_t(0xAAAAAAAAu))), 1));
  y = _mm256_xor_si256(y, _mm256_srli_epi32(_mm256_and_si256(y, _mm256_set1_epi32(int32_t(0xCCCCCCCCu))), 2));
  y = _mm256_xor_si256(y, _mm256_srli_epi32(_mm256_and_si256(y, _mm256_set1_epi32(int32_t(0xF0F0F0F0u))), 4));
  y = _mm256_xor_si256(y, _mm256_srli_epi32(_mm256_and_si256(y, _mm256_set1_epi32(int32_t(0xFF00FF00u))), 8));
  return _mm256_xor_si256(y, _mm256_srli_epi32(y, 16));  // (y & 0xFFFF0000) >> 16 == y >> 16
}

// Sampler::value_at for dimensions d .. d + 3: the four seeds' hashes in 64-bit lanes, then
// the eight coordinates in 32-bit lanes (x of the four dimensions low, y high).
[[gnu::target("avx2")]] void fill_avx2_impl(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y) {
  const auto seed = [&](uint32_t k) {
    return int64_t(key ^ (uint64_t(uint32_t(d + k)) * Sampler::kDimensionMultiplier));
  };
  const __m256i h = mix64x4(_mm256_setr_epi64x(seed(0), seed(1), seed(2), seed(3)));
  const __m256i h2 = mix64x4(h);
  // Low halves of the 64-bit lanes into the low 128 bits, high halves into the high ones.
  const __m256i halves = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  const __m256i hs = _mm256_permutevar8x32_epi32(h, halves), h2s = _mm256_permutevar8x32_epi32(h2, halves);
  const __m128i h_lo = _mm256_castsi256_si128(hs), h_hi = _mm256_extracti128_si256(hs, 1);
  const __m128i h2_lo = _mm256_castsi256_si128(h2s);
  // r = LK(reversed index, low(h)) in four lanes (the eight-lane form, upper half unused).
  const __m256i r = laine_karras8(_mm256_set1_epi32(int32_t(reversed_index)), _mm256_castsi128_si256(h_lo));
  const __m128i r4 = _mm256_castsi256_si128(r);
  // x: reverse_low24(r >> 8) = reverse(r >> 8) >> 8; y: sobol_dim1_reversed(r).
  const __m256i rev = reverse_bits8(_mm256_set_m128i(r4, _mm_srli_epi32(r4, 8)));
  const __m256i w = _mm256_blend_epi32(_mm256_srli_epi32(rev, 8), superset_xor8(rev), 0xF0);
  const __m256i u = laine_karras8(w, _mm256_set_m128i(h2_lo, h_hi));
  // unit_float24(reverse_low24(u)): exact conversions.
  const __m256 f = _mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_srli_epi32(reverse_bits8(u), 8)), _mm256_set1_ps(0x1p-24f));
  _mm_storeu_ps(x, _mm256_castps256_ps128(f));
  _mm_storeu_ps(y, _mm256_extractf128_ps(f, 1));
}

bool cpu_has_avx2() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2");
}

const bool kHasAvx2 = cpu_has_avx2();

}  // namespace

bool fill_avx2(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y) {
  if (!kHasAvx2) return false;
  fill_avx2_impl(key, reversed_index, d, x, y);
  return true;
}

void fill(uint64_t key, uint32_t reversed_index, uint32_t d, float* x, float* y) {
  if (kHasAvx2)
    fill_avx2_impl(key, reversed_index, d, x, y);
  else
    fill_scalar(key, reversed_index, d, x, y);
}

}  // namespace tessera::sampler_batch
