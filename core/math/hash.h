// 64-bit finaliser of SplitMix64 (Steele, Lea and Flood 2014): every input bit flips about
// half the output bits. The sampler's keys, the frame seeds and the alpha test's ray
// numbers all hash with it.
#pragma once

#include <cstdint>

namespace tessera {

// Its two multipliers (the AVX2 form in core/sampling/sampler.cc uses them too).
inline constexpr uint64_t kMix64Multipliers[2] = {0xbf58476d1ce4e5b9ull, 0x94d049bb133111ebull};

inline uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * kMix64Multipliers[0];
  z = (z ^ (z >> 27)) * kMix64Multipliers[1];
  return z ^ (z >> 31);
}

}  // namespace tessera
