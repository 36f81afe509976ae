// Scattering at a surface, in the local shading frame (z = normal, directions point away
// from the surface). The kernel switches on Material::Kind; each kind's physics is in
// bsdf.cc beside its sampling routine.
//
// Conventions: for reflection-only kinds the integrator flips the frame so that wo.z > 0
// (surfaces are two-sided). Glass and refraction keep the outward normal, so wo.z < 0
// means the path is inside the object.
#pragma once

#include "core/math/vec.h"
#include "core/scene/scene.h"

namespace tessera {

struct BsdfSample {
  Vec3 wi;
  Rgb weight;      // f * |cos theta_i| / pdf: the throughput multiplier
  float pdf = 0;   // solid-angle density (1 for delta lobes, as a marker)
  float etap = 1;  // relative index crossed (1 for reflection)
  bool delta = false;
};

// What the BSDF decides from wo alone: glTF PBR's lobe selection probabilities (specular
// reflection, diffuse, transmission; zero for other kinds) and, under a sheen, the sheen
// lobe's albedo at wo (sheen_albedo, which scales the base and picks the sheen's share). A
// vertex computes them once (bsdf_lobes) for its light samples' densities and its own
// sample; the forms without them compute them per call.
struct BsdfLobes {
  float spec = 0, diffuse = 0, trans = 0;
  float sheen_wo = 0;
};
BsdfLobes bsdf_lobes(const Material& m, Vec3 wo);

// f(wo, wi) for non-delta kinds (zero for delta kinds).
Rgb bsdf_eval(const Material& m, Vec3 wo, Vec3 wi);
// Solid-angle density of bsdf_sample choosing wi, for non-delta kinds.
float bsdf_pdf(const Material& m, Vec3 wo, Vec3 wi);
float bsdf_pdf(const Material& m, const BsdfLobes& lobes, Vec3 wo, Vec3 wi);  // lobes = bsdf_lobes(m, wo)
// Both at once, the same bits as the two calls: one pass over glTF PBR's lobes and layers
// (the half vector, D(h) and Lambda(wo) once), what a light sample weighed by MIS wants.
Rgb bsdf_eval_pdf(const Material& m, const BsdfLobes& lobes, Vec3 wo, Vec3 wi, float* pdf);
// Draws wi. u1 picks between reflection and transmission; u2 the direction. Returns false
// if the path ends here (black material, total internal reflection of a refraction-only
// surface, a direction below the surface).
bool bsdf_sample(const Material& m, Vec3 wo, float u1, Vec2 u2, BsdfSample* out);
bool bsdf_sample(const Material& m, const BsdfLobes& lobes, Vec3 wo, float u1, Vec2 u2, BsdfSample* out);
// What turns a delta sample's weight from wo (bsdf_sample's: the surface seen from wo) into
// the adjoint's, for light arriving along wo and leaving along wi (a light path's, seen from
// wi): 1 but under KHR_materials_clearcoat, whose layer passes (1 - Fc) with Fc taken at
// the viewing direction only, which is not reciprocal: (1 - Fc(wi)) / (1 - Fc(wo)). (Exactly
// 1 for the coat's own mirror lobe.) Radiance's 1 / eta^2 is the caller's.
float delta_adjoint_factor(const Material& m, Vec3 wo, Vec3 wi);

}  // namespace tessera
