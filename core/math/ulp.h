// One-ulp steps of a float, as integer operations (std::nextafter is an out-of-line libm
// call, and the ray offsets take six of them a vertex).
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace tessera {

inline float next_float_up(float v) {
  if (std::isinf(v) && v > 0) return v;
  if (v == -0.0f) v = 0.0f;
  uint32_t bits = std::bit_cast<uint32_t>(v);
  bits = v >= 0 ? bits + 1 : bits - 1;
  return std::bit_cast<float>(bits);
}

inline float next_float_down(float v) {
  if (std::isinf(v) && v < 0) return v;
  if (v == 0.0f) v = -0.0f;
  uint32_t bits = std::bit_cast<uint32_t>(v);
  bits = v > 0 ? bits - 1 : bits + 1;
  return std::bit_cast<float>(bits);
}

// v one ulp further along the sign of `side` (unchanged where side is 0 or NaN).
inline float step_toward(float v, float side) {
  if (side > 0) return next_float_up(v);
  if (side < 0) return next_float_down(v);
  return v;
}

// The least error to offset a ray's origin by, per axis, on a triangle whose unnormalised
// geometric normal has length `ng_len`: Embree's plane test computes 2 dot(v0 - o, Ng),
// which underflows to 0 (a hit at t = 0) for an origin a denormal off a plane through the
// origin when |Ng| < 1. 4 FLT_MIN over |Ng| (clamped to 1) keeps the product normal; see
// make_surface_point and docs/ray-offsets.md. Lights' sampled points take it too.
inline float underflow_floor(float ng_len) {
  return 4 * std::numeric_limits<float>::min() / std::clamp(ng_len, 1e-20f, 1.0f);
}

}  // namespace tessera
