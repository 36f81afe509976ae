// glTF alphaMode in the renderer: MASK cuts the surface where its coverage is below the
// cutoff, for camera, shadow and light-sampling rays alike; BLEND meets it with probability
// equal to its coverage (stochastic transparency), independently for stacked layers, so
// images converge to the blend of what is in front and behind.
#include <gtest/gtest.h>

#include <limits>

#include "core/accel/accel.h"
#include "core/light/lights.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

using testing::render;

// A black Lambertian square [-1, 1]^2 at z, facing +z, with material `m`.
Mesh square(float z, uint32_t material) {
  Mesh q;
  q.positions = {{-1, -1, z}, {1, -1, z}, {1, 1, z}, {-1, 1, z}};
  q.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  q.indices = {0, 1, 2, 0, 2, 3};
  q.material = material;
  return q;
}

Material black(Material::AlphaMode mode, float opacity) {
  Material m = testing::pbr_material(0, 1);
  m.reflectance = Rgb(0.0f);
  m.ior = 1;  // Lambertian, and black: nothing reflected
  m.alpha_mode = mode;
  m.opacity = opacity;
  return m;
}

// Left half transparent (alpha 0), right half opaque (alpha 1), clamped (its colour is
// never seen: the materials here are black).
Texture half_alpha() {
  Texture t = testing::red_blue_texture();
  t.alpha = {0.0f, 1.0f};
  return t;
}

// The mean of a small view of x = `x` on the square, under a uniform environment of 1.
double seen_at(const Scene& scene, float x) {
  Scene s = scene;
  s.camera.present = true;
  s.camera.eye = {x, 0, 3};
  s.camera.xfov_deg = 2;
  s.camera.aspect_ratio = 1;
  RenderSettings rs = testing::furnace_settings();
  rs.environment = Rgb(1.0f);
  return testing::film_estimate(render(s, rs).film).mean;
}

TEST(Alpha, MaskCutsTheSurfaceForCameraAndShadowRays) {
  Scene s;
  s.textures.push_back(half_alpha());
  Material m = black(Material::AlphaMode::kMask, 1);
  m.texture.index = 0;
  s.materials.push_back(m);
  s.meshes.push_back(square(0, 0));
  s.finalize();
  EXPECT_NEAR(seen_at(s, -0.6f), 1.0, 1e-6);  // cut away: the environment behind
  EXPECT_NEAR(seen_at(s, 0.6f), 0.0, 1e-6);   // there: black
  const Accel accel(s);
  auto blocked = [&](float x) {
    Ray r{{x, 0.1f, 2}, {0, 0, -1}, 0, std::numeric_limits<float>::infinity()};
    Hit h;
    const bool hit = accel.intersect(r, &h);
    EXPECT_EQ(hit, accel.occluded(r)) << x;
    return hit;
  };
  EXPECT_FALSE(blocked(-0.6f));
  EXPECT_TRUE(blocked(0.6f));
  // The cutoff decides: coverage 0.4 is cut at 0.5 and kept at 0.3; opacity scales it.
  s.materials[0].texture = TextureRef();
  s.materials[0].opacity = 0.4f;
  EXPECT_FALSE(Accel(s).occluded(Ray{{0, 0, 2}, {0, 0, -1}, 0, 10}));
  s.materials[0].alpha_cutoff = 0.3f;
  EXPECT_TRUE(Accel(s).occluded(Ray{{0, 0, 2}, {0, 0, -1}, 0, 10}));
  // OPAQUE ignores coverage altogether, as the specification says.
  s.materials[0].alpha_mode = Material::AlphaMode::kOpaque;
  s.materials[0].opacity = 0;
  EXPECT_TRUE(Accel(s).occluded(Ray{{0, 0, 2}, {0, 0, -1}, 0, 10}));
}

TEST(Alpha, BlendShowsTheBackgroundInProportionAndLayersAreIndependent) {
  Scene s;
  s.materials.push_back(black(Material::AlphaMode::kBlend, 0.3f));
  s.meshes.push_back(square(0, 0));
  s.finalize();
  // 24 x 24 pixels x 64 samples: the standard error of a fraction 0.7 is 0.0024.
  EXPECT_NEAR(seen_at(s, 0), 0.7, 0.012);
  // Two layers of 0.5: a quarter gets through both (0.5 if the layers were correlated).
  s.materials[0].opacity = 0.5f;
  s.meshes.push_back(square(-0.5f, 0));
  s.meshes.back().compute_normals();
  EXPECT_NEAR(seen_at(s, 0), 0.25, 0.012);
  // Per-vertex alpha (COLOR_0) multiplies: all vertices 0.5 over opacity 1, one layer.
  s.meshes.pop_back();
  s.materials[0].opacity = 1;
  s.meshes[0].color_alpha = {0.5f, 0.5f, 0.5f, 0.5f};
  EXPECT_NEAR(seen_at(s, 0), 0.5, 0.012);
  // The same ray gets the same answer twice (and on every machine: it hashes the ray).
  const Accel accel(s);
  for (int i = 0; i < 50; ++i) {
    const Ray r{{0.01f * i, 0.02f, 2}, {0.001f * i, 0, -1}, 0, 10};
    EXPECT_EQ(accel.occluded(r), accel.occluded(r));
  }
}

// A BLEND lamp emits in proportion to its coverage, whether a path hits it or a light
// sample picks it: the two estimators agree, and a MASK cut-out emits nothing.
TEST(Alpha, LightSamplesOfACutLampFollowItsCoverage) {
  Scene s;
  s.textures.push_back(half_alpha());
  Material lamp = black(Material::AlphaMode::kMask, 1);
  lamp.texture.index = 0;
  lamp.radiance = Rgb(4.0f);
  lamp.two_sided_emission = true;
  s.materials.push_back(lamp);
  s.meshes.push_back(square(0, 0));
  s.finalize();
  ASSERT_EQ(s.lights.size(), 1u);
  const LightSet lights(s);
  int left = 0, right = 0;
  for (int i = 0; i < 400; ++i) {
    LightSample ls;
    const bool got = lights.sample(0, {0, 0, 1}, (i + 0.5f) / 400, {(i % 19 + 0.5f) / 19, (i % 23 + 0.5f) / 23}, &ls);
    if (got && ls.point.x < -0.55f) ++left;
    if (got && ls.point.x > 0.55f && ls.li.r > 0) ++right;
  }
  EXPECT_EQ(left, 0);
  EXPECT_GT(right, 50);
  s.materials[0].alpha_mode = Material::AlphaMode::kBlend;
  s.materials[0].texture = TextureRef();
  s.materials[0].opacity = 0.25f;
  LightSample ls;
  ASSERT_TRUE(LightSet(s).sample(0, {0, 0, 1}, 0.5f, {0.5f, 0.5f}, &ls));
  EXPECT_FLOAT_EQ(ls.li.r, 1.0f);  // 4 x 0.25
}

}  // namespace
}  // namespace tessera
