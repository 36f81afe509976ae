// fm::sincos, fm::exp and fm::pow (core/math/float_math.h): accurate everywhere, and bit for
// bit glibc's SSE2 results (FloatMath.DISABLED_SameBitsAsLibmWithoutFma, which only ctest's
// FloatMath.SameBitsAsLibmWithoutFmaHeld runs, with glibc held to its SSE2 variants; run by
// hand on a CPU with FMA, with --gtest_also_run_disabled_tests, it reports how many inputs
// glibc's FMA variants round differently, which is why the kernel does not call libm).
#include "core/math/float_math.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace tessera {
namespace {

bool same_bits(float a, float b) {
  return std::bit_cast<uint32_t>(a) == std::bit_cast<uint32_t>(b) || (std::isnan(a) && std::isnan(b));
}

// Distance in ulps of f from the exact value e (a double), in units of f's ulp.
double ulp_error(float f, double e) {
  if (std::isinf(e) || std::isnan(e)) return same_bits(f, float(e)) ? 0 : 1e9;
  const double ulp = std::ldexp(1.0, std::max(std::ilogb(float(e)), -126) - 23);
  return std::fabs(double(f) - e) / ulp;
}

// Every float whose bits are a multiple of `stride`, then every float of magnitude in
// [lo, hi] (0 < lo < hi), both signs.
template <class F>
void for_floats(uint32_t stride, float lo, float hi, F f) {
  for (uint64_t b = 0; b <= 0xffffffffull; b += stride) f(std::bit_cast<float>(uint32_t(b)));
  for (uint32_t b = std::bit_cast<uint32_t>(lo); b <= std::bit_cast<uint32_t>(hi); ++b) {
    f(std::bit_cast<float>(b));
    f(std::bit_cast<float>(b | 0x80000000u));
  }
}

bool libm_held_to_sse2() {
  const char* t = std::getenv("GLIBC_TUNABLES");
  return t && std::strstr(t, "-FMA");
}

TEST(FloatMath, SinCosWithinOneUlp) {
  double worst = 0;
  for_floats(4099, 7.99f, 8.0f, [&](float x) {
    if (!std::isfinite(x)) return;
    float s, c;
    fm::sincos(x, &s, &c);
    worst = std::max({worst, ulp_error(s, std::sin(double(x))), ulp_error(c, std::cos(double(x)))});
    ASSERT_TRUE(same_bits(s, fm::sin(x)) && same_bits(c, fm::cos(x))) << x;
  });
  EXPECT_LT(worst, 0.57);  // glibc's own bound: 0.5607 ulp
  float s, c;
  fm::sincos(INFINITY, &s, &c);
  EXPECT_TRUE(std::isnan(s) && std::isnan(c));
  fm::sincos(NAN, &s, &c);
  EXPECT_TRUE(std::isnan(s) && std::isnan(c));
  fm::sincos(-0.0f, &s, &c);
  EXPECT_TRUE(same_bits(s, -0.0f) && c == 1.0f);
}

TEST(FloatMath, ExpWithinOneUlp) {
  double worst = 0;
  for_floats(4099, 0.99f, 1.0f, [&](float x) {
    const float e = fm::exp(x);
    if (std::isnan(x)) {
      EXPECT_TRUE(std::isnan(e));
      return;
    }
    worst = std::max(worst, ulp_error(e, std::exp(double(x))));
  });
  EXPECT_LT(worst, 0.51);  // glibc's own bound: 0.502 ulp
  EXPECT_EQ(fm::exp(-INFINITY), 0.0f);
  EXPECT_EQ(fm::exp(INFINITY), INFINITY);
  EXPECT_EQ(fm::exp(89.0f), INFINITY);
  EXPECT_EQ(fm::exp(-104.0f), 0.0f);
  EXPECT_GT(fm::exp(-103.0f), 0.0f);  // subnormal
}

TEST(FloatMath, PowWithinOneUlp) {
  const float ys[] = {2.4f, 1 / 2.4f, 0.5f, 2.0f, 3.0f, -1.0f, 7.3f, -2.5f, 100.0f, 1e-3f, 0.9f};
  double worst = 0;
  for (const float y : ys)
    for_floats(65537, 0.5f, 0.5001f, [&](float x) {
      if (!(x > 0) || std::isinf(x)) return;
      const double e = std::pow(double(x), double(y));
      if (e < 0x1p-126 || e > 0x1.fffffep127) return;  // outside normal floats: checked below
      worst = std::max(worst, ulp_error(fm::pow(x, y), e));
    });
  EXPECT_LT(worst, 0.83);  // glibc's own bound: 0.82 ulp
  // The special cases, as C's pow defines them.
  EXPECT_EQ(fm::pow(0.0f, 2.0f), 0.0f);
  EXPECT_TRUE(same_bits(fm::pow(-0.0f, 3.0f), -0.0f));
  EXPECT_EQ(fm::pow(-0.0f, -3.0f), -INFINITY);
  EXPECT_EQ(fm::pow(0.0f, -2.0f), INFINITY);
  EXPECT_EQ(fm::pow(-2.0f, 3.0f), -8.0f);
  EXPECT_EQ(fm::pow(-2.0f, 2.0f), 4.0f);
  EXPECT_TRUE(std::isnan(fm::pow(-2.0f, 0.5f)));
  EXPECT_EQ(fm::pow(NAN, 0.0f), 1.0f);
  // A signalling NaN is not quietly taken to 1 (glibc's powf; found by the -O1 sanitizer
  // build, where the NaN reached libm unquieted).
  const float snan = std::bit_cast<float>(0x7fa00000u);
  EXPECT_TRUE(std::isnan(fm::pow(snan, 0.0f)));
  EXPECT_TRUE(std::isnan(fm::pow(-snan, -0.0f)));
  EXPECT_TRUE(std::isnan(fm::pow(1.0f, snan)));
  EXPECT_EQ(fm::pow(1.0f, std::bit_cast<float>(0x7fe00000u)), 1.0f);  // a quiet one is
  EXPECT_EQ(fm::pow(1.0f, NAN), 1.0f);
  EXPECT_TRUE(std::isnan(fm::pow(2.0f, NAN)));
  EXPECT_EQ(fm::pow(0.5f, INFINITY), 0.0f);
  EXPECT_EQ(fm::pow(2.0f, INFINITY), INFINITY);
  EXPECT_EQ(fm::pow(-1.0f, INFINITY), 1.0f);
  EXPECT_EQ(fm::pow(INFINITY, -1.0f), 0.0f);
  EXPECT_EQ(fm::pow(-INFINITY, 3.0f), -INFINITY);
  EXPECT_EQ(fm::pow(10.0f, 39.0f), INFINITY);
  EXPECT_EQ(fm::pow(-10.0f, 39.0f), -INFINITY);
  EXPECT_EQ(fm::pow(10.0f, -46.0f), 0.0f);
  EXPECT_GT(fm::pow(1e-40f, 0.5f), 0.0f);  // subnormal x
}

// Bit for bit glibc's SSE2 sincosf, sinf, cosf, expf and powf: every float of magnitude in
// [1/2, 2 pi] (the angles the kernel's warps make, down to where the polynomial alone acts)
// and 1 in 257 of all the others; pow on a grid of bases and exponents and every 61st
// float of (1/128, 1) to the exponents of colour conversions. (Every float, all 2^32, was
// compared once: docs/performance.md.)
TEST(FloatMath, DISABLED_SameBitsAsLibmWithoutFma) {
  // libm through pointers the compiler cannot see through: g++ -O3 peeled the loop's first
  // exponent, 0, and folded powf(x, 0) to 1, which glibc does not return for a signalling
  // NaN x; the comparison was then with the compiler, not libm.
  static float (*volatile libm_powf)(float, float) = ::powf;
  static float (*volatile libm_expf)(float) = ::expf;
  static float (*volatile libm_sinf)(float) = ::sinf;
  static float (*volatile libm_cosf)(float) = ::cosf;
  static void (*volatile libm_sincosf)(float, float*, float*) = ::sincosf;
  size_t differ[5] = {}, n = 0;
  auto check_trig = [&](float x) {
    float s, c, ls, lc;
    fm::sincos(x, &s, &c);
    libm_sincosf(x, &ls, &lc);
    differ[0] += !same_bits(s, ls) || !same_bits(c, lc);
    differ[1] += !same_bits(s, libm_sinf(x));
    differ[2] += !same_bits(c, libm_cosf(x));
    differ[3] += !same_bits(fm::exp(x), libm_expf(x));
    ++n;
  };
  for_floats(257, 0.5f, 6.2832f, check_trig);
  size_t pow_n = 0;
  for (uint64_t xb = 0; xb <= 0xffffffffull; xb += 1048573)
    for (uint64_t yb = 0; yb <= 0xffffffffull; yb += 1048583) {
      const float x = std::bit_cast<float>(uint32_t(xb)), y = std::bit_cast<float>(uint32_t(yb));
      differ[4] += !same_bits(fm::pow(x, y), libm_powf(x, y));
      ++pow_n;
    }
  for (uint32_t xb = 0x3c000000; xb < 0x3f800000; xb += 61)  // (0.0078, 1): colours
    for (const float y : {2.4f, 1 / 2.4f, 0.5f, 7.3f}) {
      const float x = std::bit_cast<float>(xb);
      differ[4] += !same_bits(fm::pow(x, y), libm_powf(x, y));
      ++pow_n;
    }
  std::printf(
      "inputs: %zu trig and exp, %zu pow; differing from this process's libm: sincosf %zu, sinf %zu, cosf %zu, "
      "expf %zu, powf %zu\n",
      n, pow_n, differ[0], differ[1], differ[2], differ[3], differ[4]);
  if (!libm_held_to_sse2())
    GTEST_SKIP() << "glibc may run its FMA variants here: the counts above are for information; ctest runs this "
                    "test with GLIBC_TUNABLES holding glibc to SSE2";
  for (const size_t d : differ) EXPECT_EQ(d, 0u);
}

}  // namespace
}  // namespace tessera
