// Warps from the unit square to the domains the renderer samples, with their densities.
// Each has a chi-square test in tests/core/sampling_test.cc.
#pragma once

#include <cmath>

#include "core/math/float_math.h"
#include "core/math/vec.h"

namespace tessera {

// Shirley-Chiu concentric map to the unit disk: area-preserving and low-distortion, so
// stratified points stay stratified (matters for the thin lens).
inline Vec2 square_to_concentric_disk(Vec2 u) {
  const float ox = 2 * u.x - 1, oy = 2 * u.y - 1;
  if (ox == 0 && oy == 0) return {0, 0};
  float r, theta;
  if (std::fabs(ox) > std::fabs(oy)) {
    r = ox;
    theta = (kPi / 4) * (oy / ox);
  } else {
    r = oy;
    theta = (kPi / 2) - (kPi / 4) * (ox / oy);
  }
  float sn, cs;
  fm::sincos(theta, &sn, &cs);  // (fm::sin and fm::cos are its two halves: the same bits)
  return {r * cs, r * sn};
}

// Cosine-weighted hemisphere about +z (Malley's method). pdf = cos(theta) / pi.
inline Vec3 square_to_cosine_hemisphere(Vec2 u) {
  const Vec2 d = square_to_concentric_disk(u);
  const float z = std::sqrt(std::max(0.0f, 1 - d.x * d.x - d.y * d.y));
  return {d.x, d.y, z};
}
inline float cosine_hemisphere_pdf(float cos_theta) { return cos_theta > 0 ? cos_theta * kInvPi : 0; }

// Uniform hemisphere about +z. pdf = 1 / (2 pi).
inline Vec3 square_to_uniform_hemisphere(Vec2 u) {
  const float z = u.x;
  const float r = std::sqrt(std::max(0.0f, 1 - z * z));
  float sn, cs;
  fm::sincos(2 * kPi * u.y, &sn, &cs);
  return {r * cs, r * sn, z};
}
constexpr float kUniformHemispherePdf = 0.5f * kInvPi;

// Uniform sphere. pdf = 1 / (4 pi).
constexpr float kUniformSpherePdf = 0.25f * kInvPi;
inline Vec3 square_to_uniform_sphere(Vec2 u) {
  const float z = 1 - 2 * u.x;
  const float r = std::sqrt(std::max(0.0f, 1 - z * z));
  float sn, cs;
  fm::sincos(2 * kPi * u.y, &sn, &cs);
  return {r * cs, r * sn, z};
}

// Uniform barycentrics on a triangle (Heitz 2019 low-distortion map): returns (b1, b2).
inline Vec2 square_to_triangle(Vec2 u) {
  float b0, b1;
  if (u.x < u.y) {
    b0 = u.x / 2;
    b1 = u.y - b0;
  } else {
    b1 = u.y / 2;
    b0 = u.x - b1;
  }
  return {b0, b1};
}

// Veach's power heuristic (beta = 2) for nf samples of pdf fpdf against ng of gpdf.
inline float power_heuristic(float nf, float fpdf, float ng, float gpdf) {
  const float f = nf * fpdf, g = ng * gpdf;
  if (std::isinf(f * f)) return 1;
  if (f == 0 && g == 0) return 0;
  return (f * f) / (f * f + g * g);
}

}  // namespace tessera
