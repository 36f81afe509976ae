// sin, cos, exp and pow of floats that give the same bits on every x86-64 CPU.
//
// glibc picks an FMA build of sinf, cosf, sincosf, expf and powf at run time where the CPU
// has FMA, and for some inputs it rounds differently from the SSE2 build (measured: see
// docs/performance.md, "The same bits on every CPU"). An image must not depend on the CPU
// that rendered it, so the kernel calls these instead. They are the algorithms glibc itself
// uses (Szabolcs Nagy's, from Arm's optimized-routines, MIT licence: math/sincosf.c,
// math/expf.c, math/powf.c, whose constants and tables are reproduced here) evaluated as
// written: the project builds with -ffp-contract=off, so no multiply-add is fused and every
// CPU rounds each step alike. They therefore return glibc's SSE2 results, bit for bit
// (tests/core/float_math_test.cc compares them over every float that matters and samples
// the rest), and they inline where libm's are calls.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>

namespace tessera::fm {

namespace detail {

inline uint32_t abstop12(float x) { return (std::bit_cast<uint32_t>(x) >> 20) & 0x7ff; }

struct SinCosTable {
  double sign[4];             // sign of sine in quadrants 0..3
  double hpi_inv;             // 2 / pi * 2^24
  double hpi;                 // pi / 2
  double c0, c1, c2, c3, c4;  // cosine polynomial (negated in the second table)
  double s1, s2, s3;          // sine polynomial
};

inline constexpr SinCosTable kSinCos[2] = {
    {{1.0, -1.0, -1.0, 1.0},
     0x1.45F306DC9C883p+23,
     0x1.921FB54442D18p0,
     0x1p0,
     -0x1.ffffffd0c621cp-2,
     0x1.55553e1068f19p-5,
     -0x1.6c087e89a359dp-10,
     0x1.99343027bf8c3p-16,
     -0x1.555545995a603p-3,
     0x1.1107605230bc4p-7,
     -0x1.994eb3774cf24p-13},
    {{1.0, -1.0, -1.0, 1.0},
     0x1.45F306DC9C883p+23,
     0x1.921FB54442D18p0,
     -0x1p0,
     0x1.ffffffd0c621cp-2,
     -0x1.55553e1068f19p-5,
     0x1.6c087e89a359dp-10,
     -0x1.99343027bf8c3p-16,
     -0x1.555545995a603p-3,
     0x1.1107605230bc4p-7,
     -0x1.994eb3774cf24p-13},
};

// 4 / pi to 192 bits, 8 new bits an entry (so every load is aligned).
inline constexpr uint32_t kInvPio4[24] = {0xa2,       0xa2f9,     0xa2f983,   0xa2f9836e, 0xf9836e4e, 0x836e4e44,
                                          0x6e4e4415, 0x4e441529, 0x441529fc, 0x1529fc27, 0x29fc2757, 0xfc2757d1,
                                          0x2757d1f5, 0x57d1f534, 0xd1f534dd, 0xf534ddc0, 0x34ddc0db, 0xddc0db62,
                                          0xc0db6295, 0xdb629599, 0x6295993c, 0x95993c43, 0x993c4390, 0x3c439041};

// x in [-pi/4, pi/4] and x^2; quadrant n swaps sine and cosine where odd.
inline void sincos_poly(double x, double x2, const SinCosTable& p, int n, float* sinp, float* cosp) {
  const double x4 = x2 * x2, x3 = x2 * x;
  const double c2 = p.c3 + x2 * p.c4, s1 = p.s2 + x2 * p.s3;
  if (n & 1) {
    float* t = sinp;
    sinp = cosp;
    cosp = t;
  }
  const double c1 = p.c0 + x2 * p.c1, x5 = x3 * x2, x6 = x4 * x2;
  const double s = x + x3 * p.s1, c = c1 + x4 * p.c2;
  *sinp = float(s + x5 * s1);
  *cosp = float(c + x6 * c2);
}

// |x| < 120: one multiply-subtract by pi/2 (accurate to 55 bits) reduces it.
inline double reduce_fast(double x, const SinCosTable& p, int* np) {
  const double r = x * p.hpi_inv;
  const int n = (int32_t(r) + 0x800000) >> 24;
  *np = n;
  return x - n * p.hpi;
}

// Any finite |x| >= 2: the exact 2.62-bit fixed-point remainder of x * 4 / pi.
inline double reduce_large(uint32_t xi, int* np) {
  const uint32_t* arr = &kInvPio4[(xi >> 26) & 15];
  const int shift = (xi >> 23) & 7;
  xi = (xi & 0xffffff) | 0x800000;
  xi <<= shift;
  uint64_t res0 = xi * arr[0];
  const uint64_t res1 = uint64_t(xi) * arr[4];
  const uint64_t res2 = uint64_t(xi) * arr[8];
  res0 = (res2 >> 32) | (res0 << 32);
  res0 += res1;
  const uint64_t n = (res0 + (1ULL << 61)) >> 62;
  res0 -= n << 62;
  *np = int(n);
  return double(int64_t(res0)) * 0x1.921FB54442D18p-62;  // * 2 pi / 2^64
}

// 2^(i/32) as double bits, less i << 47, for exp and pow.
inline constexpr uint64_t kExp2Table[32] = {
    0x3ff0000000000000, 0x3fefd9b0d3158574, 0x3fefb5586cf9890f, 0x3fef9301d0125b51, 0x3fef72b83c7d517b,
    0x3fef54873168b9aa, 0x3fef387a6e756238, 0x3fef1e9df51fdee1, 0x3fef06fe0a31b715, 0x3feef1a7373aa9cb,
    0x3feedea64c123422, 0x3feece086061892d, 0x3feebfdad5362a27, 0x3feeb42b569d4f82, 0x3feeab07dd485429,
    0x3feea47eb03a5585, 0x3feea09e667f3bcd, 0x3fee9f75e8ec5f74, 0x3feea11473eb0187, 0x3feea589994cce13,
    0x3feeace5422aa0db, 0x3feeb737b0cdc5e5, 0x3feec49182a3f090, 0x3feed503b23e255d, 0x3feee89f995ad3ad,
    0x3feeff76f2fb5e47, 0x3fef199bdd85529c, 0x3fef3720dcef9069, 0x3fef5818dcfba487, 0x3fef7c97337b9b5f,
    0x3fefa4afa2a490da, 0x3fefd0765b6e4540};
inline constexpr double kExp2Poly[3] = {0x1.c6af84b912394p-5, 0x1.ebfce50fac4f3p-3, 0x1.62e42ff0c52d6p-1};

// 2^(k/32) 2^r' rounded to float, where 2^r' ~ poly(r) (exp and pow scale r and the
// polynomial differently); sign_bias (1 << 16) negates.
inline float exp2_scaled(uint64_t ki, double r, const double (&poly)[3], uint64_t sign_bias) {
  const uint64_t t = kExp2Table[ki % 32] + ((ki + sign_bias) << 47);
  const double s = std::bit_cast<double>(t);
  const double z = poly[0] * r + poly[1], r2 = r * r;
  double y = poly[2] * r + 1;
  y = z * r2 + y;
  return float(y * s);
}

// 2^x for x in [-1021, 1023] (doubles), rounded to float; sign_bias (1 << 16) negates.
inline float exp2_inline(double xd, uint64_t sign_bias) {
  constexpr double kShift = 0x1.8p+52 / 32;
  double kd = xd + kShift;  // x = k/32 + r, r in [-1/64, 1/64]
  const uint64_t ki = std::bit_cast<uint64_t>(kd);
  kd -= kShift;
  return exp2_scaled(ki, xd - kd, kExp2Poly, sign_bias);
}

struct Log2Entry {
  double invc, logc;
};
inline constexpr Log2Entry kPowLog2[16] = {
    {0x1.661ec79f8f3bep+0, -0x1.efec65b963019p-2}, {0x1.571ed4aaf883dp+0, -0x1.b0b6832d4fca4p-2},
    {0x1.49539f0f010bp+0, -0x1.7418b0a1fb77bp-2},  {0x1.3c995b0b80385p+0, -0x1.39de91a6dcf7bp-2},
    {0x1.30d190c8864a5p+0, -0x1.01d9bf3f2b631p-2}, {0x1.25e227b0b8eap+0, -0x1.97c1d1b3b7afp-3},
    {0x1.1bb4a4a1a343fp+0, -0x1.2f9e393af3c9fp-3}, {0x1.12358f08ae5bap+0, -0x1.960cbbf788d5cp-4},
    {0x1.0953f419900a7p+0, -0x1.a6f9db6475fcep-5}, {0x1p+0, 0x0p+0},
    {0x1.e608cfd9a47acp-1, 0x1.338ca9f24f53dp-4},  {0x1.ca4b31f026aap-1, 0x1.476a9543891bap-3},
    {0x1.b2036576afce6p-1, 0x1.e840b4ac4e4d2p-3},  {0x1.9c2d163a1aa2dp-1, 0x1.40645f0c6651cp-2},
    {0x1.886e6037841edp-1, 0x1.88e9c2c1b9ff8p-2},  {0x1.767dcf5534862p-1, 0x1.ce0a44eb17bccp-2},
};
inline constexpr double kPowLog2Poly[5] = {0x1.27616c9496e0bp-2, -0x1.71969a075c67ap-2, 0x1.ec70a6ca7baddp-2,
                                           -0x1.7154748bef6c8p-1, 0x1.71547652ab82bp0};

// log2 of a positive normal float's bits (subnormals pre-normalised to a negative exponent).
inline double log2_inline(uint32_t ix) {
  constexpr uint32_t kOff = 0x3f330000;
  const uint32_t tmp = ix - kOff;
  const int i = int((tmp >> 19) % 16);
  const uint32_t top = tmp & 0xff800000;
  const uint32_t iz = ix - top;
  const int k = int32_t(top) >> 23;
  const double invc = kPowLog2[i].invc, logc = kPowLog2[i].logc;
  const double z = std::bit_cast<float>(iz);
  const double r = z * invc - 1, y0 = logc + double(k);
  const double r2 = r * r;
  double y = kPowLog2Poly[0] * r + kPowLog2Poly[1];
  const double p = kPowLog2Poly[2] * r + kPowLog2Poly[3], r4 = r2 * r2;
  double q = kPowLog2Poly[4] * r + y0;
  q = p * r2 + q;
  y = y * r4 + q;
  return y;
}

// 0 where iy is not an integer, 1 where odd, 2 where even.
inline int checkint(uint32_t iy) {
  const int e = iy >> 23 & 0xff;
  if (e < 0x7f) return 0;
  if (e > 0x7f + 23) return 2;
  if (iy & ((1u << (0x7f + 23 - e)) - 1)) return 0;
  if (iy & (1u << (0x7f + 23 - e))) return 1;
  return 2;
}

inline bool zeroinfnan(uint32_t ix) { return 2 * ix - 1 >= 2u * 0x7f800000 - 1; }

// x^y from y log2(x): its overflow and underflow, else 2^(y log2 x); sign_bias negates.
inline float pow_from_log2(double ylogx, uint64_t sign_bias) {
  if ((std::bit_cast<uint64_t>(ylogx) >> 47 & 0xffff) >= std::bit_cast<uint64_t>(126.0) >> 47) [[unlikely]] {
    const float sign = sign_bias ? -1.0f : 1.0f;
    if (ylogx <= -150.0) return sign * 0.0f;
    if (ylogx > 0x1.fffffffd1d571p+6) return sign * INFINITY;
    if (ylogx > 0x1.fffffffa3aae2p+6) return sign * 0x1.fffffep127f;  // rounds down to the largest float
  }
  return exp2_inline(ylogx, sign_bias);
}

// pow where x is zero, subnormal, negative, infinite or NaN, or y zero, infinite or NaN.
float pow_special(float x, float y);  // float_math.cc

}  // namespace detail

// Sine and cosine of x (glibc's sincosf, 0.56 ulp at worst).
inline void sincos(float y, float* sinp, float* cosp) {
  using namespace detail;
  double x = y;
  int n;
  const SinCosTable* p = &kSinCos[0];
  if (abstop12(y) < abstop12(0x1.921FB6p-1f)) {  // |y| < pi/4
    if (abstop12(y) < abstop12(0x1p-12f)) {
      *sinp = y;
      *cosp = 1.0f;
      return;
    }
    sincos_poly(x, x * x, *p, 0, sinp, cosp);
  } else if (abstop12(y) < abstop12(120.0f)) {
    x = reduce_fast(x, *p, &n);
    const double s = p->sign[n & 3];
    if (n & 2) p = &kSinCos[1];
    sincos_poly(x * s, x * x, *p, n, sinp, cosp);
  } else if (abstop12(y) < abstop12(INFINITY)) {
    const uint32_t xi = std::bit_cast<uint32_t>(y);
    const int sign = int(xi >> 31);
    x = reduce_large(xi, &n);
    const double s = p->sign[(n + sign) & 3];
    if ((n + sign) & 2) p = &kSinCos[1];
    sincos_poly(x * s, x * x, *p, n, sinp, cosp);
  } else {
    *sinp = *cosp = y - y;  // NaN for infinities and NaNs
  }
}

inline float sin(float x) {
  float s, c;
  sincos(x, &s, &c);
  return s;
}

inline float cos(float x) {
  float s, c;
  sincos(x, &s, &c);
  return c;
}

// e^x (glibc's expf, 0.502 ulp at worst).
inline float exp(float x) {
  using namespace detail;
  const uint32_t abstop = (std::bit_cast<uint32_t>(x) >> 20) & 0x7ff;
  if (abstop >= (std::bit_cast<uint32_t>(88.0f) >> 20)) {  // |x| >= 88 or NaN
    if (std::bit_cast<uint32_t>(x) == std::bit_cast<uint32_t>(-INFINITY)) return 0.0f;
    if (abstop >= (std::bit_cast<uint32_t>(INFINITY) >> 20)) return x + x;
    if (x > 0x1.62e42ep6f) return INFINITY;  // above log(0x1p128)
    if (x < -0x1.9fe368p6f) return 0.0f;     // below log(0x1p-150)
  }
  constexpr double kInvLn2N = 0x1.71547652b82fep+0 * 32, kShift = 0x1.8p+52;
  constexpr double kPoly[3] = {0x1.c6af84b912394p-5 / 32 / 32 / 32, 0x1.ebfce50fac4f3p-3 / 32 / 32,
                               0x1.62e42ff0c52d6p-1 / 32};
  const double z = kInvLn2N * double(x);  // x * 32 / ln 2 = k + r, r in [-1/2, 1/2]
  double kd = z + kShift;
  const uint64_t ki = std::bit_cast<uint64_t>(kd);
  kd -= kShift;
  return exp2_scaled(ki, z - kd, kPoly, 0);
}

// x^y (glibc's powf, 0.82 ulp at worst).
inline float pow(float x, float y) {
  using namespace detail;
  const uint32_t ix = std::bit_cast<uint32_t>(x), iy = std::bit_cast<uint32_t>(y);
  if (ix - 0x00800000 >= 0x7f800000 - 0x00800000 || zeroinfnan(iy)) [[unlikely]]
    return pow_special(x, y);
  return pow_from_log2(double(y) * log2_inline(ix), 0);
}

}  // namespace tessera::fm
