// Unsigned sums and products that stop at the type's maximum instead of wrapping: for
// totals made of numbers a request chose (samples x frames, bytes), so that a limit's
// check sees "too many", never a wrapped small number.
#pragma once

#include <cstdint>
#include <limits>

namespace tessera {

constexpr uint64_t saturating_add(uint64_t a, uint64_t b) {
  uint64_t r = 0;
  return __builtin_add_overflow(a, b, &r) ? std::numeric_limits<uint64_t>::max() : r;
}

constexpr uint64_t saturating_mul(uint64_t a, uint64_t b) {
  uint64_t r = 0;
  return __builtin_mul_overflow(a, b, &r) ? std::numeric_limits<uint64_t>::max() : r;
}

}  // namespace tessera
