// Beckmann microfacet distribution with the Smith shadowing-masking term.
//
// CS184's provided Lambda divides by pi where Smith-Beckmann has sqrt(pi) (format doc
// 9.17); we use the correct sqrt(pi), consistent with the project's physical default.
#pragma once

#include <cmath>

#include "core/math/vec.h"

namespace tessera {

class Beckmann {
 public:
  explicit Beckmann(float alpha) : alpha_(alpha) {}

  // Normal distribution D(h), h in the local frame (z = macro normal).
  float d(Vec3 h) const {
    const float cos2 = h.z * h.z;
    if (cos2 <= 0) return 0;
    const float tan2 = (1 - cos2) / cos2;
    const float a2 = alpha_ * alpha_;
    return std::exp(-tan2 / a2) / (kPi * a2 * cos2 * cos2);
  }

  float lambda(Vec3 w) const {
    const float cos2 = w.z * w.z;
    const float sin2 = std::max(0.0f, 1 - cos2);
    if (sin2 == 0) return 0;
    const float a = std::sqrt(cos2 / sin2) / alpha_;  // 1 / (alpha tan theta)
    return 0.5f * (std::erf(a) - 1 + std::exp(-a * a) / (a * std::sqrt(kPi)));
  }

  float g(Vec3 wo, Vec3 wi) const { return 1 / (1 + lambda(wo) + lambda(wi)); }

  // Samples h with density D(h) cos(theta_h).
  Vec3 sample_h(Vec2 u) const {
    const float tan2 = -alpha_ * alpha_ * std::log1p(-u.x);
    const float cos_t = 1 / std::sqrt(1 + tan2);
    const float sin_t = std::sqrt(std::max(0.0f, 1 - cos_t * cos_t));
    const float phi = 2 * kPi * u.y;
    return {sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t};
  }

  float pdf_h(Vec3 h) const { return d(h) * std::fabs(h.z); }

 private:
  float alpha_;
};

}  // namespace tessera
