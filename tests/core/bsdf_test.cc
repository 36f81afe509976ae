// Fresnel, Snell's law, total internal reflection, and sampling of every BSDF.
#include "core/bsdf/bsdf.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/bsdf/fresnel.h"
#include "core/bsdf/microfacet.h"
#include "core/sampling/sampler.h"
#include "core/sampling/warp.h"
#include "tests/core/chi2.h"

namespace tessera {
namespace {

constexpr double kAlpha = 1e-3;

Vec3 dir(float theta) { return {std::sin(theta), 0, std::cos(theta)}; }

TEST(Fresnel, NormalIncidenceIsTheSquaredIndexRatio) {
  for (float n : {1.33f, 1.45f, 1.5f, 2.42f}) {
    const float r0 = ((n - 1) / (n + 1)) * ((n - 1) / (n + 1));
    EXPECT_NEAR(fresnel_dielectric(1, n), r0, 1e-6f);
    EXPECT_NEAR(fresnel_dielectric(-1, n), r0, 1e-6f);  // same from inside
  }
}

TEST(Fresnel, AtBrewstersAngleOnlyThePerpendicularPartReflects) {
  const float n = 1.5f, theta_b = std::atan(n);
  const float ci = std::cos(theta_b), st = std::sin(theta_b) / n, ct = std::sqrt(1 - st * st);
  const float r_perp = (ci - n * ct) / (ci + n * ct);
  EXPECT_NEAR(fresnel_dielectric(ci, n), 0.5f * r_perp * r_perp, 1e-6f);
}

TEST(Fresnel, KnownValueForGlassAt60Degrees) {
  // n = 1.5, 60 degrees: Rs = 0.1770, Rp = 0.0017 (textbook values), F = 0.0894.
  EXPECT_NEAR(fresnel_dielectric(0.5f, 1.5f), 0.5f * (0.17703f + 0.00170f), 2e-4f);
}

TEST(Fresnel, TotalInternalReflectionBeyondTheCriticalAngle) {
  const float n = 1.5f, critical = std::asin(1 / n);
  EXPECT_LT(fresnel_dielectric(-std::cos(critical - 0.01f), n), 1.0f);
  EXPECT_EQ(fresnel_dielectric(-std::cos(critical + 0.01f), n), 1.0f);
  Vec3 wt;
  float etap;
  // From inside: wo below the surface at more than the critical angle cannot refract.
  const Vec3 wo_inside{std::sin(critical + 0.01f), 0, -std::cos(critical + 0.01f)};
  EXPECT_FALSE(refract(wo_inside, Vec3{0, 0, 1}, n, &wt, &etap));
}

TEST(Fresnel, IndexOneIsInvisible) {
  for (float t = 0; t < 1.5f; t += 0.1f) {
    EXPECT_NEAR(fresnel_dielectric(std::cos(t), 1.0f), 0.0f, 1e-7f);
    Vec3 wt;
    float etap;
    ASSERT_TRUE(refract(dir(t), Vec3{0, 0, 1}, 1.0f, &wt, &etap));
    EXPECT_NEAR(wt.x, -dir(t).x, 1e-6f);
    EXPECT_NEAR(wt.z, -dir(t).z, 1e-6f);
  }
}

TEST(Snell, RefractedDirectionObeysSnellsLawBothWays) {
  const float n = 1.45f;
  for (float t = 0.05f; t < 1.5f; t += 0.1f) {
    Vec3 wt;
    float etap;
    ASSERT_TRUE(refract(dir(t), Vec3{0, 0, 1}, n, &wt, &etap));
    EXPECT_NEAR(length(wt), 1.0f, 1e-5f);
    EXPECT_LT(wt.z, 0);
    EXPECT_NEAR(std::sin(t), n * std::sqrt(wt.x * wt.x + wt.y * wt.y), 1e-5f);
    EXPECT_FLOAT_EQ(etap, n);
    Vec3 back;  // reciprocity: refracting the transmitted direction gives wo back
    ASSERT_TRUE(refract(wt, Vec3{0, 0, 1}, n, &back, &etap));
    EXPECT_NEAR(back.x, dir(t).x, 1e-5f);
    EXPECT_NEAR(back.z, dir(t).z, 1e-5f);
    EXPECT_FLOAT_EQ(etap, 1 / n);
  }
}

TEST(Bsdf, GlassChoosesReflectionWithTheFresnelProbability) {
  Material glass;
  glass.kind = Material::Kind::kGlass;
  glass.ior = 1.5f;
  glass.reflectance = glass.transmittance = Rgb(1);
  for (float t : {0.0f, 0.7f, 1.3f}) {
    const Vec3 wo = dir(t);
    const int n = 100000;
    int reflected = 0;
    for (int i = 0; i < n; ++i) {
      BsdfSample s;
      ASSERT_TRUE(bsdf_sample(glass, wo, (i + 0.5f) / n, Vec2{0.5f, 0.5f}, &s));
      EXPECT_TRUE(s.delta);
      if (s.wi.z > 0) {
        ++reflected;
        EXPECT_EQ(s.weight.r, 1.0f);
      } else {
        // Radiance crossing into the denser medium is scaled by 1 / eta^2.
        EXPECT_NEAR(s.weight.r, 1 / (1.5f * 1.5f), 1e-6f);
      }
    }
    EXPECT_NEAR(double(reflected) / n, fresnel_dielectric(wo.z, 1.5f), 1e-4);
  }
}

TEST(Bsdf, GlassReflectsTotallyInsideBeyondTheCriticalAngle) {
  Material glass;
  glass.kind = Material::Kind::kGlass;
  glass.ior = 1.5f;
  const Vec3 wo{std::sin(0.9f), 0, -std::cos(0.9f)};  // inside, 51.6 deg > 41.8 deg
  for (float u : {0.0f, 0.5f, 0.999f}) {
    BsdfSample s;
    ASSERT_TRUE(bsdf_sample(glass, wo, u, {}, &s));
    EXPECT_LT(s.wi.z, 0);  // stays inside
    EXPECT_NEAR(s.wi.x, -wo.x, 1e-6f);
  }
}

TEST(Bsdf, RefractionOnlyEndsUnderTotalInternalReflection) {
  Material m;
  m.kind = Material::Kind::kRefraction;
  m.ior = 1.45f;
  BsdfSample s;
  EXPECT_FALSE(bsdf_sample(m, Vec3{std::sin(1.2f), 0, -std::cos(1.2f)}, 0.5f, {}, &s));
  EXPECT_TRUE(bsdf_sample(m, dir(1.2f), 0.5f, {}, &s));
  EXPECT_LT(s.wi.z, 0);
}

TEST(Bsdf, MirrorReflectsAboutTheNormal) {
  Material m;
  m.kind = Material::Kind::kMirror;
  m.reflectance = Rgb(1.0f, 0.8f, 0.4f);
  BsdfSample s;
  ASSERT_TRUE(bsdf_sample(m, Vec3{0.6f, 0, 0.8f}, 0, {}, &s));
  EXPECT_FLOAT_EQ(s.wi.x, -0.6f);
  EXPECT_FLOAT_EQ(s.wi.z, 0.8f);
  EXPECT_FLOAT_EQ(s.weight.g, 0.8f);
}

TEST(Bsdf, DiffuseSamplingMatchesItsPdfAndWeightIsTheAlbedo) {
  Material m;
  m.reflectance = Rgb(0.6f);
  const Vec3 wo = normalize(Vec3{0.3f, 0.2f, 0.9f});
  const auto r = testing::chi2_directions(
      [&](int i) -> std::optional<Vec3> {
        Sampler sp(3, 0, uint32_t(i));
        BsdfSample s;
        if (!bsdf_sample(m, wo, sp.next_1d(), sp.next_2d(), &s)) return std::nullopt;
        EXPECT_FLOAT_EQ(s.weight.r, 0.6f);
        return s.wi;
      },
      [&](Vec3 wi) { return double(bsdf_pdf(m, wo, wi)); }, 200000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

// Chi-square of bsdf_sample's directions against bsdf_pdf over the whole sphere (40 x 80
// cells), each sample a non-delta one whose weight is f |cos| / pdf in every channel, from
// bsdf_eval and bsdf_pdf.
testing::Chi2Result sample_against_pdf(const Material& m, Vec3 wo, uint64_t seed, int n) {
  return testing::chi2_directions(
      [&](int i) -> std::optional<Vec3> {
        Sampler sp(seed, 0, uint32_t(i));
        BsdfSample s;
        const float u1 = sp.next_1d();
        if (!bsdf_sample(m, wo, u1, sp.next_2d(), &s)) return std::nullopt;
        EXPECT_FALSE(s.delta);
        const Rgb f = bsdf_eval(m, wo, s.wi) * (std::fabs(s.wi.z) / bsdf_pdf(m, wo, s.wi));
        for (const auto& [got, expect] : {std::pair{s.weight.r, f.r}, {s.weight.g, f.g}, {s.weight.b, f.b}})
          EXPECT_NEAR(got, expect, 1e-3f * std::max(1.0f, expect));
        return s.wi;
      },
      [&](Vec3 wi) { return double(bsdf_pdf(m, wo, wi)); }, n, 40, 80);
}

class MicrofacetTest : public ::testing::TestWithParam<std::tuple<float, float>> {};

TEST_P(MicrofacetTest, ImportanceSamplingMatchesItsPdf) {
  const auto [alpha, theta] = GetParam();
  Material m;
  m.kind = Material::Kind::kMicrofacet;
  m.alpha = alpha;
  m.eta = Rgb(0.2f);
  m.k = Rgb(3.9f);
  const auto r = sample_against_pdf(m, dir(theta), 9, 300000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

INSTANTIATE_TEST_SUITE_P(AlphasAndAngles, MicrofacetTest,
                         ::testing::Values(std::make_tuple(0.05f, 0.3f), std::make_tuple(0.25f, 0.0f),
                                           std::make_tuple(0.25f, 1.0f), std::make_tuple(0.5f, 1.3f)));

TEST(Microfacet, BeckmannProjectedAreaIsOne) {
  // Integral of D(h) cos(theta_h) over the hemisphere is 1 (normalisation of D).
  for (float alpha : {0.05f, 0.25f, 0.6f}) {
    const Beckmann d(alpha);
    double sum = 0;
    const int nt = 4000;
    for (int i = 0; i < nt; ++i) {
      const double t = (i + 0.5) / nt * M_PI / 2;
      const Vec3 h{float(std::sin(t)), 0, float(std::cos(t))};
      sum += d.d(h) * std::cos(t) * std::sin(t) * (M_PI / 2 / nt) * 2 * M_PI;
    }
    EXPECT_NEAR(sum, 1.0, 2e-3) << alpha;
  }
}

TEST(Microfacet, ConductorFresnelIsOneForAPerfectConductor) {
  EXPECT_NEAR(fresnel_conductor(0.5f, 0.0f, 1e4f), 1.0f, 1e-3f);
  // Gold-like eta/k at normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2).
  const float n = 0.2f, k = 3.0f;
  EXPECT_NEAR(fresnel_conductor(1.0f, n, k), ((n - 1) * (n - 1) + k * k) / ((n + 1) * (n + 1) + k * k), 1e-5f);
}

// ---- GGX and the glTF metallic-roughness model (kPbr) ----------------------------------

TEST(Ggx, ProjectedAreaAndVisibleNormalsAreNormalised) {
  // Integral of D(h) cos(theta_h) is 1; of the visible-normal density, 1 for any wo.
  for (float alpha : {0.02f, 0.2f, 0.7f, 1.0f}) {
    const Ggx g(alpha);
    const Vec3 wo = normalize(Vec3{0.6f, 0.1f, 0.5f});
    double area = 0, visible = 0;
    const int nt = 20000, np = 64;
    for (int i = 0; i < nt; ++i) {
      // Substitution t = theta^2 resolves the narrow peak of a small alpha.
      const double u = (i + 0.5) / nt, t = u * u * M_PI / 2, dt = 2 * u * M_PI / 2 / nt;
      for (int j = 0; j < np; ++j) {
        const double phi = (j + 0.5) / np * 2 * M_PI;
        const Vec3 h{float(std::sin(t) * std::cos(phi)), float(std::sin(t) * std::sin(phi)), float(std::cos(t))};
        const double dw = std::sin(t) * dt * 2 * M_PI / np;
        area += g.d(h) * std::cos(t) * dw;
        visible += g.pdf_visible(wo, h) * dw;
      }
    }
    EXPECT_NEAR(area, 1.0, 3e-3) << alpha;
    EXPECT_NEAR(visible, 1.0, 3e-3) << alpha;
  }
}

struct PbrCase {
  const char* name;
  float metallic, roughness, transmission;
  bool thin;
  float theta;  // of wo; > pi/2 is inside the object
  Rgb base{0.9f, 0.6f, 0.3f};
  float ior = 1.5f;
  // KHR_materials_specular, when `specular` >= 0.
  float specular = -1;
  Rgb specular_color{1.0f};
  float clearcoat = 0, clearcoat_roughness = 0;  // KHR_materials_clearcoat
  Vec3 coat_normal{0, 0, 1};                     // clearcoatNormalTexture's, in the shading frame
  Rgb sheen{0.0f};                               // KHR_materials_sheen
  float sheen_roughness = 0;
};
void PrintTo(const PbrCase& c, std::ostream* os) { *os << c.name; }

Material pbr(const PbrCase& c) {
  Material m;
  m.kind = Material::Kind::kPbr;
  m.reflectance = c.base;
  m.metallic = c.metallic;
  m.roughness = c.roughness;
  m.alpha = c.roughness * c.roughness;
  m.transmission = c.transmission;
  m.thin = c.thin;
  m.ior = c.ior;
  if (c.specular >= 0) {
    m.specular_ext = true;
    m.specular = c.specular;
    m.specular_color = c.specular_color;
  }
  m.clearcoat = c.clearcoat;
  m.clearcoat_roughness = c.clearcoat_roughness;
  m.clearcoat_alpha = c.clearcoat_roughness * c.clearcoat_roughness;
  m.coat_normal = c.coat_normal;
  m.sheen_color = c.sheen;
  m.sheen_roughness = c.sheen_roughness;
  return m;
}

class PbrTest : public ::testing::TestWithParam<PbrCase> {};

// The sampled directions follow bsdf_pdf over the whole sphere (reflection and
// transmission), and each weight is f |cos| / pdf from bsdf_eval and bsdf_pdf.
TEST_P(PbrTest, SamplingMatchesItsPdfAndTheWeightIsFCosOverPdf) {
  const PbrCase c = GetParam();
  const Material m = pbr(c);
  const auto r = sample_against_pdf(m, dir(c.theta), 11, 400000);
  EXPECT_GT(r.p_value, kAlpha) << r.describe();
}

// White furnace, per BSDF: the albedo (with the 1/eta^2 radiance scaling undone, which
// carries no energy) estimated by sampling equals the quadrature of f |cos| from
// bsdf_eval, and never exceeds 1 for a base colour of 1.
TEST_P(PbrTest, AlbedoBySamplingEqualsQuadratureAndNeverExceedsOne) {
  PbrCase c = GetParam();
  c.base = Rgb(1.0f);
  const Material m = pbr(c);
  const Vec3 wo = dir(c.theta);
  const int n = 400000;
  double sum = 0, sum2 = 0, radiance_sum = 0;
  for (int i = 0; i < n; ++i) {
    Sampler sp(5, 0, uint32_t(i));
    BsdfSample s;
    const float u1 = sp.next_1d();
    if (!bsdf_sample(m, wo, u1, sp.next_2d(), &s)) continue;
    const double w = s.weight.g * s.etap * s.etap;
    sum += w;
    sum2 += w * w;
    radiance_sum += s.weight.g;
  }
  const double mean = sum / n, err = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
  double quad = 0;  // over (z, phi): uniform in solid angle
  const int nz = 1200, np = 240;
  for (int i = 0; i < nz; ++i)
    for (int j = 0; j < np; ++j) {
      const double z = -1 + (i + 0.5) * 2 / nz, phi = (j + 0.5) * 2 * M_PI / np, r = std::sqrt(1 - z * z);
      const Vec3 wi{float(r * std::cos(phi)), float(r * std::sin(phi)), float(z)};
      quad += bsdf_eval(m, wo, wi).g * std::fabs(z) * (2.0 / nz) * (2 * M_PI / np);
    }
  EXPECT_LE(mean, 1 + 4 * err + 1e-6) << "albedo " << mean;  // (+ rounding: a Lambertian has no variance)
  EXPECT_GT(mean, 0.5) << "albedo " << mean;                 // GGX without multiple scattering loses some, not half
  // The quadrature misses the sharpest peaks of rough 0.2 a little: 1%.
  EXPECT_NEAR(radiance_sum / n, quad, 4 * err * 3 + 0.01 * quad)
      << "sampled " << radiance_sum / n << " quadrature " << quad;
}

// The extensions' cases: a base case with KHR_materials_specular, _clearcoat or _sheen added.
PbrCase with_specular(PbrCase c, float specular, Rgb color) {
  c.specular = specular;
  c.specular_color = color;
  return c;
}
PbrCase with_coat(PbrCase c, float clearcoat, float roughness) {
  c.clearcoat = clearcoat;
  c.clearcoat_roughness = roughness;
  return c;
}
PbrCase tilted(PbrCase c, Vec3 coat_normal) {
  c.coat_normal = normalize(coat_normal);
  return c;
}
PbrCase index_one(PbrCase c) {  // KHR_materials_ior 1: no specular reflection (bsdf.cc)
  c.ior = 1;
  return c;
}
PbrCase with_sheen(PbrCase c, Rgb color, float roughness) {
  c.sheen = color;
  c.sheen_roughness = roughness;
  return c;
}

INSTANTIATE_TEST_SUITE_P(
    Materials, PbrTest,
    ::testing::Values(
        PbrCase{"plastic", 0, 0.5f, 0, true, 0.6f}, PbrCase{"rough_plastic_grazing", 0, 0.9f, 0, true, 1.4f},
        PbrCase{"metal", 1, 0.3f, 0, true, 1.2f}, PbrCase{"half_metal", 0.5f, 0.7f, 0, true, 0.3f},
        PbrCase{"rough_glass_outside", 0, 0.3f, 1, false, 0.5f},
        PbrCase{"rough_glass_inside", 0, 0.3f, 1, false, float(M_PI) - 0.3f},
        PbrCase{"rough_glass_inside_beyond_critical", 0, 0.4f, 1, false, float(M_PI) - 1.0f},
        PbrCase{"thin_rough_transmission", 0, 0.4f, 1, true, 0.7f},
        PbrCase{"thin_from_behind", 0, 0.5f, 0.6f, true, float(M_PI) - 0.4f},
        PbrCase{"everything_mixed", 0.2f, 0.6f, 0.5f, false, 1.3f},
        index_one({"index_one_plastic", 0, 0.5f, 0, true, 0.6f}),
        index_one({"index_one_thin_rough_transmission", 0, 0.4f, 0.6f, true, 0.7f}),
        with_specular({"specular_tinted_plastic", 0, 0.5f, 0, true, 0.6f}, 0.6f, {1.0f, 0.5f, 0.2f}),
        with_specular({"specular_bright_rough_glass", 0, 0.3f, 1, false, 0.5f}, 0.5f, {8.0f, 4.0f, 1.0f}),
        with_specular({"specular_thin_inside", 0, 0.4f, 0.6f, true, float(M_PI) - 0.4f}, 0.8f, {1.0f, 1.0f, 3.0f}),
        with_coat({"rough_coat_on_plastic", 0, 0.6f, 0, true, 0.9f}, 1.0f, 0.3f),
        with_coat({"rough_coat_on_rough_metal", 1, 0.5f, 0, true, 1.2f}, 0.7f, 0.2f),
        with_coat({"rough_coat_on_rough_glass_inside", 0, 0.4f, 1, false, float(M_PI) - 0.5f}, 0.8f, 0.25f),
        tilted(with_coat({"tilted_rough_coat_on_plastic", 0, 0.6f, 0, true, 0.9f}, 1.0f, 0.3f), {0.3f, -0.2f, 1}),
        tilted(with_coat({"tilted_coat_on_rough_glass_inside", 0, 0.4f, 1, false, float(M_PI) - 0.5f}, 0.8f, 0.25f),
               {-0.2f, 0.1f, 1}),
        with_sheen({"white_sheen_on_plastic", 0, 0.7f, 0, true, 0.8f}, Rgb(1.0f), 0.5f),
        with_sheen({"smooth_sheen_grazing_on_metal", 1, 0.4f, 0, true, 1.45f}, {1.0f, 0.8f, 0.6f}, 0.07f),
        with_sheen({"rough_sheen_on_rough_glass_inside", 0, 0.4f, 1, false, float(M_PI) - 0.5f}, Rgb(0.8f), 1.0f),
        with_sheen(with_coat({"sheen_under_a_coat", 0, 0.6f, 0, true, 1.0f}, 0.7f, 0.3f), Rgb(1.0f), 0.3f)),
    [](const ::testing::TestParamInfo<PbrCase>& info) { return std::string(info.param.name); });

TEST(Pbr, IndexOneMakesTheDielectricExactlyLambertian) {
  PbrCase c{"lambert", 0, 0.5f, 0, true, 0.7f};
  c.ior = 1;
  const Material m = pbr(c);
  for (float t : {0.1f, 0.8f, 1.4f}) {
    const Rgb f = bsdf_eval(m, dir(0.7f), Vec3{std::sin(t) * 0.6f, std::sin(t) * 0.8f, std::cos(t)});
    EXPECT_NEAR(f.r, 0.9f / M_PI, 1e-6);
    EXPECT_NEAR(f.b, 0.3f / M_PI, 1e-6);
  }
  // And sampled as that: the cosine density exactly, every sample on the diffuse lobe with
  // the base colour as its weight (no share of samples for a specular lobe that is zero).
  const Vec3 wo = dir(0.7f);
  for (int i = 0; i < 1000; ++i) {
    const Vec2 u{(i % 31 + 0.5f) / 31, (i / 31 + 0.5f) / 33};
    BsdfSample s;
    ASSERT_TRUE(bsdf_sample(m, wo, (i % 97 + 0.5f) / 97, u, &s));
    EXPECT_EQ(s.pdf, cosine_hemisphere_pdf(s.wi.z));
    EXPECT_EQ(bsdf_pdf(m, wo, s.wi), cosine_hemisphere_pdf(s.wi.z));
    EXPECT_NEAR(s.weight.r, 0.9f, 1e-5f);
    EXPECT_NEAR(s.weight.b, 0.3f, 1e-5f);
  }
}

// A rough solid of ior 1 bends nothing: its transmission is a delta lobe straight through
// (the rough refraction lobe degenerates: sampling it gave NaN weights), beside the rest.
TEST(Pbr, IndexMatchedSolidTransmitsStraightThrough) {
  for (const float transmission : {1.0f, 0.5f})
    for (const float theta : {0.3f, 1.2f, float(M_PI) - 0.3f, float(M_PI) - 1.4f}) {
      PbrCase c{"index_matched", 0, 0.4f, transmission, false, theta};
      c.ior = 1;
      const Material m = pbr(c);
      const Vec3 wo = dir(theta);
      int straight = 0;
      double albedo = 0;
      for (int i = 0; i < 4000; ++i) {
        Sampler sp(3, 0, uint32_t(i));
        BsdfSample s;
        const float u1 = sp.next_1d();
        if (!bsdf_sample(m, wo, u1, sp.next_2d(), &s)) continue;
        ASSERT_TRUE(s.weight.is_finite() && std::isfinite(s.pdf)) << "theta " << theta;
        albedo += s.weight.g;
        if (s.delta) {
          ++straight;
          EXPECT_EQ(s.wi, -wo);
          EXPECT_EQ(s.etap, 1.0f);
        }
        EXPECT_TRUE(bsdf_eval(m, wo, s.wi).is_finite());
        EXPECT_TRUE(std::isfinite(bsdf_pdf(m, wo, s.wi)));
      }
      if (transmission == 1) {  // nothing else: every sample straight through, the base colour
        EXPECT_EQ(straight, 4000);
        EXPECT_NEAR(albedo / 4000, 0.6, 1e-6);
      } else if (theta < M_PI / 2) {  // outside: the diffuse half and the straight half
        EXPECT_GT(straight, 1000);
        EXPECT_LT(straight, 3000);
        EXPECT_NEAR(albedo / 4000, 0.6, 0.02);  // (0.5 diffuse + 0.5 transmitted) x 0.6
      }
    }
}

// KHR_materials_specular: factor 0 leaves a dielectric's diffuse alone (exactly Lambertian
// at any ior); factor 1 with a white colour is the plain model (same f).
TEST(Pbr, SpecularFactorScalesTheDielectricLayer) {
  PbrCase c{"no_specular", 0, 0.5f, 0, true, 0.7f};
  c.specular = 0;
  const Material m = pbr(c);
  c.specular = 1;
  const Material full = pbr(c);
  c.specular = -1;
  const Material plain = pbr(c);
  for (float t : {0.1f, 0.8f, 1.4f}) {
    const Vec3 wi{std::sin(t) * 0.6f, std::sin(t) * 0.8f, std::cos(t)};
    const Rgb f = bsdf_eval(m, dir(0.7f), wi);
    EXPECT_NEAR(f.r, 0.9f / M_PI, 1e-6);
    EXPECT_NEAR(f.b, 0.3f / M_PI, 1e-6);
    const Rgb a = bsdf_eval(full, dir(0.7f), wi), b = bsdf_eval(plain, dir(0.7f), wi);
    EXPECT_NEAR(a.r, b.r, 1e-6 * b.r + 1e-7);
    EXPECT_NEAR(a.g, b.g, 1e-6 * b.g + 1e-7);
  }
}

// A smooth clearcoat over a smooth metal: both lobes are deltas along the mirror
// direction, and the mean weight is the coat's Fresnel plus what it lets through of the
// metal's, c Fc + (1 - c Fc) Schlick(base).
TEST(Pbr, ASmoothCoatOverAMirrorAddsItsFresnelToWhatItLetsThrough) {
  const Material m = pbr(with_coat({"coat", 1, 0, 0, true, 1.1f}, 0.8f, 0));
  EXPECT_TRUE(m.is_delta());
  const Vec3 wo = dir(1.1f);
  const float c = wo.z, x = 1 - c, fc = 0.8f * (0.04f + 0.96f * x * x * x * x * x);
  const float schlick_g = 0.6f + 0.4f * x * x * x * x * x;
  double sum = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    Sampler sp(9, 0, uint32_t(i));
    BsdfSample s;
    ASSERT_TRUE(bsdf_sample(m, wo, sp.next_1d(), sp.next_2d(), &s));
    EXPECT_TRUE(s.delta);
    EXPECT_NEAR(s.wi.z, wo.z, 1e-6);
    sum += s.weight.g;
  }
  EXPECT_NEAR(sum / n, fc + (1 - fc) * schlick_g, 0.01);
  // A rough coat makes the same mirror a non-delta material.
  EXPECT_FALSE(pbr(with_coat({"rough", 1, 0, 0, true, 1.1f}, 0.8f, 0.3f)).is_delta());
}

TEST(Pbr, SmoothSurfacesAreDeltaLobes) {
  // A smooth white metal reflects everything about the normal.
  Material metal = pbr({"mirror", 1, 0, 0, true, 0.5f, Rgb(1.0f)});
  ASSERT_TRUE(metal.is_delta());
  BsdfSample s;
  ASSERT_TRUE(bsdf_sample(metal, dir(0.5f), 0.3f, {0.2f, 0.7f}, &s));
  EXPECT_TRUE(s.delta);
  EXPECT_FLOAT_EQ(s.wi.x, -std::sin(0.5f));
  EXPECT_FLOAT_EQ(s.weight.g, 1);
  EXPECT_TRUE(bsdf_eval(metal, dir(0.5f), dir(-0.5f)).is_black());  // nothing for light sampling
  // Smooth solid glass: reflection with probability ~ F, refraction with Snell's angle, and
  // both weights together conserve energy (eta^2 undone).
  const Material glass = pbr({"glass", 0, 0, 1, false, 0.8f, Rgb(1.0f)});
  ASSERT_TRUE(glass.is_delta());
  double energy = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(bsdf_sample(glass, dir(0.8f), (i + 0.5f) / n, {0.5f, 0.5f}, &s));
    if (s.wi.z < 0) {
      EXPECT_NEAR(std::sin(0.8f) / std::sqrt(1 - s.wi.z * s.wi.z), 1.5f, 1e-4f);
    }
    energy += s.weight.g * s.etap * s.etap / n;
  }
  EXPECT_NEAR(energy, 1.0, 1e-3);
  // Smooth plastic keeps its diffuse lobe for light sampling.
  const Material plastic = pbr({"plastic", 0, 0, 0, true, 0.5f});
  EXPECT_FALSE(plastic.is_delta());
  EXPECT_GT(bsdf_eval(plastic, dir(0.5f), dir(0.2f)).g, 0);
}

}  // namespace
}  // namespace tessera
