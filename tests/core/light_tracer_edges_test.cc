// The light tracer at numerical edges (found by audit, 2026-11-29): a light in a plane through
// the origin, a light of radiance 1e8, a target seen from 2e5 radii away.
#include <gtest/gtest.h>

#include <set>

#include "core/render/delta_targets.h"
#include "core/render/light_tracer.h"
#include "core/render/splats.h"
#include "core/sampling/sampler.h"
#include "core/scene/load.h"
#include "tests/core/caustic_scene.h"
#include "tests/core/render_helpers.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

using testing::render;
using namespace testing::caustics;

// Found by audit: for a target seen from more than about 700 radii the cosine test of its
// cone rounded (1 - omc to 1) and counted another target's density for directions far
// outside its cone, at random: a distant light's light tracing was 2.9% dark with two.
TEST(DeltaTargets, ANarrowConeCountsOnlyDirectionsInsideIt) {
  Scene s = caustic_scene(glass());
  s.spheres.push_back(Sphere{"second", {0.3f, 1.7f, 3.1f}, 0.5f, 1, -1});
  const DeltaTargets targets(s);
  ASSERT_EQ(targets.targets().size(), 2u);
  // Directions toward the first target alone, from afar (each cone some 1e-5 rad across, the
  // targets 3e-5 rad apart): the density is the first cone's, the same for every one.
  int mixed = 0;
  for (const Vec3 from : {Vec3{1e5f, 0.6f, 0}, Vec3{7.3e4f, 1234.5f, -2345.6f}, Vec3{-3.3e4f, 2.5e4f, 1.1e4f}}) {
    std::set<float> densities;
    for (int i = 0; i < 4096; ++i) {
      Sampler sm(3, 0, uint32_t(i));
      const float u = sm.next_1d() * 0.5f;  // (picks the first target)
      float pdf = 0;
      targets.sample(from, u, sm.next_2d(), &pdf);
      densities.insert(pdf);
    }
    mixed += densities.size() != 1;
  }
  EXPECT_EQ(mixed, 0);
}

// Found by audit: a rect light in a plane through the origin started its light paths a
// denormal off its own triangles, which Embree's plane test hit at t = 0: no light path left
// it, and `auto` rendered the caustics' share of the image black (27% darker). The light's
// points take the surface points' underflow floor.
TEST(LightTracer, ALightInAPlaneThroughTheOriginSendsItsLightPaths) {
  const Scene scene = caustic_scene(glass(), true, std::nullopt, -2.2f, 0.6f);  // (|Ng| 0.36: below 1/2)
  ASSERT_EQ(scene.lights[0].position.y, 0.f);
  const RenderResult a = render(scene, caustic_settings(LT::kOff, 1024)),
                     b = render(scene, caustic_settings(LT::kOn, 128));
  EXPECT_GT(b.stats.rays.splats, 1000u);
  expect_same_image(a.film, b.film);
}

// Found by audit: a splat's channel is capped at 2^20 in its fixed-point sums, and a light of
// radiance 1.2e8 lost every caustic splat (7% dark, said only in the summary line). Its
// splats now enter the sums scaled down by a power of two from the brightest light
// (splat_exponent_for), and the image's fold scales them back.
TEST(LightTracer, ALightOfRadiance1e8KeepsItsCaustic) {
  const Scene scene = caustic_scene(glass(), true, std::nullopt, 0, 0.8f, 2e7f);
  EXPECT_EQ(splat_exponent_for(caustic_scene(glass()).lights, 32 * 24), 0);  // everyday scenes: as before
  EXPECT_GT(splat_exponent_for(scene.lights, 32 * 24), 0);
  const RenderResult a = render(scene, caustic_settings(LT::kOff, 1024)),
                     b = render(scene, caustic_settings(LT::kOn, 128));
  EXPECT_EQ(b.dropped_splats, 0u);
  EXPECT_GT(b.stats.rays.splats, 1000u);
  expect_same_image(a.film, b.film);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

using testing::render;
using namespace testing::caustics;

// Found by audit: KHR_materials_clearcoat's Fresnel is taken at the viewing direction only
// (not reciprocal), and the light tracer weighed a delta lobe under the coat by it at the
// light's side: on a clear-coated glass prism the light paths' caustic was 5% dark and the
// prism's shadow 23% (a sphere hid it: its entry and exit angles swap and the error
// cancels). tests/core/data/clearcoat-prism.gltf: a smooth glass prism (ior 1.5, a smooth
// coat of factor 1) on a diffuse floor, an emissive quad lighting one face at about 75
// degrees, the light leaving near the normal of another. The light tracer and the path
// tracer agree over the frame, the caustic and the shadow.
TEST(LightTracer, AgreesWithThePathTracerThroughAClearCoatedPrism) {
  const Scene scene = load_scene(testing::source_path("tests/core/data/clearcoat-prism.gltf"));
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = 64;
  s.camera.height = 48;
  s.max_depth = 8;
  s.seed = 9;
  s.spp = 4096;
  s.light_tracer = LT::kOff;
  const RenderResult pt = render(scene, s);
  s.spp = 1024;
  s.light_tracer = LT::kOn;
  const RenderResult lt = render(scene, s);
  ASSERT_TRUE(lt.light_tracing.on);
  expect_agree(testing::film_estimate(pt.film), testing::film_estimate(lt.film), "frame");
  expect_agree(block(pt.film, 15, 21, 13, 6), block(lt.film, 15, 21, 13, 6), "caustic");
  expect_agree(block(pt.film, 30, 22, 20, 4), block(lt.film, 30, 22, 20, 4), "shadow");
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a frame's splat film was two full planes of int64 sums made at the
// first record, 1.06 GB for an 8K frame even when no splat landed (the coordinator's
// memory for such a frame 2.64 GB against its film's 1.33 GB). Its sums are chunks made at
// their first splat; the sums read back are the same.
TEST(SplatFilm, ItsSumsTakeMemoryOnlyWhereSplatsLanded) {
  SplatFilm film(Rect{0, 0, 7680, 4320}, int64_t(7680) * 4320, true);
  EXPECT_EQ(film.bytes(), 0u);
  SplatRecord record;
  record.paths = 10;
  SplatEntry e;
  e.index = uint32_t(7680 * 2000 + 4000);
  e.v[0] = 5, e.v[1] = 6, e.v[2] = 7, e.v[3] = 8;
  record.entries.push_back(e);
  film.add_record(record);
  film.add_record(record);
  EXPECT_EQ(film.bytes(), (uint64_t(1) << 14) * 32);  // one chunk
  const SplatSums at = film.at(4000, 2000);
  EXPECT_EQ(at.rgb[0], 10);
  EXPECT_EQ(at.lum2, 16);
  EXPECT_EQ(film.at(0, 0).rgb[0], 0);
  EXPECT_EQ(film.at(4000, 2000, true).rgb[0], 0);  // the odd plane
  std::vector<SplatSums> row;
  film.copy_rows(2000, 1, false, &row);
  EXPECT_EQ(row[4000].rgb[2], 14);
  // Rows set back (a checkpoint): zero rows make no chunk.
  SplatFilm restored(Rect{0, 0, 7680, 4320}, int64_t(7680) * 4320, true);
  std::vector<SplatSums> zeros(7680);
  restored.set_rows(100, 1, true, zeros.data());
  EXPECT_EQ(restored.bytes(), 0u);
  restored.set_rows(2000, 1, false, row.data());
  EXPECT_EQ(restored.at(4000, 2000).rgb[2], 14);
  film.clear();
  EXPECT_EQ(film.bytes(), 0u);
}

}  // namespace
}  // namespace tessera
