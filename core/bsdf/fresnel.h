// Fresnel reflectance and Snell refraction.
#pragma once

#include <algorithm>
#include <cmath>

#include "core/math/vec.h"

namespace tessera {

// Exact unpolarised Fresnel reflectance of a dielectric interface. cos_i is measured
// against the normal on the side of the exterior; eta = n_interior / n_exterior. A negative
// cos_i means the ray arrives from the interior. Returns 1 under total internal reflection.
inline float fresnel_dielectric(float cos_i, float eta) {
  cos_i = std::clamp(cos_i, -1.0f, 1.0f);
  if (cos_i < 0) {
    eta = 1 / eta;
    cos_i = -cos_i;
  }
  const float sin2_i = 1 - cos_i * cos_i;
  const float sin2_t = sin2_i / (eta * eta);
  if (sin2_t >= 1) return 1;
  const float cos_t = std::sqrt(std::max(0.0f, 1 - sin2_t));
  const float r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  const float r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  return 0.5f * (r_parl * r_parl + r_perp * r_perp);
}

// Refracts wo (pointing away from the surface) through the interface with normal n
// (pointing to the exterior) and relative index eta = n_interior / n_exterior. Writes the
// transmitted direction and the relative index seen along the path (n_t / n_i). Returns
// false under total internal reflection.
inline bool refract(Vec3 wo, Vec3 n, float eta, Vec3* wt, float* etap) {
  float cos_i = dot(n, wo);
  if (cos_i < 0) {
    eta = 1 / eta;
    cos_i = -cos_i;
    n = -n;
  }
  const float sin2_i = std::max(0.0f, 1 - cos_i * cos_i);
  const float sin2_t = sin2_i / (eta * eta);
  if (sin2_t >= 1) return false;
  const float cos_t = std::sqrt(1 - sin2_t);
  *wt = -wo / eta + (cos_i / eta - cos_t) * n;
  *etap = eta;
  return true;
}

// Air-conductor Fresnel for complex index eta + i k at cosine c (the approximation used
// by CS184 and Mitsuba's fresnelConductorApprox), per channel.
inline float fresnel_conductor(float c, float eta, float k) {
  c = std::clamp(c, 0.0f, 1.0f);
  const float s = eta * eta + k * k, c2 = c * c;
  const float rs = (s - 2 * eta * c + c2) / (s + 2 * eta * c + c2);
  const float rp = (s * c2 - 2 * eta * c + 1) / (s * c2 + 2 * eta * c + 1);
  return 0.5f * (rs + rp);
}

inline Rgb fresnel_conductor(float c, Rgb eta, Rgb k) {
  return {fresnel_conductor(c, eta.r, k.r), fresnel_conductor(c, eta.g, k.g), fresnel_conductor(c, eta.b, k.b)};
}

}  // namespace tessera
