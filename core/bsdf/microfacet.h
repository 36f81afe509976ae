// Microfacet distributions: Beckmann (CS184's glossy material) and GGX (glTF's model).
//
// Beckmann microfacet distribution with the Smith shadowing-masking term.
//
// CS184's provided Lambda divides by pi where Smith-Beckmann has sqrt(pi) (format doc
// 9.17); we use the correct sqrt(pi), consistent with the project's physical default.
#pragma once

#include <cmath>
#include <limits>

#include "core/math/float_math.h"
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
    return fm::exp(-tan2 / a2) / (kPi * a2 * cos2 * cos2);
  }

  float lambda(Vec3 w) const {
    const float cos2 = w.z * w.z;
    const float sin2 = std::max(0.0f, 1 - cos2);
    if (sin2 == 0) return 0;
    const float a = std::sqrt(cos2 / sin2) / alpha_;  // 1 / (alpha tan theta)
    return 0.5f * (std::erf(a) - 1 + fm::exp(-a * a) / (a * std::sqrt(kPi)));
  }

  float g(Vec3 wo, Vec3 wi) const { return 1 / (1 + lambda(wo) + lambda(wi)); }

  // Samples h with density D(h) cos(theta_h).
  Vec3 sample_h(Vec2 u) const {
    const float tan2 = -alpha_ * alpha_ * std::log1p(-u.x);
    const float cos_t = 1 / std::sqrt(1 + tan2);
    const float sin_t = std::sqrt(std::max(0.0f, 1 - cos_t * cos_t));
    float sn, cs;
    fm::sincos(2 * kPi * u.y, &sn, &cs);
    return {sin_t * cs, sin_t * sn, cos_t};
  }

  float pdf_h(Vec3 h) const { return d(h) * std::fabs(h.z); }

 private:
  float alpha_;
};

// Trowbridge-Reitz (GGX), isotropic, with the height-correlated Smith masking-shadowing
// term glTF's Appendix B names, and sampling of the visible normals (Heitz 2018, "Sampling
// the GGX Distribution of Visible Normals"): a sampled normal is never back-facing and the
// weight F G2 / G1 is bounded, so even a nearly smooth surface is sampled well.
class Ggx {
 public:
  explicit Ggx(float alpha) : a2_(alpha * alpha), alpha_(alpha) {}

  // D(h) = a^2 / (pi (cos^2 (a^2 - 1) + 1)^2), written with sin^2 = x^2 + y^2 so that a
  // small alpha near the normal loses no precision to 1 - cos^2.
  float d(Vec3 h) const {
    if (h.z <= 0) return 0;
    const float t = h.x * h.x + h.y * h.y + a2_ * h.z * h.z;
    return t > 0 ? a2_ / (kPi * t * t) : 0;
  }

  // Lambda(w) = (sqrt(1 + a^2 tan^2) - 1) / 2, as x / (sqrt(1 + x) + 1) / 2 (no cancellation).
  float lambda(Vec3 w) const {
    const float cos2 = w.z * w.z;
    if (cos2 <= 0) return std::numeric_limits<float>::infinity();
    const float x = a2_ * (w.x * w.x + w.y * w.y) / cos2;
    return 0.5f * x / (std::sqrt(1 + x) + 1);
  }
  float g2(Vec3 wo, Vec3 wi) const { return g2(lambda(wo), wi); }
  // With Lambda(wo) already at hand (an evaluation that wants the density too).
  float g2(float lambda_wo, Vec3 wi) const { return 1 / (1 + lambda_wo + lambda(wi)); }

  // Density of sample_visible(wo) drawing h, over solid angle of h; wo.z > 0: G1(wo)
  // max(0, wo.h) D(h) / wo.z, with G1 = 1 / (1 + Lambda). The second form takes Lambda(wo)
  // and D(h) from an evaluation that has them already.
  float pdf_visible(Vec3 wo, Vec3 h) const { return pdf_visible(wo, h, lambda(wo), d(h)); }
  float pdf_visible(Vec3 wo, Vec3 h, float lambda_wo, float d_h) const {
    const float c = dot(wo, h);
    return c > 0 && wo.z > 0 ? 1 / (1 + lambda_wo) * c * d_h / wo.z : 0;
  }

  // A normal h with density pdf_visible(wo, h); wo.z > 0.
  Vec3 sample_visible(Vec3 wo, Vec2 u) const {
    const Vec3 vh = normalize(Vec3{alpha_ * wo.x, alpha_ * wo.y, wo.z});  // hemisphere configuration
    const float len2 = vh.x * vh.x + vh.y * vh.y;
    const Vec3 t1 = len2 > 0 ? Vec3{-vh.y, vh.x, 0} / std::sqrt(len2) : Vec3{1, 0, 0};
    const Vec3 t2 = cross(vh, t1);
    const float r = std::sqrt(u.x);
    float sn, cs;
    fm::sincos(2 * kPi * u.y, &sn, &cs);
    const float p1 = r * cs;
    const float s = 0.5f * (1 + vh.z);
    const float p2 = (1 - s) * std::sqrt(std::max(0.0f, 1 - p1 * p1)) + s * r * sn;
    const Vec3 nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.0f, 1 - p1 * p1 - p2 * p2));
    return normalize(Vec3{alpha_ * nh.x, alpha_ * nh.y, std::max(1e-6f, nh.z)});
  }

 private:
  float a2_, alpha_;
};

}  // namespace tessera
