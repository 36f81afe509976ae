// The sampler and the warps: determinism, range, stratification, and chi-square fits.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <set>

#include "core/sampling/sampler.h"
#include "core/sampling/warp.h"
#include "tests/core/chi2.h"

namespace tessera {
namespace {

using testing::chi2_directions;
constexpr double kAlpha = 1e-3;  // significance; samples are deterministic, so no flakes

TEST(Sampler, SobolTableMatchesTheBitByBitDefinition) {
  std::mt19937 rng(7);
  for (int i = 0; i < 10000; ++i) {
    const uint32_t x = rng();
    ASSERT_EQ(sobol_dim1(x), sobol_dim1_reference(x)) << x;
  }
}

TEST(Sampler, ReversedDomainFormEqualsTheTextbookOwenScrambledSobol) {
  std::mt19937 rng(3);
  for (int k = 0; k < 10000; ++k) {
    const uint32_t i = rng() & 0xFFFF, s0 = rng(), s1 = rng(), s2 = rng();
    const uint32_t shuffled = nested_uniform_scramble(i, s0);
    const uint32_t r = laine_karras_permutation(reverse_bits(i), s0);
    ASSERT_EQ(reverse_bits(r), shuffled);
    ASSERT_EQ(nested_uniform_scramble(reverse_bits(shuffled), s1),
              reverse_bits(laine_karras_permutation(reverse_bits(r), s1)));
    ASSERT_EQ(nested_uniform_scramble(sobol_dim1(shuffled), s2),
              reverse_bits(laine_karras_permutation(sobol_dim1_reversed(r), s2)));
  }
}

// The sampler as it was written before its reversals became 24-bit table lookups: whole
// 32-bit reversals, then the top 24 bits as the float.
struct FullReversalSampler {
  uint64_t key;
  uint32_t reversed_index, dim = 0;
  FullReversalSampler(uint64_t seed, uint64_t pixel, uint32_t index)
      : key(mix64(seed * 0x9E3779B97F4A7C15ull + pixel)), reversed_index(reverse_bits(index)) {}
  static float unit(uint32_t x) { return float(x >> 8) * 0x1p-24f; }
  uint64_t hash() { return mix64(key ^ (uint64_t(++dim) * 0xD1B54A32D192ED03ull)); }
  float next_1d() {
    const uint64_t h = hash();
    const uint32_t r = laine_karras_permutation(reversed_index, uint32_t(h));
    return unit(reverse_bits(laine_karras_permutation(reverse_bits(r), uint32_t(h >> 32))));
  }
  Vec2 next_2d() {
    const uint64_t h = hash(), h2 = mix64(h);
    const uint32_t r = laine_karras_permutation(reversed_index, uint32_t(h));
    return {unit(reverse_bits(laine_karras_permutation(reverse_bits(r), uint32_t(h >> 32)))),
            unit(reverse_bits(laine_karras_permutation(sobol_dim1_reversed(r), uint32_t(h2))))};
  }
};

TEST(Sampler, TableReversalsGiveTheFullReversalsBits) {
  std::mt19937 rng(5);
  for (int k = 0; k < 100000; ++k) {
    const uint32_t x = rng();
    ASSERT_EQ(reverse_low24(x), reverse_bits(x) >> 8) << x;
  }
  for (int k = 0; k < 20000; ++k) {
    const uint64_t seed = rng(), pixel = rng();
    const uint32_t index = rng() % 100000;
    Sampler a(seed, pixel, index);
    FullReversalSampler b(seed, pixel, index);
    for (int d = 0; d < 4; ++d) {
      ASSERT_EQ(a.next_1d(), b.next_1d());
      const Vec2 va = a.next_2d(), vb = b.next_2d();
      ASSERT_EQ(va.x, vb.x);
      ASSERT_EQ(va.y, vb.y);
    }
  }
}

// Sobol's second dimension in the reversed domain as the AVX2 batch computes it (a superset
// transform of the reversed index, no table): equal to the table for every input bit.
uint32_t superset_xor(uint32_t y) {
  y ^= (y & 0xAAAAAAAAu) >> 1;
  y ^= (y & 0xCCCCCCCCu) >> 2;
  y ^= (y & 0xF0F0F0F0u) >> 4;
  y ^= (y & 0xFF00FF00u) >> 8;
  return y ^ (y >> 16);
}

TEST(Sampler, SupersetTransformIsSobolsSecondDimension) {
  for (int b = 0; b < 32; ++b) ASSERT_EQ(superset_xor(reverse_bits(1u << b)), sobol_dim1_reversed(1u << b)) << b;
  std::mt19937 rng(9);
  for (int k = 0; k < 100000; ++k) {
    const uint32_t r = rng();
    ASSERT_EQ(superset_xor(reverse_bits(r)), sobol_dim1_reversed(r)) << r;
  }
}

// The batches (scalar and AVX2) give each dimension the bits of computing it alone, at any
// dimension (the split continuations start 2^20 apart; dimensions wrap at 2^32).
TEST(Sampler, BatchesGiveTheBitsOfOneDimensionAtATime) {
  std::mt19937_64 rng(13);
  float x[sampler_batch::kDimensions], y[sampler_batch::kDimensions];
  float xa[sampler_batch::kDimensions], ya[sampler_batch::kDimensions];
  bool avx2 = false;
  for (int k = 0; k < 200000; ++k) {
    const uint64_t key = rng();
    const uint32_t reversed_index = uint32_t(rng());
    const uint32_t d = k % 7 == 0 ? uint32_t(-int(k % 5)) : k % 3 == 0 ? uint32_t(rng()) : uint32_t(k % 64);
    sampler_batch::fill_scalar(key, reversed_index, d, x, y);
    avx2 = sampler_batch::fill_avx2(key, reversed_index, d, xa, ya);
    for (uint32_t j = 0; j < sampler_batch::kDimensions; ++j) {
      const Vec2 v = Sampler::value_at(key, reversed_index, d + j);
      ASSERT_EQ(x[j], v.x) << d << " + " << j;
      ASSERT_EQ(y[j], v.y) << d << " + " << j;
      if (avx2) {
        ASSERT_EQ(xa[j], v.x) << d << " + " << j;
        ASSERT_EQ(ya[j], v.y) << d << " + " << j;
      }
    }
  }
  if (!avx2) std::printf("this CPU has no AVX2: only the scalar batch was compared\n");
}

// Through the Sampler: draws in any mix of 1D and 2D, with jumps of the dimension (as the
// split continuations make), give the values of each dimension computed alone.
TEST(Sampler, DrawsThroughTheBatchesEqualTheDefinition) {
  std::mt19937 rng(17);
  for (int k = 0; k < 20000; ++k) {
    const uint64_t seed = rng(), pixel = rng();
    const uint32_t index = rng() % 100000;
    Sampler s(seed, pixel, index);
    FullReversalSampler ref(seed, pixel, index);
    for (int draw = 0; draw < 24; ++draw) {
      if (rng() % 8 == 0) {
        const uint32_t d = rng() % 3 == 0 ? uint32_t(rng()) : s.dimension() + (rng() % 3) * (1u << 20);
        s.set_dimension(d);
        ref.dim = d;
      }
      if (rng() % 2) {
        ASSERT_EQ(s.next_1d(), ref.next_1d());
      } else {
        const Vec2 a = s.next_2d(), b = ref.next_2d();
        ASSERT_EQ(a.x, b.x);
        ASSERT_EQ(a.y, b.y);
      }
    }
  }
}

TEST(Sampler, IsAPureFunctionOfSeedPixelIndexAndDimension) {
  Sampler a(42, 1234, 17), b(42, 1234, 17), c(43, 1234, 17), d(42, 1235, 17);
  for (int k = 0; k < 8; ++k) {
    const Vec2 va = a.next_2d(), vb = b.next_2d(), vc = c.next_2d(), vd = d.next_2d();
    EXPECT_EQ(va.x, vb.x);
    EXPECT_EQ(va.y, vb.y);
    EXPECT_NE(va.x, vc.x);
    EXPECT_NE(va.x, vd.x);
  }
}

TEST(Sampler, ValuesLieInTheUnitInterval) {
  for (uint32_t i = 0; i < 4096; ++i) {
    Sampler s(1, 99, i);
    for (int k = 0; k < 6; ++k) {
      const float u = s.next_1d();
      const Vec2 v = s.next_2d();
      ASSERT_GE(u, 0.0f);
      ASSERT_LT(u, 1.0f);
      ASSERT_GE(v.x, 0.0f);
      ASSERT_LT(v.x, 1.0f);
      ASSERT_GE(v.y, 0.0f);
      ASSERT_LT(v.y, 1.0f);
    }
  }
}

// Owen-scrambled Sobol (0,2)-sequences are (0,m,2)-nets: the first 2^m points put exactly
// one point in every elementary interval of area 2^-m. Check all shapes for m = 8.
TEST(Sampler, First256PointsOfEveryDimensionPairFormA02Net) {
  const int m = 8, n = 1 << m;
  for (int dim = 0; dim < 4; ++dim) {
    std::vector<Vec2> pts;
    for (int i = 0; i < n; ++i) {
      Sampler s(5, 321, uint32_t(i));
      Vec2 v;
      for (int k = 0; k <= dim; ++k) v = s.next_2d();
      pts.push_back(v);
    }
    for (int kx = 0; kx <= m; ++kx) {
      const int nx = 1 << kx, ny = 1 << (m - kx);
      std::set<int> cells;
      for (const Vec2& p : pts) cells.insert(int(p.x * nx) * ny + int(p.y * ny));
      EXPECT_EQ(int(cells.size()), n) << "dimension pair " << dim << ", " << nx << "x" << ny << " intervals";
    }
  }
}

Vec2 uniform2(int i) {
  Sampler s(11, 0, uint32_t(i));
  return s.next_2d();
}

TEST(Warp, CosineHemisphereMatchesItsPdf) {
  const auto r = chi2_directions([](int i) { return std::optional<Vec3>(square_to_cosine_hemisphere(uniform2(i))); },
                                 [](Vec3 w) { return double(cosine_hemisphere_pdf(w.z)); }, 200000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

TEST(Warp, UniformHemisphereMatchesItsPdf) {
  const auto r = chi2_directions([](int i) { return std::optional<Vec3>(square_to_uniform_hemisphere(uniform2(i))); },
                                 [](Vec3 w) { return w.z > 0 ? double(kUniformHemispherePdf) : 0.0; }, 200000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

TEST(Warp, UniformSphereMatchesItsPdf) {
  const auto r = chi2_directions([](int i) { return std::optional<Vec3>(square_to_uniform_sphere(uniform2(i))); },
                                 [](Vec3) { return 1 / (4 * M_PI); }, 200000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

TEST(Warp, ConcentricDiskIsUniformInArea) {
  // Quadrant-and-ring histogram: each of 16 equal-area cells should get 1/16.
  const int n = 160000, rings = 4, sectors = 4;
  std::vector<int> counts(rings * sectors, 0);
  for (int i = 0; i < n; ++i) {
    const Vec2 d = square_to_concentric_disk(uniform2(i));
    const double r2 = d.x * d.x + d.y * d.y;
    ASSERT_LE(r2, 1.0 + 1e-6);
    double phi = std::atan2(d.y, d.x);
    if (phi < 0) phi += 2 * M_PI;
    counts[std::min(rings - 1, int(r2 * rings)) * sectors + std::min(sectors - 1, int(phi / (2 * M_PI) * sectors))]++;
  }
  double chi2 = 0;
  const double e = double(n) / counts.size();
  for (int c : counts) chi2 += (c - e) * (c - e) / e;
  EXPECT_GT(testing::gamma_q((counts.size() - 1) / 2.0, chi2 / 2), kAlpha) << chi2;
}

TEST(Warp, TriangleBarycentricsAreUniform) {
  const int n = 100000;
  int inside = 0;
  std::vector<int> counts(4, 0);  // the 4 sub-triangles of the midpoint subdivision
  for (int i = 0; i < n; ++i) {
    const Vec2 b = square_to_triangle(uniform2(i));
    const float b0 = 1 - b.x - b.y;
    if (b.x >= 0 && b.y >= 0 && b0 >= -1e-6f) ++inside;
    const int cell = b.x > 0.5f ? 1 : b.y > 0.5f ? 2 : b0 > 0.5f ? 0 : 3;
    counts[cell]++;
  }
  EXPECT_EQ(inside, n);
  double chi2 = 0;
  for (int c : counts) chi2 += (c - n / 4.0) * (c - n / 4.0) / (n / 4.0);
  EXPECT_GT(testing::gamma_q(1.5, chi2 / 2), kAlpha) << chi2;
}

TEST(Warp, PowerHeuristicWeightsSumToOne) {
  for (float f : {0.1f, 1.0f, 7.0f})
    for (float g : {0.0f, 0.5f, 3.0f})
      EXPECT_NEAR(power_heuristic(4, f, 1, g) + power_heuristic(1, g, 4, f), 1.0f, 1e-6f);
}

}  // namespace
}  // namespace tessera
