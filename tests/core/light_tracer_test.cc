// The light tracer (core/render/light_tracer.h): its sampling routines, its agreement with
// the path tracer alone on caustic scenes, energy through glass, determinism, and that it
// costs a scene without caustic casters nothing.
#include "core/render/light_tracer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>
#include <tuple>

#include "core/camera/camera.h"
#include "core/light/lights.h"
#include "core/render/delta_targets.h"
#include "core/render/integrator.h"
#include "core/sampling/sampler.h"
#include "core/scene/load.h"
#include "tests/core/caustic_scene.h"
#include "tests/core/chi2.h"
#include "tests/core/render_helpers.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

using testing::chi2_directions;
using testing::film_estimate;
using testing::render;
using LT = RenderSettings::LightTracer;
using namespace testing::caustics;

TEST(DeltaTargets, DirectionsFollowTheirDensity) {
  Scene s = caustic_scene(glass());
  s.spheres.push_back(Sphere{"second", {1.2f, 0.4f, -0.5f}, 0.3f, 1, -1});
  const DeltaTargets targets(s);
  ASSERT_EQ(targets.targets().size(), 2u);
  for (const Vec3 from : {Vec3{0.2f, 2.2f, 0.1f}, Vec3{0, 0.6f, 0.2f} /* inside the first */}) {
    const testing::Chi2Result r = chi2_directions(
        [&](int i) -> std::optional<Vec3> {
          Sampler sm(7, 0, uint32_t(i));
          const float u = sm.next_1d();
          float pdf = 0;
          const Vec3 d = targets.sample(from, u, sm.next_2d(), &pdf);
          EXPECT_NEAR(pdf, targets.pdf(from, d), 1e-3f * pdf);
          return d;
        },
        [&](Vec3 w) { return double(targets.pdf(from, w)); }, 400000, 20, 40, 48);
    EXPECT_GT(r.p_value, 1e-3) << r.describe();
  }
}

TEST(DeltaTargets, BoundEveryDeltaShapeAndNothingElse) {
  EXPECT_TRUE(DeltaTargets(caustic_scene(diffuse(0.5f))).empty());
  EXPECT_FALSE(has_delta_lobe(testing::pbr_material(0, 0.5f)));
  EXPECT_TRUE(has_delta_lobe(testing::pbr_material(1, 0)));
  const DeltaTargets t(caustic_scene(mirror()));
  ASSERT_EQ(t.targets().size(), 1u);
  EXPECT_NEAR(t.targets()[0].radius, 0.5f, 1e-3f);
  EXPECT_GE(t.targets()[0].radius, 0.5f);
}

// The file's camera at width x height, with a thin lens of this radius and focal distance.
CameraSettings file_camera(int width, int height, float lens, float focus) {
  CameraSettings cs;
  cs.framing = Framing::kFile;
  cs.width = width;
  cs.height = height;
  cs.lens_radius = lens;
  cs.focal_distance = focus;
  return cs;
}

// Camera::connect inverts generate(): the film position a ray was generated for, and the
// lens point it left from.
TEST(CameraConnect, InvertsGenerate) {
  const Scene s = caustic_scene(glass());
  for (const float lens : {0.0f, 0.2f}) {
    const Camera cam(s, file_camera(32, 24, lens, 3));
    for (uint32_t i = 0; i < 2000; ++i) {
      Sampler sm(3, 1, i);
      const Vec2 f = sm.next_2d(), u = sm.next_2d();
      const float t = 0.5f + 5 * sm.next_1d();
      const Ray r = cam.generate(f.x * 32, f.y * 24, u);
      CameraConnection c;
      ASSERT_TRUE(cam.connect(r.o + r.d * t, u, &c));
      EXPECT_NEAR(c.fx, f.x * 32, 2e-3f);
      EXPECT_NEAR(c.fy, f.y * 24, 2e-3f);
      EXPECT_NEAR(length(c.lens - r.o), 0, 1e-5f);
      EXPECT_NEAR(dot(c.wi, -r.d), 1, 1e-5f);
      EXPECT_NEAR(c.dist, t, 1e-4f * t);
    }
  }
}

// The camera's importance integrates to one over what it sees: over a plane filling the
// view, the sum of weight x cos x area of points sampled uniformly on it, for a pinhole
// and for a thin lens (any lens point).
TEST(CameraConnect, ImportanceIntegratesToOne) {
  Scene s;
  s.camera.present = true;
  s.camera.xfov_deg = 60;
  s.camera.aspect_ratio = 4.0 / 3.0;
  s.finalize();
  for (const float lens : {0.0f, 0.3f}) {
    const Camera cam(s, file_camera(40, 30, lens, 2));
    const float half = 8, depth = 5;  // the plane z = -5, [-8, 8]^2: wider than the view
    double sum = 0;
    const int n = 400000;
    for (int i = 0; i < n; ++i) {
      Sampler sm(5, 2, uint32_t(i));
      const Vec2 u = sm.next_2d();
      const Vec3 p{(2 * u.x - 1) * half, (2 * u.y - 1) * half, -depth};
      CameraConnection c;
      if (!cam.connect(p, sm.next_2d(), &c)) continue;
      sum += double(c.weight) * std::fabs(c.wi.z) * (4 * half * half);
    }
    EXPECT_NEAR(sum / n, 1.0, 0.01) << "lens " << lens;
  }
}

TEST(LightEmission, SpotsAndPointsEmitAsNextEventEstimationSeesThem) {
  Scene s = caustic_scene(glass(), true, Vec3{0, 2, 0});
  Light spot = s.lights[0];
  spot.kind = Light::Kind::kSpot;
  spot.direction = {0, -1, 0};
  spot.cos_inner = 0.9f;
  spot.cos_outer = 0.7f;
  s.lights.push_back(spot);
  const LightSet lights(s);
  for (size_t i = 0; i < 2; ++i) {
    LightPoint e;
    ASSERT_TRUE(lights.emission_point(i, 0.5f, {0.5f, 0.5f}, &e));
    for (const Vec3 p : {Vec3{0, 0, 0}, Vec3{0.5f, 0, 0.3f}, Vec3{1.5f, 0, 0}}) {
      LightSample ls;
      const bool lit = lights.sample(i, p, 0.5f, {0.5f, 0.5f}, &ls);
      const Rgb out = lights.emitted_toward(i, e, normalize(p - e.q));
      const float d = length(p - e.q);
      EXPECT_NEAR(out.r, lit ? ls.li.r * d * d : 0.0f, 1e-4f * out.r + 1e-6f) << i;
    }
  }
  EXPECT_GT(lights.emitted_power(0), 0);
}

// Light tracing and the path tracer alone estimate the same image: over the whole frame
// and in the caustic under the sphere, for glass and a mirror, pinhole and thin lens.
TEST(LightTracer, AgreesWithThePathTracerAlone) {
  for (const bool lens : {false, true})
    for (const Material& caster : {glass(), mirror()}) {
      const Scene scene = caustic_scene(caster);
      RenderSettings off = caustic_settings(LT::kOff, 1024), on = caustic_settings(LT::kOn, 128);
      if (lens) off.camera.lens_radius = on.camera.lens_radius = 0.15f;
      const RenderResult a = render(scene, off), b = render(scene, on);
      ASSERT_TRUE(b.light_tracing.on) << b.light_tracing.why;
      EXPECT_GT(b.stats.rays.splats, 1000u);
      EXPECT_EQ(b.light_paths, 32u * 24u * 128u / LightTracer::kSamplesPerLightPath);
      SCOPED_TRACE(std::string(caster.kind == Material::Kind::kGlass ? "glass" : "mirror") +
                   (lens ? ", thin lens" : ""));
      expect_same_image(a.film, b.film);
    }
}

// Paths seen through a mirror or glass split at their first smooth vertex
// (Integrator::set_specular_splits): the same mean, less noise, on the pixels that see the
// sphere; a pixel that sees the floor directly is not split and keeps its bits.
TEST(LightTracer, SplitsBehindMirrorsAndGlassKeepTheMeanAndCutTheNoise) {
  for (const Material& caster : {glass(), mirror()}) {
    SCOPED_TRACE(caster.kind == Material::Kind::kGlass ? "glass" : "mirror");
    const Scene scene = caustic_scene(caster);
    const RenderSettings s = caustic_settings(LT::kOn, 1);
    const Accel accel(scene);
    const LightSet lights(scene);
    const Camera camera(scene, s.camera);
    const LightTracer tracer(scene, accel, lights, camera, s);
    Integrator one(scene, accel, lights, s), split(scene, accel, lights, s);
    one.leave_to_light_tracer(tracer.traced_lights(), LightTracer::kMaxSmoothVertices, tracer.target_materials());
    split.leave_to_light_tracer(tracer.traced_lights(), LightTracer::kMaxSmoothVertices, tracer.target_materials());
    split.set_specular_splits(4);
    struct Moments {
      double sum = 0, sum2 = 0;
      int n = 0;
      double mean() const { return sum / n; }
      double var() const { return sum2 / n - mean() * mean(); }
    };
    // On the sphere, seeing the floor through it or in it (where the glass's own Fresnel
    // choice, made before the split, is not most of the noise); (16, 21): the floor itself.
    const int sphere_row = caster.kind == Material::Kind::kGlass ? 9 : 12;
    for (const auto& [px, py, on_sphere] : {std::tuple{16, sphere_row, true}, std::tuple{16, 21, false}}) {
      Moments a, b;
      bool same = true;
      uint64_t split_paths = 0;
      for (uint32_t i = 0; i < 40000; ++i) {
        const uint64_t pixel = uint64_t(py) * 32 + px;
        Sampler sa(7, pixel, i), sb(7, pixel, i);
        const Vec2 ja = sa.next_2d(), jb = sb.next_2d();
        const Ray ray = camera.generate(px + ja.x, 23 - py + ja.y, {});
        RayCounters ca, cb;
        const Rgb la = one.radiance(ray, sa, ca),
                  lb = split.radiance(camera.generate(px + jb.x, 23 - py + jb.y, {}), sb, cb);
        ASSERT_TRUE(la.is_finite() && lb.is_finite());
        EXPECT_EQ(ca.split_paths, 0u);
        split_paths += cb.split_paths;
        same = same && la.r == lb.r && la.g == lb.g && la.b == lb.b;
        a.sum += la.luminance(), a.sum2 += la.luminance() * la.luminance(), ++a.n;
        b.sum += lb.luminance(), b.sum2 += lb.luminance() * lb.luminance(), ++b.n;
      }
      SCOPED_TRACE(on_sphere ? "on the sphere" : "on the floor");
      EXPECT_EQ(split_paths > 0, on_sphere);
      EXPECT_GT(a.mean(), 0.01);
      EXPECT_LT(std::fabs(a.mean() - b.mean()), 4.5 * std::sqrt((a.var() + b.var()) / a.n))
          << a.mean() << " against " << b.mean();
      if (on_sphere) {
        EXPECT_LT(b.var(), 0.6 * a.var()) << "variance " << b.var() << " against " << a.var();
      } else {
        EXPECT_TRUE(same);
      }
    }
  }
}

// glTF's materials: a smooth solid glass and a smooth metal casting onto a rough glTF
// floor (its GGX coat and diffuse base are the connection vertex's lobes, evaluated the
// camera's way round), and a rough metal caster that is not a caustic caster at all.
TEST(LightTracer, AgreesWithThePathTracerAloneOnGltfMaterials) {
  for (const Material& caster :
       {testing::pbr_material(0, 0, 1, false), testing::pbr_material(1, 0), testing::pbr_material(1, 0.4f)}) {
    Scene scene = caustic_scene(caster);
    scene.materials[0] = testing::pbr_material(0, 0.5f);
    scene.materials[0].reflectance = Rgb(0.8f);
    const RenderResult a = render(scene, caustic_settings(LT::kOff, 1024)),
                       b = render(scene, caustic_settings(LT::kOn, 128));
    ASSERT_TRUE(b.light_tracing.on);
    SCOPED_TRACE("caster metallic " + std::to_string(caster.metallic) + " roughness " +
                 std::to_string(caster.roughness));
    expect_same_image(a.film, b.film);
  }
}

// A metal whose roughness texture makes it a mirror (factor 1, texel 0) is not a light
// tracer's target (has_delta_lobe sees the factor), while a glass sphere elsewhere turns
// the light tracer on. Light paths reach the metal only through the glass's cone, so its
// caustic must stay the path tracer's: it was left to the light tracer and lost.
TEST(LightTracer, ATextureMadeMirrorOffTheTargetsKeepsItsCaustic) {
  Material metal = testing::pbr_material(1, 1);
  metal.metal_rough_texture.index = 0;
  Scene scene = caustic_scene(metal);
  Texture smooth;
  smooth.width = smooth.height = 1;
  smooth.texels = {Rgb(1, 0, 1)};  // roughness x 0, metallic x 1
  scene.textures.push_back(smooth);
  const uint32_t target = uint32_t(scene.materials.size());
  scene.materials.push_back(glass());
  scene.spheres.push_back(Sphere{"target", {1.5f, 0.25f, -1.5f}, 0.2f, target, -1});
  scene.finalize();
  ASSERT_FALSE(has_delta_lobe(scene.materials[1]));
  ASSERT_TRUE(has_delta_lobe(scene.materials[target]));
  const RenderResult a = render(scene, caustic_settings(LT::kOff, 1024)),
                     b = render(scene, caustic_settings(LT::kOn, 128));
  ASSERT_TRUE(b.light_tracing.on);
  expect_same_image(a.film, b.film);
}

// A file camera's near clip: its rays start past it, so a wall nearer the lens is not
// seen, and must not block the light tracer's connections to the lens either (it did:
// every splat was lost behind a wall the camera sits in).
TEST(LightTracer, GeometryInsideTheNearClipBlocksNoConnection) {
  Scene scene = caustic_scene(glass());
  scene.camera.znear = 0.5f;
  const Vec3 c = scene.camera.eye + scene.camera.forward * 0.2f, u{1, 0, 0}, v = normalize(Vec3{0, 1, -1});
  Mesh wall;
  wall.name = "wall";
  wall.positions = {c - u - v, c + u - v, c + u + v, c - u + v};
  wall.indices = {0, 1, 2, 0, 2, 3};
  wall.material = 0;
  scene.meshes.push_back(wall);
  scene.finalize();
  const RenderResult a = render(scene, caustic_settings(LT::kOff, 1024)),
                     b = render(scene, caustic_settings(LT::kOn, 128));
  ASSERT_TRUE(b.light_tracing.on);
  EXPECT_GT(b.stats.rays.splats, 1000u);
  expect_same_image(a.film, b.film);
}

// The white furnace with glass and finite light: inside a sphere whose inner surface is
// Lambertian (albedo 1/2) and glows with radiance 1 (a sphere light), radiance is 2
// everywhere, through a lossless glass sphere too. The walls seen through the glass are
// the path tracer's (split), the glass seen from the walls the light tracer's: together
// they must give exactly that, pixel block by pixel block.
TEST(LightTracer, WhiteFurnaceWithGlassIsUniform) {
  Material wall = testing::pbr_material(0, 1);
  wall.reflectance = Rgb(0.5f);
  wall.ior = 1.0f;  // no specular coat: Lambertian
  wall.radiance = Rgb(1.0f);
  Scene scene = testing::furnace_with({Sphere{"glass", {0, 0, 0}, 1, 0, -1}}, glass(), 6, 3, 60);
  scene.materials[1] = wall;
  scene.finalize();
  RenderSettings s = testing::furnace_settings();
  s.spp = 256;
  s.light_tracer = LT::kOn;
  const RenderResult r = render(scene, s);
  ASSERT_TRUE(r.light_tracing.on) << r.light_tracing.why;
  EXPECT_GT(r.stats.rays.splats, 1000u);
  EXPECT_EQ(r.stats.nan_samples, 0u);
  const testing::Estimate two{2.0, 0.0};
  expect_agree(film_estimate(r.film), two, "frame");
  for (int by = 0; by < 24; by += 8)
    for (int bx = 0; bx < 24; bx += 8) {
      SCOPED_TRACE("block at " + std::to_string(bx) + ", " + std::to_string(by));
      expect_agree(block(r.film, bx, by, 8, 8), two, "block");
    }
}

// A point light at the centre of a glass sphere: every ray leaves radially and, Fresnel
// reflections included, all of its flux gets out (lossless glass), so the floor is lit as if
// the sphere were not there. The path tracer alone sees none of it (a delta light behind
// glass); light tracing must carry it without the radiance's eta^2.
TEST(LightTracer, PointLightThroughAGlassSphereKeepsItsEnergy) {
  const Vec3 centre{0, 0.6f, 0};
  const RenderResult bare = render(caustic_scene(glass(), false, centre), caustic_settings(LT::kOff, 64));
  RenderSettings s = caustic_settings(LT::kOn, 64);
  s.max_depth = 64;
  const RenderResult through = render(caustic_scene(glass(), true, centre), s);
  ASSERT_TRUE(through.light_tracing.on);
  // The floor's corners, away from the sphere's silhouette.
  for (const auto& [x, y] : {std::pair{0, 16}, std::pair{24, 16}, std::pair{0, 0}, std::pair{24, 0}})
    expect_agree(block(bare.film, x, y, 8, 8), block(through.film, x, y, 8, 8), "floor");
  EXPECT_EQ(through.stats.nan_samples, 0u);
  EXPECT_EQ(through.dropped_splats, 0u);
}

// Degenerate chains stay finite: a light inside glass, grazing glass, a camera inside glass.
TEST(LightTracer, DegenerateChainsStayFinite) {
  Scene scene = caustic_scene(glass(), true, Vec3{0, 0.6f, 0.49f});  // just inside the sphere's skin
  RenderSettings s = caustic_settings(LT::kOn, 32);
  s.max_depth = 100;
  const RenderResult r = render(scene, s);
  EXPECT_EQ(r.stats.nan_samples, 0u);
  EXPECT_EQ(r.dropped_splats, 0u);
  for (const PixelSums& p : r.film.pixels()) ASSERT_TRUE(std::isfinite(p.r) && std::isfinite(p.lum2));
  scene.camera.eye = {0, 0.6f, 0.2f};  // the camera inside the glass
  const RenderResult inside = render(scene, s);
  EXPECT_EQ(inside.stats.nan_samples, 0u);
  for (const PixelSums& p : inside.film.pixels()) ASSERT_TRUE(std::isfinite(p.r));
}

// The odd half's pixel means summed, over the whole film's: 1 in expectation when each half
// has its own light paths.
double odd_over_whole(const Film& film) {
  double all = 0, odd = 0;
  for (size_t i = 0; i < film.pixels().size(); ++i) {
    all += film.pixels()[i].lum_sum() / film.pixels()[i].n;
    odd += film.odd()[i].lum_sum() / film.odd()[i].n;
  }
  return odd / all;
}

TEST(LightTracer, SameBitsAtAnyThreadCountAndTiling) {
  const Scene scene = caustic_scene(glass());
  RenderSettings s = caustic_settings(LT::kOn, 32);
  s.aovs = kAovHalves;
  const RenderResult a = testing::render(scene, s, 1, 8), b = testing::render(scene, s, 2, 16);
  EXPECT_TRUE(same_bits(a.film, b.film));
  ASSERT_TRUE(a.film.halves());
  // Each half has its own light paths: both halves' means agree with the whole.
  EXPECT_NEAR(odd_over_whole(a.film), 1, 0.05);
}

// Every pixel traces a light path in each aligned block of four samples, on an even and an
// odd one in turn, and the coordinator's bound on a pass's light paths a pixel is exact.
TEST(LightTracer, EveryPixelsLightPathsReachBothHalves) {
  for (uint64_t p : {0ull, 1ull, 2ull, 3ull, 4ull, 7ull, 640ull * 480ull - 1, (1ull << 40) + 3}) {
    for (uint32_t block = 0; block < 64; ++block) {
      uint32_t traced[2] = {0, 0};  // even, odd samples
      for (uint32_t s = 8 * block; s < 8 * block + 8; ++s) traced[s & 1] += LightTracer::traces(p, s);
      EXPECT_EQ(traced[0], 1u) << "pixel " << p << " samples from " << 8 * block;
      EXPECT_EQ(traced[1], 1u) << "pixel " << p << " samples from " << 8 * block;
    }
  }
  for (uint32_t s0 = 0; s0 < 24; ++s0) {
    for (uint32_t s1 = s0; s1 < 48; ++s1) {
      uint64_t most = 0;
      for (uint64_t p = 0; p < 8; ++p) {
        uint64_t n = 0;
        for (uint32_t s = s0; s < s1; ++s) n += LightTracer::traces(p, s);
        most = std::max(most, n);
      }
      EXPECT_EQ(LightTracer::max_paths_per_pixel(s0, s1), most) << "samples " << s0 << " to " << s1;
    }
  }
  EXPECT_EQ(LightTracer::max_paths_per_pixel(4000000000u, 4000000004u), 1u);
}

// A window one pixel wide of an image of even width: its odd half has light paths of its
// own, so both halves see the caustic (the old pick gave them all to the even half).
TEST(LightTracer, AOnePixelWideWindowsHalvesBothHaveLightPaths) {
  const Scene scene = caustic_scene(glass());
  RenderSettings s = caustic_settings(LT::kOn, 256);
  s.aovs = kAovHalves;
  s.window = Rect{16, 0, 1, 24};
  const RenderResult r = testing::render(scene, s, 2, 8);
  ASSERT_TRUE(r.film.halves());
  // 0.866 with the old pick (the caustic is 13% of this column's light), 1.004 with this one.
  EXPECT_NEAR(odd_over_whole(r.film), 1, 0.05);
}

// scenes/cornell-shapes.gltf: caustic casters that are meshes of other shapes (a glass cube,
// a mirror torus) turn light tracing on, and it agrees with the path tracer alone.
TEST(LightTracer, TheShapesSceneAgreesWithThePathTracerAlone) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-shapes.gltf"));
  RenderSettings off;
  off.camera.framing = Framing::kFile;
  off.camera.width = 48;
  off.camera.height = 36;
  off.spp = 512;
  off.light_tracer = LT::kOff;
  RenderSettings on = off;
  on.spp = 128;
  on.light_tracer = LT::kAuto;
  const RenderResult a = render(scene, off), b = render(scene, on);
  ASSERT_TRUE(b.light_tracing.on) << b.light_tracing.why;
  EXPECT_GT(b.stats.rays.splats, 1000u);
  EXPECT_EQ(b.stats.nan_samples, 0u);
  EXPECT_EQ(b.dropped_splats, 0u);
  expect_agree(film_estimate(a.film), film_estimate(b.film), "frame");
}

// Auto: on where a mirror or glass surface can carry a finite light's flux; a scene
// without one renders the same bits as with light tracing off, at no cost.
TEST(LightTracer, AutoTurnsOnOnlyWhereItCanHelp) {
  const RenderResult with = render(caustic_scene(glass()), caustic_settings(LT::kAuto, 4));
  EXPECT_TRUE(with.light_tracing.on) << with.light_tracing.why;
  const Scene plain = caustic_scene(diffuse(0.5f));
  const RenderResult autod = render(plain, caustic_settings(LT::kAuto, 16)),
                     off = render(plain, caustic_settings(LT::kOff, 16));
  EXPECT_FALSE(autod.light_tracing.on);
  EXPECT_NE(autod.light_tracing.why.find("no mirror"), std::string::npos) << autod.light_tracing.why;
  EXPECT_TRUE(same_bits(autod.film, off.film));
  EXPECT_EQ(autod.stats.rays.rays, off.stats.rays.rays);
  RenderSettings adaptive = caustic_settings(LT::kAuto, 16);
  adaptive.adaptive = true;
  EXPECT_FALSE(render(caustic_scene(glass()), adaptive).light_tracing.on);
  adaptive.light_tracer = LT::kOn;
  EXPECT_THROW(adaptive.validate(), SettingsError);
}

}  // namespace
}  // namespace tessera
