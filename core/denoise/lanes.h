// SIMD lanes for the denoiser's kernels (internal to core/denoise): 4 floats (SSE2, NEON) or
// 8 (AVX2, used where the CPU has it).
//
// GCC/Clang vector extensions rather than intrinsics or the auto-vectoriser: the kernels are
// vectorised at any optimisation level and on any target, and each lane is plain IEEE float
// arithmetic (no FMA is enabled for the 8-lane code), so a pixel's result is the same bits
// whichever lane, lane width or thread computed it.
//
// Everything here is always inlined and takes vectors by reference: the kernels are
// instantiated inside functions compiled for AVX2 (target attribute), and a 32-byte vector
// passed by value across a call compiled without AVX would change the calling convention.
#pragma once

#include <cstdint>
#include <cstring>

#define NFOR_INLINE __attribute__((always_inline)) inline

namespace tessera {
namespace nfor {

typedef float Lanes4 __attribute__((vector_size(16)));
typedef float Lanes8 __attribute__((vector_size(32)));

template <typename V>
constexpr int kWidth = int(sizeof(V) / sizeof(float));
template <typename V>
using MaskOf = decltype(V{} < V{});  // what a comparison gives: int32 lanes, ~0 or 0

template <typename V>
NFOR_INLINE V load(const float* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename V>
NFOR_INLINE void store(float* p, const V& v) {
  std::memcpy(p, &v, sizeof v);
}
template <typename V>
NFOR_INLINE V splat(float x) {
  return V{} + x;
}
template <typename V>
NFOR_INLINE V select(const MaskOf<V>& m, const V& a, const V& b) {
  return (V)(((MaskOf<V>)a & m) | ((MaskOf<V>)b & ~m));
}
template <typename V>
NFOR_INLINE V min(const V& a, const V& b) {
  return select<V>(a < b, a, b);
}
template <typename V>
NFOR_INLINE V max(const V& a, const V& b) {
  return select<V>(a > b, a, b);
}
template <typename V>
NFOR_INLINE MaskOf<V> finite(const V& a) {  // false for NaN and +-inf
  return (a - a) == V{};
}

// e^x for x <= 0 (x = 0 gives exactly 1; below -87, 2^-126): 2^n times a degree-5 Taylor
// polynomial of e^r on |r| <= ln(2)/2, good to 3e-6 relative (these are filter weights).
// Branch-free, so it vectorises; libm's expf does not.
template <typename V>
NFOR_INLINE V exp_nonpositive(const V& x) {
  using Mask = MaskOf<V>;
  const V t = max<V>(x, splat<V>(-87.f)) * 1.44269504f;    // x / ln 2
  const Mask n = __builtin_convertvector(t - 0.5f, Mask);  // round(t): truncation of t - 1/2 <= 0
  const V r = (t - __builtin_convertvector(n, V)) * 0.693147181f;
  V p = splat<V>(1.f / 120);
  p = p * r + 1.f / 24;
  p = p * r + 1.f / 6;
  p = p * r + 0.5f;
  p = p * r + 1.f;
  p = p * r + 1.f;
  return p * (V)((n + 127) << 23);
}

}  // namespace nfor
}  // namespace tessera
