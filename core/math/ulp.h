// One-ulp steps of a float, as integer operations (std::nextafter is an out-of-line libm
// call, and the ray offsets take six of them a vertex).
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

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

}  // namespace tessera
