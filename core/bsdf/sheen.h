// KHR_materials_sheen's microfibre lobe: Conty Estevez and Kulla 2017's "Charlie"
// distribution and visibility, as the extension's implementation notes give them, for a
// white sheen (the caller multiplies by the sheen colour). The layer goes over the base by
// albedo scaling: f = sheenColor f_sheen + f_base (1 - max(sheenColor) E), E the lobe's
// directional albedo (sheen_albedo), taken at both wo and wi (the smaller scale wins) so
// that the sum never gains energy. bsdf.cc does the layering and the sampling.
#pragma once

#include <algorithm>

#include "core/math/vec.h"

namespace tessera {

// The roughness floor: the visibility fit is for [0, 1], and below this the distribution's
// exponent (1 / alpha) makes a spike at grazing angles that no sampler finds.
constexpr float kSheenMinAlpha = 0.07f;

// The lobe's alpha from glTF's sheenRoughness (the extension uses it as is, not squared).
inline float sheen_alpha(float sheen_roughness) { return std::clamp(sheen_roughness, kSheenMinAlpha, 1.0f); }

// D(h): (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi), normalised over projected area.
float sheen_d(float alpha, float cos_h);

// f_sheen(wo, wi) for a white sheen, both directions on the same side (z > 0 after the
// caller's flip): D V with V = 1 / ((1 + Lambda(wo) + Lambda(wi)) 4 cos_o cos_i).
float sheen_f(float alpha, Vec3 wo, Vec3 wi);

// E(cos_theta, alpha) = integral of sheen_f cos over the hemisphere: bilinear in a table
// (32 x 32) integrated once per process, on first use, so that scenes without sheen never
// pay for it.
float sheen_albedo(float cos_theta, float alpha);

}  // namespace tessera
