// KHR_materials_sheen's lobe (core/bsdf/sheen.h): the Charlie distribution's
// normalisation, the albedo table against a direct quadrature, and the layer's energy.
// Sampling and its density are chi-square tested with the other glTF lobes (bsdf_test.cc).
#include "core/bsdf/sheen.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/bsdf/bsdf.h"

namespace tessera {
namespace {

Vec3 dir(float theta, float phi = 0) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

// Integral of g(w) over the upper hemisphere, midpoint rule in (cos theta, phi).
template <class G>
double hemisphere(G g, int nz = 600, int np = 400) {
  double sum = 0;
  for (int i = 0; i < nz; ++i)
    for (int j = 0; j < np; ++j) {
      const double z = (i + 0.5) / nz, phi = (j + 0.5) * 2 * M_PI / np, r = std::sqrt(1 - z * z);
      sum += g(Vec3{float(r * std::cos(phi)), float(r * std::sin(phi)), float(z)});
    }
  return sum * (1.0 / nz) * (2 * M_PI / np);
}

TEST(Sheen, DistributionIsNormalisedOverProjectedArea) {
  for (float alpha : {kSheenMinAlpha, 0.3f, 0.6f, 1.0f}) {
    const double area = hemisphere([&](Vec3 h) { return sheen_d(alpha, h.z) * h.z; });
    EXPECT_NEAR(area, 1.0, 2e-3) << alpha;
  }
}

// The bilinear table against a finer quadrature of f cos, between its own grid points too.
TEST(Sheen, AlbedoTableMatchesQuadrature) {
  for (float alpha : {kSheenMinAlpha, 0.2f, 0.55f, 1.0f})
    for (float theta : {0.1f, 0.7f, 1.2f, 1.5f}) {
      const Vec3 wo = dir(theta);
      const double e = hemisphere([&](Vec3 wi) { return sheen_f(alpha, wo, wi) * wi.z; });
      EXPECT_NEAR(sheen_albedo(wo.z, alpha), e, 0.01 + 0.02 * e) << "alpha " << alpha << " theta " << theta;
      EXPECT_LT(e, 1.0);
      EXPECT_GT(e, 0.0);
    }
}

Material velvet(Rgb base, Rgb sheen, float sheen_roughness) {
  Material m;
  m.kind = Material::Kind::kPbr;
  m.reflectance = base;
  m.metallic = 0;
  m.roughness = 1;
  m.alpha = 1;
  m.sheen_color = sheen;
  m.sheen_roughness = sheen_roughness;
  return m;
}

// The layer adds the sheen and takes its albedo from the base: f = c f_sheen + f_base s.
TEST(Sheen, LayerIsSheenPlusTheScaledBase) {
  const Material plain = velvet(Rgb(0.5f), Rgb(0.0f), 0), soft = velvet(Rgb(0.5f), Rgb(0.6f), 0.4f);
  const Vec3 wo = dir(1.0f), wi = dir(0.5f, 2.0f);
  const float alpha = sheen_alpha(0.4f);
  const float s = std::min(1 - 0.6f * sheen_albedo(wo.z, alpha), 1 - 0.6f * sheen_albedo(wi.z, alpha));
  const float expect = 0.6f * sheen_f(alpha, wo, wi) + bsdf_eval(plain, wo, wi).g * s;
  EXPECT_NEAR(bsdf_eval(soft, wo, wi).g, expect, 1e-6f);
  EXPECT_FALSE(soft.is_delta());
  // Black sheen is no sheen: bit for bit the plain material.
  EXPECT_EQ(bsdf_eval(velvet(Rgb(0.5f), Rgb(0.0f), 0.4f), wo, wi).g, bsdf_eval(plain, wo, wi).g);
}

// White sheen over a white base: the albedo never exceeds 1 at any angle or roughness,
// and the sheen moves energy to grazing angles rather than adding it.
TEST(Sheen, WhiteSheenOverAWhiteBaseConservesEnergy) {
  for (float r : {0.0f, 0.3f, 1.0f})
    for (float theta : {0.2f, 1.0f, 1.45f}) {
      const Material m = velvet(Rgb(1.0f), Rgb(1.0f), r);
      const Vec3 wo = dir(theta);
      const double albedo = hemisphere([&](Vec3 wi) { return bsdf_eval(m, wo, wi).g * wi.z; }, 300, 200);
      EXPECT_LE(albedo, 1.0 + 2e-3) << "roughness " << r << " theta " << theta;
      EXPECT_GT(albedo, 0.8) << "roughness " << r << " theta " << theta;
    }
}

}  // namespace
}  // namespace tessera
