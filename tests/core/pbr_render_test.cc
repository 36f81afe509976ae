// The glTF material model in the renderer: Beer-Lambert absorption inside a solid, normal
// maps turning the shading frame, emissive textures on emitters (camera rays and light
// sampling alike), and white furnaces of the model's lobes.
#include <gtest/gtest.h>

#include <cmath>

#include "core/light/lights.h"
#include "core/render/integrator.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

using testing::film_estimate;
using testing::pbr_material;
using testing::render;

// An axis-aligned box [-h, h]^3 of outward-wound triangles.
Mesh box(float h, uint32_t material) {
  Mesh m;
  m.name = "box";
  for (int i = 0; i < 8; ++i) m.positions.push_back({i & 1 ? h : -h, i & 2 ? h : -h, i & 4 ? h : -h});
  m.indices = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
               2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
  m.material = material;
  return m;
}

Scene scene_with(Mesh mesh, Material m) {
  Scene s;
  s.materials.push_back(m);
  s.meshes.push_back(std::move(mesh));
  s.camera.present = true;
  s.camera.eye = {0, 0, 4};
  s.camera.xfov_deg = 8;  // only the box's front face
  s.camera.aspect_ratio = 1;
  s.finalize();
  return s;
}

RenderSettings env_settings() {
  RenderSettings s = testing::furnace_settings();
  s.environment = Rgb(1);
  return s;
}

TEST(PbrRender, AbsorbingSolidTransmitsExpOfMinusSigmaTimesItsThickness) {
  // Index 1 and smooth: no reflection, no bending; the path crosses 2 units of a medium of
  // sigma (0.5, 1, 2) and sees the environment of radiance 1 behind.
  Material glass = pbr_material(0, 0, 1, false);
  glass.ior = 1;
  glass.absorption = Rgb(0.5f, 1.0f, 2.0f);
  const Scene scene = scene_with(box(1, 0), glass);
  const Film film = render(scene, env_settings()).film;
  const PixelSums& p = film.pixels()[size_t(12 * 24 + 12)];
  EXPECT_NEAR(p.r / p.n, std::exp(-1.0), 1e-5);
  EXPECT_NEAR(p.g / p.n, std::exp(-2.0), 1e-5);
  EXPECT_NEAR(p.b / p.n, std::exp(-4.0), 1e-5);
  // The same solid without absorption is clear.
  glass.absorption = Rgb(0.0f);
  const Film clear = render(scene_with(box(1, 0), glass), env_settings()).film;
  EXPECT_NEAR(clear.pixels()[size_t(12 * 24 + 12)].g / clear.pixels()[size_t(12 * 24 + 12)].n, 1.0, 1e-5);
}

// Under a uniform environment of 1, a smooth white metal and an index-1 white dielectric
// are 1 everywhere; rough white metal and glass lose only GGX's single-scattering share
// (small at roughness 0.2; every interface a path crosses loses it again). glTF's Fresnel
// mix of coat and diffuse is not exactly energy conserving: measured here, at most 1% more
// than it receives.
TEST(PbrRender, WhiteFurnaces) {
  auto mean_of = [](Material m) { return film_estimate(render(testing::lone_sphere(m), env_settings()).film); };
  testing::Estimate e = mean_of(pbr_material(1, 0));
  EXPECT_NEAR(e.mean, 1.0, 1e-4);
  Material lambert = pbr_material(0, 0.5f);
  lambert.ior = 1;
  e = mean_of(lambert);
  EXPECT_NEAR(e.mean, 1.0, 4 * e.stderr_ + 2e-3);
  e = mean_of(pbr_material(0, 0, 1, false));  // smooth glass: energy is only redirected
  EXPECT_NEAR(e.mean, 1.0, 4 * e.stderr_ + 2e-3);
  for (const Material& m : {pbr_material(1, 0.2f), pbr_material(0, 0.2f, 1, false), pbr_material(0, 0.2f, 1, true)}) {
    e = mean_of(m);
    EXPECT_LE(e.mean, 1.0 + 4 * e.stderr_);
    EXPECT_GT(e.mean, 0.95) << m.thin << " " << m.transmission;
  }
  e = mean_of(pbr_material(1, 0.5f));  // rougher: more of the single-scattering loss
  EXPECT_LE(e.mean, 1.0 + 4 * e.stderr_);
  EXPECT_GT(e.mean, 0.8);
  e = mean_of(pbr_material(0, 0.5f));  // white plastic
  EXPECT_LE(e.mean, 1.01 + 4 * e.stderr_);
  EXPECT_GT(e.mean, 0.97);
}

// glTF COLOR_0 multiplies the base colour: a smooth metal reflects its base colour times
// the vertex colour (here the same at every vertex) of a uniform environment.
TEST(PbrRender, VertexColoursMultiplyTheBaseColour) {
  Mesh b = box(1, 0);
  b.colors.assign(b.positions.size(), Rgb(0.5f, 0.25f, 1.0f));
  Material metal = pbr_material(1, 0);
  metal.reflectance = Rgb(1.0f, 1.0f, 0.5f);
  const Film film = render(scene_with(b, metal), env_settings()).film;
  const PixelSums& p = film.pixels()[size_t(12 * 24 + 12)];
  EXPECT_NEAR(p.r / p.n, 0.5, 1e-4);
  EXPECT_NEAR(p.g / p.n, 0.25, 1e-4);
  EXPECT_NEAR(p.b / p.n, 0.5, 1e-4);
}

// A quad at z = 0 facing +z, u along +x and v along -y (an upright glTF texture), with a
// normal map of one texel: tangent-space normal (0.6, 0, 0.8), tilted toward +T.
Scene normal_mapped_quad(const std::vector<Tangent>& tangents = {}) {
  Scene s;
  Texture t;
  t.width = t.height = 1;
  t.texels = {Rgb(0.5f * 0.6f + 0.5f, 0.5f, 0.5f * 0.8f + 0.5f)};
  s.textures.push_back(t);
  Material m = pbr_material(0, 0.5f);
  m.normal_texture.index = 0;
  s.materials.push_back(m);
  Mesh quad;
  quad.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  quad.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  quad.indices = {0, 1, 2, 0, 2, 3};
  quad.tangents = tangents;
  s.meshes.push_back(quad);
  s.finalize();
  return s;
}

// The quad's shading normal at barycentrics (0.3, 0.2), seen from above, after its normal map.
Hit quad_hit() {
  Hit hit;
  hit.u = 0.3f;
  hit.v = 0.2f;
  hit.t = 1;
  return hit;
}
Vec3 mapped_normal_at(const Scene& s, const Hit& hit) {
  const Ray ray{{0, 0, 1}, {0, 0, -1}, 0, 10};
  SurfacePoint sp = make_surface_point(s, ray, hit);
  apply_normal_map(s, s.materials[0], hit, &sp);
  return sp.ns;
}

TEST(PbrRender, NormalMapTurnsTheShadingNormalInTangentSpace) {
  Scene s = normal_mapped_quad();  // T = dp/du = +x
  const Hit hit = quad_hit();
  Vec3 n = mapped_normal_at(s, hit);
  EXPECT_NEAR(n.x, 0.6f, 1e-5);
  EXPECT_NEAR(n.y, 0.0f, 1e-5);
  EXPECT_NEAR(n.z, 0.8f, 1e-5);
  // Green is "up" in the image (v decreasing): +y here.
  s.textures[0].texels = {Rgb(0.5f, 0.5f * 0.6f + 0.5f, 0.5f * 0.8f + 0.5f)};
  EXPECT_NEAR(mapped_normal_at(s, hit).y, 0.6f, 1e-5);
  // A map that would turn the normal below the surface is ignored.
  s.textures[0].texels = {Rgb(1.0f, 0.5f, 0.0f)};
  EXPECT_NEAR(mapped_normal_at(s, hit).z, 1.0f, 1e-6);
}

// glTF TANGENT: the file's tangents give the frame (here turned 90 degrees from the
// triangle's dp/du, and with each bitangent sign), also through a mirroring instance.
TEST(PbrRender, FileTangentsGiveTheNormalMapsFrame) {
  Scene s = normal_mapped_quad(std::vector<Tangent>(4, Tangent{{0, 1, 0}, 1}));  // T = +y, not dp/du's +x
  Hit hit = quad_hit();
  Vec3 n = mapped_normal_at(s, hit);
  EXPECT_NEAR(n.x, 0.0f, 1e-5);
  EXPECT_NEAR(n.y, 0.6f, 1e-5);
  EXPECT_NEAR(n.z, 0.8f, 1e-5);
  // Green follows the bitangent cross(N, T) x sign: -x for sign 1, +x for -1.
  s.textures[0].texels = {Rgb(0.5f, 0.5f * 0.6f + 0.5f, 0.5f * 0.8f + 0.5f)};
  EXPECT_NEAR(mapped_normal_at(s, hit).x, -0.6f, 1e-5);
  for (Tangent& tg : s.meshes[0].tangents) tg.sign = -1;
  EXPECT_NEAR(mapped_normal_at(s, hit).x, 0.6f, 1e-5);
  // Placed by an instance mirrored in x: the tangent stays +y, the bitangent turns with
  // the mirror, so the world normal is the mirror image of the unmirrored one.
  s.meshes[0].instanced = true;
  s.instances.push_back(*Instance::make(0, Mat4::scale(-1, 1, 1)));
  hit.instance = 0;
  n = mapped_normal_at(s, hit);
  EXPECT_NEAR(n.x, -0.6f, 1e-5);
  EXPECT_NEAR(n.z, 0.8f, 1e-5);
}

// clearcoatNormalTexture: a smooth coat over a black base, seen straight down. Its normal
// map tilts the coat's normal 20 degrees toward +x, so the camera sees, in the coat, a lamp
// 40 degrees off the vertical with the coat's Fresnel (0.04 there); unmapped, the coat
// reflects the dark above the camera.
TEST(PbrRender, ClearcoatNormalTextureTurnsTheCoatsReflection) {
  Scene s;
  const float th = 20 * kPi / 180;
  Texture t;
  t.width = t.height = 1;
  t.texels = {Rgb(0.5f * std::sin(th) + 0.5f, 0.5f, 0.5f * std::cos(th) + 0.5f)};
  s.textures.push_back(t);
  Material m = pbr_material(0, 1);
  m.reflectance = Rgb(0.0f);
  m.ior = 1;  // no base specular: black Lambert
  m.clearcoat = 1;
  m.clearcoat_normal_texture.index = 0;
  s.materials.push_back(m);
  Material lamp;
  lamp.kind = Material::Kind::kEmission;
  lamp.radiance = Rgb(1.0f);
  s.materials.push_back(lamp);
  Mesh floor;
  floor.positions = {{-10, -10, 0}, {10, -10, 0}, {10, 10, 0}, {-10, 10, 0}};
  floor.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};  // u along +x: T = +x
  floor.indices = {0, 1, 2, 0, 2, 3};
  s.meshes.push_back(floor);
  const Vec3 r{std::sin(2 * th), 0, std::cos(2 * th)}, c = r * 3, a{0, 2, 0}, b = cross(r, a);
  Mesh light;  // 4 x 4, square to r, 3 away
  light.positions = {c - a - b, c + a - b, c + a + b, c - a + b};
  light.indices = {0, 1, 2, 0, 2, 3};
  light.material = 1;
  s.meshes.push_back(light);
  s.camera.present = true;
  s.camera.eye = {0, 0, 5};
  s.camera.xfov_deg = 2;
  s.camera.aspect_ratio = 1;
  s.finalize();
  RenderSettings rs;
  rs.camera.framing = Framing::kFile;
  rs.camera.width = rs.camera.height = 8;
  rs.spp = 256;
  rs.max_depth = 2;
  const float fc = 0.04f + 0.96f * std::pow(1 - std::cos(th), 5.0f);
  EXPECT_NEAR(film_estimate(render(s, rs).film).mean, fc, 0.006);
  s.materials[0].clearcoat_normal_texture = TextureRef();
  EXPECT_NEAR(film_estimate(render(s, rs).film).mean, 0, 1e-6);
}

TEST(PbrRender, EmissiveTextureScalesCameraHitsAndLightSamplesAlike) {
  Scene s;
  s.textures.push_back(testing::red_blue_texture());
  Material e;
  e.kind = Material::Kind::kEmission;
  e.radiance = Rgb(2.0f);
  e.emissive_texture.index = 0;
  s.materials.push_back(e);
  Mesh quad;  // x < 0 half red, x > 0 half blue; faces +z
  quad.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  quad.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  quad.indices = {0, 1, 2, 0, 2, 3};
  s.meshes.push_back(quad);
  s.finalize();
  ASSERT_EQ(s.lights.size(), 1u);
  const LightSet lights(s);
  int red = 0, blue = 0;
  for (int i = 0; i < 200; ++i) {
    LightSample ls;
    ASSERT_TRUE(lights.sample(0, {0, 0, 1}, (i + 0.5f) / 200, {(i % 17 + 0.5f) / 17, (i % 13 + 0.5f) / 13}, &ls));
    // Texel centres at u = 0.25 and 0.75 (x = -0.5, 0.5): clamped beyond them.
    const bool left = ls.point.x<-0.55f, right = ls.point.x> 0.55f;
    if (left) {
      EXPECT_NEAR(ls.li.r, 2, 1e-5);
      EXPECT_NEAR(ls.li.b, 0, 1e-5);
      ++red;
    }
    if (right) {
      EXPECT_NEAR(ls.li.b, 2, 1e-5);
      ++blue;
    }
  }
  EXPECT_GT(red, 20);
  EXPECT_GT(blue, 20);
  // Seen by the camera: the textured radiance too.
  s.camera.present = true;
  s.camera.eye = {-0.6f, 0, 3};
  s.camera.xfov_deg = 2;
  s.camera.aspect_ratio = 1;
  const Film film = render(s, testing::furnace_settings()).film;
  const PixelSums& p = film.pixels()[size_t(12 * 24 + 12)];
  EXPECT_NEAR(p.r / p.n, 2, 1e-4);
  EXPECT_NEAR(p.b / p.n, 0, 1e-4);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// glTF emission adds to reflection (the specification's model): a textured emissive quad
// (left half red, right half blue) that is also a Lambertian reflector (ior 1, albedo 0.5)
// under a uniform environment of radiance 1 shows emission + 0.5 x 1, whether its emission
// is bright enough to be a sampled light (a lamp) or only glows.
TEST(PbrRender, EmissionAddsToReflection) {
  for (const float strength : {0.5f, 3.0f}) {
    Scene s;
    s.textures.push_back(testing::red_blue_texture());
    Material m = pbr_material(0, 1);
    m.ior = 1;  // exactly Lambertian (docs/gltf.md)
    m.reflectance = Rgb(0.5f);
    m.radiance = Rgb(strength);
    m.emissive_texture.index = 0;
    m.two_sided_emission = false;
    s.materials.push_back(m);
    Mesh quad;  // faces +z
    quad.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
    quad.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
    quad.indices = {0, 1, 2, 0, 2, 3};
    s.meshes.push_back(quad);
    s.finalize();
    // Mean texture radiance strength / 2 per lit channel: a lamp from kLampRadiance on.
    EXPECT_EQ(s.lights.size(), strength / 2 >= Scene::kLampRadiance ? 1u : 0u) << strength;
    s.camera.present = true;
    s.camera.eye = {-0.6f, 0, 3};
    s.camera.xfov_deg = 2;
    s.camera.aspect_ratio = 1;
    RenderSettings rs = testing::furnace_settings();
    rs.environment = Rgb(1.0f);
    const Film film = render(s, rs).film;
    double r = 0, g = 0, b = 0, n = 0;
    for (const PixelSums& p : film.pixels()) {
      r += p.r;
      g += p.g;
      b += p.b;
      n += p.n;
    }
    EXPECT_NEAR(r / n, strength + 0.5, 0.01 * (strength + 0.5)) << strength;
    EXPECT_NEAR(g / n, 0.5, 0.01) << strength;
    EXPECT_NEAR(b / n, 0.5, 0.01) << strength;
    // Seen from behind, one-sided emission is dark: only the reflection is left.
    s.camera.eye = {-0.6f, 0, -3};
    s.camera.forward = {0, 0, 1};
    const Film back = render(s, rs).film;
    r = n = 0;
    for (const PixelSums& p : back.pixels()) {
      r += p.r;
      n += p.n;
    }
    EXPECT_NEAR(r / n, 0.5, 0.01) << strength;
  }
}

}  // namespace
}  // namespace tessera
