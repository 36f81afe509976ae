#include "core/bsdf/bsdf.h"

#include <cmath>

#include "core/bsdf/fresnel.h"
#include "core/bsdf/microfacet.h"
#include "core/bsdf/sheen.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

Vec3 reflect_z(Vec3 w) { return {-w.x, -w.y, w.z}; }

// The microfacet normal along v, facing +z; false if v is degenerate or the normal is
// back-facing to wo or wi (each must be on the same side of it as of the macro surface).
bool half_vector(Vec3 v, Vec3 wo, Vec3 wi, Vec3* h) {
  const float len = length(v);
  if (!(len > 0)) return false;
  v = v / len;
  if (v.z < 0) v = -v;
  *h = v;
  return dot(v, wo) * wo.z > 0 && dot(v, wi) * wi.z > 0;
}

// Half vector of a reflection.
bool reflection_half(Vec3 wo, Vec3 wi, Vec3* h) { return half_vector(wo + wi, wo, wi, h); }

// Generalized half vector of a refraction (Walter et al. eq. 16); etap is the relative
// index along the path (n_t / n_i).
bool refraction_half(const Material& m, Vec3 wo, Vec3 wi, Vec3* h, float* etap) {
  *etap = wo.z > 0 ? m.ior : 1 / m.ior;
  return half_vector(wi * *etap + wo, wo, wi, h);
}

Rgb microfacet_f(const Material& m, Vec3 wo, Vec3 wi) {
  Vec3 h;
  if (wo.z <= 0 || wi.z <= 0 || !reflection_half(wo, wi, &h)) return Rgb(0);
  const Beckmann dist(m.alpha);
  // Fresnel at the microfacet (wi . h), not the macro normal as CS184 does.
  const Rgb f = fresnel_conductor(dot(wi, h), m.eta, m.k);
  return f * (dist.d(h) * dist.g(wo, wi) / (4 * wo.z * wi.z));
}

float microfacet_pdf(const Material& m, Vec3 wo, Vec3 wi) {
  Vec3 h;
  if (wo.z <= 0 || wi.z <= 0 || !reflection_half(wo, wi, &h)) return 0;
  return Beckmann(m.alpha).pdf_h(h) / (4 * std::fabs(dot(wo, h)));
}

// ---- glTF metallic-roughness (kPbr) ----------------------------------------------------
// glTF 2.0 Appendix B, as three components mixed by weight:
//   metal   (metallic)                        Schlick(F0 = base colour) x GGX specular
//   coat    ((1 - metallic)(1 - transmission)) dielectric: F x GGX specular + (1 - F) base / pi
//   glass   ((1 - metallic) transmission)      F x GGX reflection + (1 - F) base x GGX transmission
// F is the exact dielectric Fresnel of `ior` at the microfacet (Schlick's approximation of
// it, which the specification allows, is what we avoid). Glass transmission is Walter et
// al. 2007's rough refraction for a solid (`thin` false) and, thin-walled, the reflection
// lobe mirrored through the surface (no bending). Every lobe is two-sided; only glass tells
// inside from outside. Sampling picks a lobe by its estimated albedo seen from wo, then
// the direction (cosine for diffuse, visible normals for the rest); the density is the
// mixture over all lobes, so one sample of any lobe is weighted by the whole BSDF.

struct PbrWeights {
  float metal, coat, glass;
};
PbrWeights pbr_weights(const Material& m) {
  const float d = 1 - m.metallic;
  return {m.metallic, d * (1 - m.transmission), d * m.transmission};
}

Rgb schlick(Rgb f0, float c) {
  const float x = 1 - std::clamp(c, 0.0f, 1.0f), x5 = x * x * x * x * x;
  return f0 + (Rgb(1.0f) - f0) * x5;
}

bool pbr_smooth(const Material& m) { return m.alpha < Material::kSmoothAlpha; }

// No specular reflection at all: no metal, and a dielectric of ior 1, whose Fresnel is 0 at
// every angle (KHR_materials_specular's too: its F0 is then 0 and its curve the exact
// one's). Our Cornell glTF scenes' walls are such (exactly the CS184 boxes' Lambertian
// ones): their reflection is the diffuse lobe alone, sampled and evaluated as that.
bool pbr_no_specular(const Material& m) { return m.metallic <= 0 && m.ior == 1; }
// A solid of ior 1 bends nothing: its transmission goes straight through, a delta lobe
// however rough the surface (Walter et al.'s refraction lobe degenerates there: its half
// vector wi + wo vanishes, and sampling it gave NaN weights). A thin wall's transmission
// is the reflection lobe mirrored, rough at any ior.
bool pbr_index_matched(const Material& m) { return !m.thin && m.ior == 1; }

// The glass component's Fresnel at cosine c against the outward normal: a solid's inside
// sees the inverse index (total internal reflection); a thin wall has air on both sides.
float glass_fresnel(const Material& m, float c) { return fresnel_dielectric(m.thin ? std::fabs(c) : c, m.ior); }

// The dielectric interface's reflectance `reflect` (per channel) and the weight `keep` of
// what lies under it (diffuse, transmission), from the exact Fresnel reflectance `f` at
// that angle; `lum` is the reflectance for lobe selection. Without KHR_materials_specular
// exactly Rgb(f), 1 - f, f. With it, as the extension's fresnel_mix: F0 = min(F0(ior) x
// specular_color, 1), the curve from it to 1 shaped as the exact one, the layer scaled by
// `specular` and the base kept at 1 - specular x max(F).
struct DielectricF {
  Rgb reflect;
  float keep, lum;
};
DielectricF dielectric_f(const Material& m, float f) {
  if (!m.specular_ext) return {Rgb(f), 1 - f, f};
  const float r = (m.ior - 1) / (m.ior + 1), f0 = r * r;
  const float shape = f0 < 1 ? std::clamp((f - f0) / (1 - f0), 0.0f, 1.0f) : 1.0f;
  const Rgb tinted = m.specular_color * f0;
  const Rgb c0(std::min(tinted.r, 1.0f), std::min(tinted.g, 1.0f), std::min(tinted.b, 1.0f));
  const Rgb fr = (c0 + (Rgb(1.0f) - c0) * shape) * m.specular;
  return {fr, 1 - fr.max(), fr.luminance()};
}

// Lobe probabilities for wo: specular reflection, diffuse, transmission (sum 1).
BsdfLobes pbr_lobes(const Material& m, Vec3 wo) {
  const PbrWeights w = pbr_weights(m);
  const float c = std::fabs(wo.z);
  // A component of weight 0 adds +0 (its Fresnel is finite, ior in [1, 1e4]): skipped.
  const DielectricF fc = w.coat > 0 ? dielectric_f(m, fresnel_dielectric(c, m.ior)) : DielectricF{};
  const DielectricF fg = w.glass > 0 ? dielectric_f(m, glass_fresnel(m, wo.z)) : DielectricF{};
  const float base = m.reflectance.luminance();
  BsdfLobes p;
  p.spec = w.metal * schlick(m.reflectance, c).luminance() + w.coat * fc.lum + w.glass * fg.lum;
  p.trans = w.glass > 0 ? w.glass * fg.keep * base : 0;
  // Floors keep every rough lobe that can be non-zero samplable (an unbiased mixture needs
  // it; an identically zero one, pbr_no_specular, needs none). A smooth lobe's albedo is
  // exact, so a delta lobe of albedo 0 is never chosen.
  if (!pbr_smooth(m)) {
    if (!pbr_no_specular(m)) p.spec = std::max(p.spec, 0.05f);
    if (w.glass > 0 && base > 0) p.trans = std::max(p.trans, 0.02f);
  }
  if (w.coat > 0 && base > 0) p.diffuse = std::max(w.coat * fc.keep * base, 0.02f);
  const float sum = p.spec + p.diffuse + p.trans;
  if (!(sum > 0)) return BsdfLobes{};
  p.spec /= sum;
  p.diffuse /= sum;
  p.trans /= sum;
  return p;
}

// The non-delta part of f(wo, wi) (kF) and the density of pbr_sample's non-delta lobes
// drawing wi (kPdf), in one pass: where both are wanted the half vector, D(h) and
// Lambda(wo) are computed once (Lambda is even in w, so Lambda(wo) = Lambda(wo_up)).
// `lobes`: pbr_lobes(m, wo), for kPdf (null otherwise).
template <bool kF, bool kPdf>
void pbr_eval(const Material& m, const BsdfLobes* lobes, Vec3 wo, Vec3 wi, Rgb* f_out, float* pdf_out) {
  if constexpr (kF) *f_out = Rgb(0);
  if constexpr (kPdf) *pdf_out = 0;
  const float co = wo.z, ci = wi.z;
  if (co == 0 || ci == 0) return;
  BsdfLobes p;
  if constexpr (kPdf) p = *lobes;
  const PbrWeights w = pbr_weights(m);
  const bool smooth = pbr_smooth(m);
  const Ggx g(m.alpha);
  const Vec3 wo_up = co > 0 ? wo : -wo;
  if (co * ci > 0) {
    Vec3 h;
    const bool has_h = reflection_half(wo, wi, &h);
    if constexpr (kPdf) *pdf_out = p.diffuse * std::fabs(ci) * kInvPi;
    if (!has_h) return;           // (f is then 0, its diffuse part too)
    const float oh = dot(wo, h);  // negative inside
    DielectricF fc{};             // (a component of weight 0 adds +0: its Fresnel is skipped)
    if constexpr (kF) {
      if (w.coat > 0) {
        fc = dielectric_f(m, fresnel_dielectric(std::fabs(oh), m.ior));
        *f_out += m.reflectance * (w.coat * fc.keep * kInvPi);
      }
    }
    if (smooth || pbr_no_specular(m)) return;
    const float d = g.d(h), lambda_o = g.lambda(wo);
    if constexpr (kF) {
      const float spec = d * g.g2(lambda_o, wi) / (4 * std::fabs(co * ci));
      if (w.metal > 0) *f_out += schlick(m.reflectance, std::fabs(oh)) * (w.metal * spec);
      const Rgb glass = w.glass > 0 ? dielectric_f(m, glass_fresnel(m, oh)).reflect * w.glass : Rgb(0);
      *f_out = *f_out + (fc.reflect * w.coat + glass) * spec;
    }
    if constexpr (kPdf) *pdf_out += p.spec * g.pdf_visible(wo_up, h, lambda_o, d) / (4 * std::fabs(oh));
    return;
  }
  const bool want_f = kF && w.glass > 0, want_pdf = kPdf && p.trans > 0;
  if (smooth || pbr_index_matched(m) || !(want_f || want_pdf)) return;
  if (m.thin) {  // the reflection lobe mirrored through the surface
    const Vec3 wr{wi.x, wi.y, -wi.z};
    Vec3 h;
    if (!reflection_half(wo, wr, &h)) return;
    const float d = g.d(h), lambda_o = g.lambda(wo), oh = dot(wo, h);
    if (want_f) {
      const float spec = d * g.g2(lambda_o, wr) / (4 * std::fabs(co * ci));
      *f_out = m.reflectance * (w.glass * dielectric_f(m, glass_fresnel(m, oh)).keep * spec);
    }
    if (want_pdf) *pdf_out = p.trans * g.pdf_visible(wo_up, h, lambda_o, d) / (4 * std::fabs(oh));
    return;
  }
  Vec3 h;
  float etap;
  if (!refraction_half(m, wo, wi, &h, &etap)) return;
  const float oh = dot(wo, h), ih = dot(wi, h);
  const float d = g.d(h), lambda_o = g.lambda(wo);
  if (want_f) {
    const float denom = (ih + oh / etap) * (ih + oh / etap) * ci * co;
    const float ft = d * dielectric_f(m, glass_fresnel(m, oh)).keep * g.g2(lambda_o, wi) * std::fabs(ih * oh / denom);
    *f_out = m.reflectance * (w.glass * ft / (etap * etap));  // radiance scaled by 1/eta^2, as glass
  }
  if (want_pdf)
    *pdf_out = p.trans * g.pdf_visible(wo_up, h, lambda_o, d) * std::fabs(ih) / ((ih + oh / etap) * (ih + oh / etap));
}

bool pbr_sample(const Material& m, const BsdfLobes& p, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
  const float co = wo.z;
  if (co == 0) return false;
  if (p.spec + p.diffuse + p.trans <= 0) return false;  // black: nothing scatters
  const PbrWeights w = pbr_weights(m);
  const bool smooth = pbr_smooth(m);
  const Vec3 wo_up = co > 0 ? wo : -wo;
  out->etap = 1;
  out->delta = false;
  if (u1 < p.diffuse) {
    const Vec3 d = square_to_cosine_hemisphere(u2);
    out->wi = co > 0 ? d : Vec3{d.x, d.y, -d.z};
  } else if (smooth) {  // a delta lobe: weight = its albedo / its probability
    out->delta = true;
    out->pdf = 1;
    const float c = std::fabs(co);
    if (u1 < p.diffuse + p.spec) {
      out->wi = reflect_z(wo);
      const Rgb fd = dielectric_f(m, fresnel_dielectric(c, m.ior)).reflect * w.coat +
                     dielectric_f(m, glass_fresnel(m, co)).reflect * w.glass;
      out->weight = (schlick(m.reflectance, c) * w.metal + fd) / p.spec;
      return true;
    }
    const float t = w.glass * dielectric_f(m, glass_fresnel(m, co)).keep / p.trans;
    if (m.thin) {
      out->wi = -wo;
      out->weight = m.reflectance * t;
      return t > 0;
    }
    if (!refract(wo, Vec3{0, 0, 1}, m.ior, &out->wi, &out->etap)) return false;
    out->weight = m.reflectance * (t / (out->etap * out->etap));
    return t > 0;
  } else if (u1 >= p.diffuse + p.spec && p.trans > 0 && pbr_index_matched(m)) {  // straight through
    out->delta = true;
    out->pdf = 1;
    out->wi = -wo;
    const float t = w.glass * dielectric_f(m, glass_fresnel(m, co)).keep / p.trans;
    out->weight = m.reflectance * t;
    return t > 0;
  } else {
    const Ggx g(m.alpha);
    const Vec3 h = g.sample_visible(wo_up, u2);  // facing +z, the exterior, as refract() wants
    const bool reflect = u1 < p.diffuse + p.spec || p.trans <= 0;
    if (reflect || m.thin) {
      const Vec3 wr = h * (2 * dot(wo, h)) - wo;
      out->wi = reflect ? wr : Vec3{wr.x, wr.y, -wr.z};         // thin: mirrored through the surface
    } else if (!refract(wo, h, m.ior, &out->wi, &out->etap)) {  // sets etap
      return false;
    }
    if (reflect ? out->wi.z * co <= 0 : out->wi.z * co >= 0) return false;  // on the wrong side
  }
  Rgb f;
  pbr_eval<true, true>(m, &p, wo, out->wi, &f, &out->pdf);
  if (!(out->pdf > 0)) return false;
  out->weight = f * (std::fabs(out->wi.z) / out->pdf);
  return true;
}

// ---- KHR_materials_sheen over kPbr ----------------------------------------------------
// The extension's albedo scaling: f = sheenColor f_sheen + f_base s, s = min(1 - c E(wo),
// 1 - c E(wi)) with c = max(sheenColor) and E the white lobe's directional albedo
// (core/bsdf/sheen.h). The lobe is two-sided as the base's are. Sampling picks the sheen
// with probability from c E(wo) (in [0.1, 0.9]; 1 over a black base), drawing a cosine
// direction on wo's side, else the base; the density is the mixture's.

bool has_sheen(const Material& m) { return m.sheen_color.max() > 0; }
// e_wo: the lobe's albedo at wo, sheen_albedo(wo.z, alpha) (BsdfLobes::sheen_wo).
float sheen_scale(const Material& m, float alpha, float e_wo, Vec3 wi) {
  const float c = m.sheen_color.max();
  return std::min(1 - c * e_wo, 1 - c * sheen_albedo(wi.z, alpha));
}
float sheen_probability(const Material& m, const BsdfLobes& base) {
  if (base.spec + base.diffuse + base.trans <= 0) return 1;
  return std::clamp(m.sheen_color.max() * base.sheen_wo, 0.1f, 0.9f);
}
// The lobe with the caller's frame flipped so that wo is up.
float sheen_lobe_f(float alpha, Vec3 wo, Vec3 wi) {
  if (wo.z * wi.z <= 0) return 0;
  return wo.z > 0 ? sheen_f(alpha, wo, wi) : sheen_f(alpha, -wo, -wi);
}

// f (kF) and the density (kPdf; `lobes` = pbr_lobes(m, wo)) of the sheen over the base, in
// one pass where both are wanted: the base's once (pbr_eval).
template <bool kF, bool kPdf>
void sheened_eval(const Material& m, const BsdfLobes* lobes, Vec3 wo, Vec3 wi, Rgb* f_out, float* pdf_out) {
  if (!has_sheen(m)) return pbr_eval<kF, kPdf>(m, lobes, wo, wi, f_out, pdf_out);
  const float alpha = sheen_alpha(m.sheen_roughness);
  float ps = 1;
  if constexpr (kPdf) ps = sheen_probability(m, *lobes);
  Rgb base(0);
  float base_pdf = 0;
  if (kPdf && ps < 1)
    pbr_eval<kF, true>(m, lobes, wo, wi, &base, &base_pdf);
  else if constexpr (kF)
    pbr_eval<true, false>(m, nullptr, wo, wi, &base, nullptr);
  if constexpr (kF) {
    const float e_wo = lobes ? lobes->sheen_wo : sheen_albedo(wo.z, alpha);
    *f_out = m.sheen_color * sheen_lobe_f(alpha, wo, wi) + base * sheen_scale(m, alpha, e_wo, wi);
  }
  if constexpr (kPdf) {
    const float cosine = wo.z * wi.z > 0 ? std::fabs(wi.z) * kInvPi : 0;
    *pdf_out = ps * cosine + (ps < 1 ? (1 - ps) * base_pdf : 0);
  }
}

bool sheened_sample(const Material& m, const BsdfLobes& lobes, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
  if (!has_sheen(m)) return pbr_sample(m, lobes, wo, u1, u2, out);
  if (wo.z == 0) return false;
  const float alpha = sheen_alpha(m.sheen_roughness), ps = sheen_probability(m, lobes);
  if (u1 < ps) {  // the sheen: a cosine direction on wo's side
    const Vec3 d = square_to_cosine_hemisphere(u2);
    out->wi = wo.z > 0 ? d : Vec3{d.x, d.y, -d.z};
    out->delta = false;
    out->etap = 1;
  } else {  // the base, its own choice of lobe from the rest of u1
    if (!pbr_sample(m, lobes, wo, std::min((u1 - ps) / (1 - ps), 0x1.fffffep-1f), u2, out)) return false;
    if (out->delta) {  // a delta lobe of the base, scaled under the sheen
      out->weight = out->weight * (sheen_scale(m, alpha, lobes.sheen_wo, out->wi) / (1 - ps));
      return true;
    }
  }
  Rgb f;
  sheened_eval<true, true>(m, &lobes, wo, out->wi, &f, &out->pdf);
  if (!(out->pdf > 0)) return false;
  out->weight = f * (std::fabs(out->wi.z) / out->pdf);
  return true;
}

// ---- KHR_materials_clearcoat over kPbr -------------------------------------------------
// The extension's fresnel_coat: f = (1 - c Fc) f_base + c Fc f_coat, with Fc Schlick's
// reflectance of an ior-1.5 coat (F0 = 0.04) at the viewing angle |wo.z| and f_coat a GGX
// specular lobe of the coat's roughness without Fresnel; every lobe is two-sided as the
// base's are. Sampling picks the coat with probability from c Fc (floored while the coat
// is rough, so that every lobe that can be non-zero is samplable), else the base; the
// density is the mixture's. A smooth coat is a delta lobe of albedo c Fc.

constexpr float kCoatF0 = 0.04f;  // ((1.5 - 1) / (1.5 + 1))^2

// clearcoatNormalTexture: the coat's own normal (Material::coat_normal, in the base's
// shading frame). Its lobe and Fresnel are those of a coat whose normal is z in the coat's
// frame; without a map the vectors pass unturned.
struct CoatFrame {
  explicit CoatFrame(const Material& m) : tilted(m.coat_normal.z < 1), f(tilted ? Frame(m.coat_normal) : Frame()) {}
  Vec3 in(Vec3 v) const { return tilted ? f.to_local(v) : v; }
  Vec3 out(Vec3 v) const { return tilted ? f.to_world(v) : v; }
  bool tilted;
  Frame f;
};

float coat_fresnel(const Material& m, Vec3 wo) {
  const float x = 1 - std::min(std::fabs(wo.z), 1.0f), x5 = x * x * x * x * x;
  return m.clearcoat * (kCoatF0 + (1 - kCoatF0) * x5);
}
bool coat_smooth(const Material& m) { return m.clearcoat_alpha < Material::kSmoothAlpha; }
// Probability of sampling the coat.
float coat_probability(const Material& m, Vec3 wo) {
  const float p = coat_fresnel(m, wo);
  return coat_smooth(m) ? p : std::clamp(p, 0.05f, 0.95f);
}
float coat_f(const Material& m, Vec3 wo, Vec3 wi) {
  Vec3 h;
  if (coat_smooth(m) || wo.z * wi.z <= 0 || !reflection_half(wo, wi, &h)) return 0;
  const Ggx g(m.clearcoat_alpha);
  return g.d(h) * g.g2(wo, wi) / (4 * std::fabs(wo.z * wi.z));
}
float coat_pdf(const Material& m, Vec3 wo, Vec3 wi) {
  Vec3 h;
  if (coat_smooth(m) || wo.z * wi.z <= 0 || !reflection_half(wo, wi, &h)) return 0;
  const Vec3 wo_up = wo.z > 0 ? wo : -wo;
  return Ggx(m.clearcoat_alpha).pdf_visible(wo_up, h) / (4 * std::fabs(dot(wo, h)));
}

// f (kF) and the density (kPdf; `lobes` = pbr_lobes(m, wo)) of the coat over the sheened
// base, in one pass where both are wanted: the base's once (sheened_eval).
template <bool kF, bool kPdf>
void coated_eval(const Material& m, const BsdfLobes* lobes, Vec3 wo, Vec3 wi, Rgb* f_out, float* pdf_out) {
  if (m.clearcoat <= 0) return sheened_eval<kF, kPdf>(m, lobes, wo, wi, f_out, pdf_out);
  Rgb base(0);
  float base_pdf = 0;
  sheened_eval<kF, kPdf>(m, lobes, wo, wi, &base, &base_pdf);
  const CoatFrame c(m);
  const Vec3 co = c.in(wo), ci = c.in(wi);
  if constexpr (kF) {
    const float fc = coat_fresnel(m, co);
    // A tilted coat's lobe reflects as it would about its own normal: its cosine, not the
    // base's, weighs it (f |cos_base| = f_coat |cos_coat|), so it never gains energy.
    const float cos_ratio = c.tilted ? std::fabs(ci.z) / std::max(std::fabs(wi.z), 1e-7f) : 1;
    *f_out = base * (1 - fc) + Rgb(fc * coat_f(m, co, ci) * cos_ratio);
  }
  if constexpr (kPdf) {
    const float pc = coat_probability(m, co);
    *pdf_out = (1 - pc) * base_pdf + pc * coat_pdf(m, co, ci);  // (densities turn unchanged)
  }
}

bool coated_sample(const Material& m, const BsdfLobes& lobes, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
  if (m.clearcoat <= 0) return sheened_sample(m, lobes, wo, u1, u2, out);
  if (wo.z == 0) return false;
  const CoatFrame c(m);
  const Vec3 co = c.in(wo);
  if (co.z == 0) return false;
  const float pc = coat_probability(m, co), fc = coat_fresnel(m, co);
  if (u1 < pc) {  // the coat
    out->etap = 1;
    if (coat_smooth(m)) {
      out->wi = c.out(reflect_z(co));
      out->delta = true;
      out->pdf = 1;
      out->weight = Rgb(fc / pc);
      return fc > 0;
    }
    const Vec3 wo_up = co.z > 0 ? co : -co;
    const Vec3 h = Ggx(m.clearcoat_alpha).sample_visible(wo_up, u2);
    const Vec3 wi = h * (2 * dot(co, h)) - co;
    if (wi.z * co.z <= 0) return false;
    out->wi = c.out(wi);
    out->delta = false;
  } else {  // the base, its own choice of lobe from the rest of u1
    if (!sheened_sample(m, lobes, wo, std::min((u1 - pc) / (1 - pc), 0x1.fffffep-1f), u2, out)) return false;
    if (out->delta) {  // a delta lobe of the base: its weight, under the coat
      out->weight = out->weight * ((1 - fc) / (1 - pc));
      return true;
    }
  }
  Rgb f;
  coated_eval<true, true>(m, &lobes, wo, out->wi, &f, &out->pdf);
  if (!(out->pdf > 0)) return false;
  out->weight = f * (std::fabs(out->wi.z) / out->pdf);
  return true;
}

}  // namespace

Rgb bsdf_eval(const Material& m, Vec3 wo, Vec3 wi) {
  switch (m.kind) {
    case Material::Kind::kDiffuse:
      return (wo.z > 0 && wi.z > 0) ? m.reflectance * kInvPi : Rgb(0);
    case Material::Kind::kMicrofacet:
      return microfacet_f(m, wo, wi);
    case Material::Kind::kPbr: {
      Rgb f;
      coated_eval<true, false>(m, nullptr, wo, wi, &f, nullptr);
      return f;
    }
    default:
      return Rgb(0);
  }
}

Rgb bsdf_eval_pdf(const Material& m, const BsdfLobes& lobes, Vec3 wo, Vec3 wi, float* pdf) {
  if (m.kind != Material::Kind::kPbr) {
    *pdf = bsdf_pdf(m, lobes, wo, wi);
    return bsdf_eval(m, wo, wi);
  }
  Rgb f;
  coated_eval<true, true>(m, &lobes, wo, wi, &f, pdf);
  return f;
}

BsdfLobes bsdf_lobes(const Material& m, Vec3 wo) {
  if (m.kind != Material::Kind::kPbr) return BsdfLobes{};
  BsdfLobes lobes = pbr_lobes(m, wo);
  if (has_sheen(m)) lobes.sheen_wo = sheen_albedo(wo.z, sheen_alpha(m.sheen_roughness));
  return lobes;
}

float bsdf_pdf(const Material& m, Vec3 wo, Vec3 wi) { return bsdf_pdf(m, bsdf_lobes(m, wo), wo, wi); }

float bsdf_pdf(const Material& m, const BsdfLobes& lobes, Vec3 wo, Vec3 wi) {
  switch (m.kind) {
    case Material::Kind::kDiffuse:
      return (wo.z > 0) ? cosine_hemisphere_pdf(wi.z) : 0;
    case Material::Kind::kMicrofacet:
      return microfacet_pdf(m, wo, wi);
    case Material::Kind::kPbr: {
      float pdf;
      coated_eval<false, true>(m, &lobes, wo, wi, nullptr, &pdf);
      return pdf;
    }
    default:
      return 0;
  }
}

bool bsdf_sample(const Material& m, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
  return bsdf_sample(m, bsdf_lobes(m, wo), wo, u1, u2, out);
}

bool bsdf_sample(const Material& m, const BsdfLobes& lobes, Vec3 wo, float u1, Vec2 u2, BsdfSample* out) {
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
    case Material::Kind::kPbr:
      return coated_sample(m, lobes, wo, u1, u2, out);
    case Material::Kind::kEmission:
      return false;
  }
  return false;
}

float delta_adjoint_factor(const Material& m, Vec3 wo, Vec3 wi) {
  if (m.kind != Material::Kind::kPbr || m.clearcoat <= 0) return 1;
  const CoatFrame c(m);
  const float through_wo = 1 - coat_fresnel(m, c.in(wo));
  return through_wo > 0 ? (1 - coat_fresnel(m, c.in(wi))) / through_wo : 0;
}

}  // namespace tessera
