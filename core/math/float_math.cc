// The rare cases of fm::pow: glibc's powf for a zero, subnormal, negative, infinite or NaN
// x, or a zero, infinite or NaN y (see float_math.h). Errno and floating-point exception
// flags are not raised: nothing reads them.
#include "core/math/float_math.h"

namespace tessera::fm::detail {
namespace {

// A signalling NaN's bits (glibc's issignalingf_inline): exponent all ones, the quiet bit
// clear, some other mantissa bit set.
bool signalling(uint32_t ix) { return 2 * (ix ^ 0x00400000) > 2u * 0x7fc00000; }

}  // namespace

float pow_special(float x, float y) {
  uint32_t ix = std::bit_cast<uint32_t>(x);
  const uint32_t iy = std::bit_cast<uint32_t>(y);
  uint64_t sign_bias = 0;
  if (zeroinfnan(iy)) {
    // x^0 and 1^y are 1 for a quiet NaN too, a NaN for a signalling one (as glibc 2.36).
    if (2 * iy == 0) return signalling(ix) ? x + y : 1.0f;
    if (ix == 0x3f800000) return signalling(iy) ? x + y : 1.0f;
    if (2 * ix > 2u * 0x7f800000 || 2 * iy > 2u * 0x7f800000) return x + y;
    if (2 * ix == 2 * 0x3f800000) return 1.0f;
    if ((2 * ix < 2 * 0x3f800000) == !(iy & 0x80000000)) return 0.0f;  // |x| < 1, y = inf or |x| > 1, y = -inf
    return y * y;
  }
  if (zeroinfnan(ix)) {
    float x2 = x * x;
    if (ix & 0x80000000 && checkint(iy) == 1) x2 = -x2;
    return iy & 0x80000000 ? 1 / x2 : x2;
  }
  if (ix & 0x80000000) {  // finite x < 0
    const int yint = checkint(iy);
    if (yint == 0) return (x - x) / (x - x);  // NaN
    if (yint == 1) sign_bias = 1 << 16;
    ix &= 0x7fffffff;
  }
  if (ix < 0x00800000) {  // subnormal: normalise so the exponent goes negative
    ix = std::bit_cast<uint32_t>(std::bit_cast<float>(ix) * 0x1p23f);
    ix &= 0x7fffffff;
    ix -= 23 << 23;
  }
  return pow_from_log2(double(y) * log2_inline(ix), sign_bias);
}

}  // namespace tessera::fm::detail
