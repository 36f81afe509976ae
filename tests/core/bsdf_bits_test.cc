// The BSDFs' bits, recorded: bsdf_eval, bsdf_pdf and bsdf_sample over 400,000 random
// materials (diffuse, Beckmann conductors, and glTF PBR with every mix of metal, rough and
// thin glass, KHR_materials_specular, sheen and clearcoat) and directions, hashed. A
// change meant to be faster and not different (core/bsdf/bsdf.cc's pbr_eval was one) must
// keep the hash; one that changes the physics re-records it and says why.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <cstring>

#include "core/bsdf/bsdf.h"
#include "core/math/hash.h"
#include "core/sampling/sampler.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

struct Hasher {
  uint64_t h = 0;
  void put(float f) { h = mix64(h ^ std::bit_cast<uint32_t>(f)); }
  void put(Rgb c) { put(c.r), put(c.g), put(c.b); }
  void put(Vec3 v) { put(v.x), put(v.y), put(v.z); }
};

Material random_material(uint64_t i, Sampler& s) {
  Material m;
  m.kind = Material::Kind::kPbr;
  m.metallic = s.next_1d() < 0.3f ? 0 : s.next_1d();
  m.transmission = s.next_1d() < 0.5f ? 0 : s.next_1d();
  const float r = s.next_1d();
  m.roughness = r < 0.1f ? 0 : r;  // a tenth smooth (delta lobes)
  m.alpha = m.roughness * m.roughness;
  m.ior = 1.0f + s.next_1d();
  m.thin = s.next_1d() < 0.5f;
  m.reflectance = Rgb(s.next_1d(), s.next_1d(), s.next_1d());
  m.specular_ext = s.next_1d() < 0.3f;
  m.specular = s.next_1d();
  m.specular_color = Rgb(s.next_1d(), 1, s.next_1d() * 2);
  if (s.next_1d() < 0.3f) {
    m.sheen_color = Rgb(s.next_1d(), s.next_1d(), 0.5f);
    m.sheen_roughness = s.next_1d();
  }
  if (s.next_1d() < 0.3f) {
    m.clearcoat = s.next_1d();
    m.clearcoat_alpha = s.next_1d() < 0.3f ? 0 : s.next_1d();
  }
  if (i % 7 == 0) {
    m.kind = Material::Kind::kMicrofacet;
    m.alpha = s.next_1d();
  }
  if (i % 11 == 0) m.kind = Material::Kind::kDiffuse;
  return m;
}

TEST(BsdfBits, SameAsRecorded) {
  Hasher h;
  size_t sampled = 0;
  for (uint64_t i = 0; i < 400000; ++i) {
    Sampler s(7, i, 0);
    const Material m = random_material(i, s);
    const Vec3 wo = square_to_uniform_sphere(s.next_2d()), wi = square_to_uniform_sphere(s.next_2d());
    h.put(bsdf_eval(m, wo, wi));
    h.put(bsdf_pdf(m, wo, wi));
    BsdfSample b;
    const float u1 = s.next_1d();
    const Vec2 u2 = s.next_2d();
    const bool ok = bsdf_sample(m, wo, u1, u2, &b);
    h.put(float(ok));
    if (ok) {
      h.put(b.wi), h.put(b.weight), h.put(b.pdf), h.put(b.etap), h.put(float(b.delta));
      ++sampled;
    }
  }
  EXPECT_EQ(sampled, 332809u);
  EXPECT_EQ(h.h, 0xc8f0964b108d7e62ull) << std::hex << h.h;
}

// bsdf_eval_pdf, f and the density in one pass, gives the bits of bsdf_eval and bsdf_pdf.
TEST(BsdfBits, EvalPdfSameAsTheTwoCalls) {
  size_t differ = 0, nonzero = 0;
  for (uint64_t i = 0; i < 200000; ++i) {
    Sampler s(11, i, 0);
    const Material m = random_material(i, s);
    const Vec3 wo = square_to_uniform_sphere(s.next_2d()), wi = square_to_uniform_sphere(s.next_2d());
    float pdf = -1;
    const Rgb f = bsdf_eval_pdf(m, bsdf_lobes(m, wo), wo, wi, &pdf);
    const Rgb f2 = bsdf_eval(m, wo, wi);
    const float pdf2 = bsdf_pdf(m, wo, wi);
    differ += std::memcmp(&f, &f2, sizeof f) != 0 || std::memcmp(&pdf, &pdf2, sizeof pdf) != 0;
    nonzero += !f.is_black() && pdf > 0;
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(nonzero, 50000u);  // (the pairs are not mostly zero)
}

}  // namespace
}  // namespace tessera
