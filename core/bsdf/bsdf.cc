#include "core/bsdf/bsdf.h"

#include <cmath>

#include "core/bsdf/fresnel.h"
#include "core/bsdf/microfacet.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

Vec3 reflect_z(Vec3 w) { return {-w.x, -w.y, w.z}; }

Rgb microfacet_f(const Material& m, Vec3 wo, Vec3 wi) {
  if (wo.z <= 0 || wi.z <= 0) return Rgb(0);
  Vec3 h = wo + wi;
  const float len = length(h);
  if (len == 0) return Rgb(0);
  h = h / len;
  const Beckmann dist(m.alpha);
  // Fresnel at the microfacet (wi . h), not the macro normal as CS184 does.
  const Rgb f = fresnel_conductor(dot(wi, h), m.eta, m.k);
  return f * (dist.d(h) * dist.g(wo, wi) / (4 * wo.z * wi.z));
}

float microfacet_pdf(const Material& m, Vec3 wo, Vec3 wi) {
  if (wo.z <= 0 || wi.z <= 0) return 0;
  Vec3 h = wo + wi;
  const float len = length(h);
  if (len == 0) return 0;
  h = h / len;
  return Beckmann(m.alpha).pdf_h(h) / (4 * std::fabs(dot(wo, h)));
}

}  // namespace

Rgb bsdf_eval(const Material& m, Vec3 wo, Vec3 wi) {
  switch (m.kind) {
    case Material::Kind::kDiffuse:
      return (wo.z > 0 && wi.z > 0) ? m.reflectance * kInvPi : Rgb(0);
    case Material::Kind::kMicrofacet:
      return microfacet_f(m, wo, wi);
    default:
      return Rgb(0);
  }
}

float bsdf_pdf(const Material& m, Vec3 wo, Vec3 wi) {
  switch (m.kind) {
    case Material::Kind::kDiffuse:
      return (wo.z > 0) ? cosine_hemisphere_pdf(wi.z) : 0;
    case Material::Kind::kMicrofacet:
      return microfacet_pdf(m, wo, wi);
    default:
      return 0;
  }
}

bool bsdf_sample(const Material& m, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
  switch (m.kind) {
    case Material::Kind::kDiffuse: {
      if (wo.z <= 0) return false;
      out->wi = square_to_cosine_hemisphere(u2);
      out->pdf = cosine_hemisphere_pdf(out->wi.z);
      if (out->pdf <= 0) return false;
      out->weight = m.reflectance;  // (rho / pi) cos / (cos / pi)
      out->delta = false;
      out->etap = 1;
      return true;
    }
    case Material::Kind::kMirror: {
      if (wo.z <= 0) return false;
      out->wi = reflect_z(wo);
      out->pdf = 1;
      out->weight = m.reflectance;
      out->delta = true;
      out->etap = 1;
      return true;
    }
    case Material::Kind::kGlass: {
      const float f = fresnel_dielectric(wo.z, m.ior);
      out->delta = true;
      out->pdf = 1;
      if (u1 < f) {  // reflect with probability F: weight F * R / F
        out->wi = reflect_z(wo);
        out->weight = m.reflectance;
        out->etap = 1;
        return true;
      }
      if (!refract(wo, Vec3{0, 0, 1}, m.ior, &out->wi, &out->etap)) return false;  // f == 1 then
      // Radiance is scaled by 1/eta^2 crossing the interface (pbrt, non-symmetric BSDF).
      out->weight = m.transmittance / (out->etap * out->etap);
      return true;
    }
    case Material::Kind::kRefraction: {
      out->delta = true;
      out->pdf = 1;
      if (!refract(wo, Vec3{0, 0, 1}, m.ior, &out->wi, &out->etap)) return false;
      out->weight = m.transmittance / (out->etap * out->etap);
      return true;
    }
    case Material::Kind::kMicrofacet: {
      if (wo.z <= 0) return false;
      const Beckmann dist(m.alpha);
      const Vec3 h = dist.sample_h(u2);
      const float wo_h = dot(wo, h);
      if (wo_h <= 0) return false;
      out->wi = h * (2 * wo_h) - wo;
      if (out->wi.z <= 0) return false;
      out->pdf = dist.pdf_h(h) / (4 * wo_h);
      if (!(out->pdf > 0)) return false;
      out->weight = microfacet_f(m, wo, out->wi) * (out->wi.z / out->pdf);
      out->delta = false;
      out->etap = 1;
      return true;
    }
    case Material::Kind::kEmission:
      return false;
  }
  return false;
}

}  // namespace tessera
