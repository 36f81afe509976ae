// Whole-renderer physics and determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>

#include "core/io/image_io.h"
#include "core/render/local_renderer.h"
#include "core/scene/image_read.h"
#include "core/scene/load.h"
#include "tests/core/render_helpers.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

using testing::Estimate;
using testing::film_estimate;
using testing::furnace;
using testing::furnace_settings;
using testing::render;
using testing::transformed;

TEST(Furnace, WhiteDiffuseSphereReflectsExactlyTheEmittedRadiance) {
  Material white;
  white.reflectance = Rgb(1);
  const RenderResult r = render(furnace(white), furnace_settings());
  const Estimate e = film_estimate(r.film);
  // NEE and BSDF sampling both contribute (MIS): the mean is 1 within the estimator's noise.
  EXPECT_NEAR(e.mean, 1.0, 5 * e.stderr_ + 1e-6) << "stderr " << e.stderr_;
  EXPECT_LT(e.stderr_, 0.01);
  EXPECT_EQ(r.stats.nan_samples, 0u);
}

TEST(Furnace, GreyDiffuseSphereReflectsItsAlbedo) {
  Material grey;
  grey.reflectance = Rgb(0.5f);
  RenderSettings s = furnace_settings();
  s.camera.width = s.camera.height = 8;  // the central pixels all see the sphere
  s.window = Rect{2, 2, 4, 4};
  const Estimate e = film_estimate(render(furnace(grey), s).film);
  EXPECT_NEAR(e.mean, 0.5, 5 * e.stderr_ + 1e-6) << "stderr " << e.stderr_;
}

TEST(Furnace, GlassSphereConservesEnergyOnEveryPath) {
  Material glass;
  glass.kind = Material::Kind::kGlass;
  glass.ior = 1.5f;
  glass.reflectance = glass.transmittance = Rgb(1);
  const RenderResult r = render(furnace(glass), furnace_settings());
  // Reflection weighs 1, entering 1/eta^2 and leaving eta^2: each sample is exactly 1
  // up to rounding, however often it reflects inside.
  for (const PixelSums& p : r.film.pixels()) ASSERT_NEAR(p.lum_sum() / p.n, 1.0, 1e-4);
}

TEST(Furnace, IndexOneGlassVanishes) {
  Material clear;
  clear.kind = Material::Kind::kGlass;
  clear.ior = 1.0f;
  const RenderResult r = render(furnace(clear), furnace_settings());
  for (const PixelSums& p : r.film.pixels()) ASSERT_NEAR(p.lum_sum() / p.n, 1.0, 1e-5);
}

RenderSettings small_cornell() {
  RenderSettings s;
  s.camera.width = 64;
  s.camera.height = 48;
  s.spp = 12;
  s.pass_spp = 5;  // passes of 5, 5, 2
  s.max_depth = 8;
  s.seed = 7;
  return s;
}

// Bitwise equality of the sums (field by field: the struct has padding).
bool same_bits(const PixelSums& a, const PixelSums& b) {
  return std::memcmp(&a.r, &b.r, sizeof a.r) == 0 && std::memcmp(&a.g, &b.g, sizeof a.g) == 0 &&
         std::memcmp(&a.b, &b.b, sizeof a.b) == 0 && std::memcmp(&a.lum2, &b.lum2, sizeof a.lum2) == 0 && a.n == b.n;
}

bool identical(const Film& a, const Film& b) {
  if (a.pixels().size() != b.pixels().size()) return false;
  for (size_t i = 0; i < a.pixels().size(); ++i)
    if (!same_bits(a.pixels()[i], b.pixels()[i])) return false;
  return true;
}

TEST(Determinism, IdenticalBitsForAnyThreadCountAndTileSize) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  const RenderSettings s = small_cornell();
  const RenderResult a = render(scene, s, 1, 7), b = render(scene, s, 2, 16), c = render(scene, s, 3, 64);
  EXPECT_TRUE(identical(a.film, b.film));
  EXPECT_TRUE(identical(a.film, c.film));
  RenderSettings other = s;
  other.seed = 8;
  EXPECT_FALSE(identical(a.film, render(scene, other).film));
}

// Issue 12: each frame of a sequence has random numbers of its own, the same whichever
// way it is rendered; a still (no frame) keeps exactly the seed's image.
TEST(Determinism, EachFrameHasItsOwnNumbersAndAStillKeepsTheSeed) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  EXPECT_EQ(s.sample_seed(), s.seed);
  const RenderResult still = render(scene, s);
  s.frame = 7;
  const RenderResult seven = render(scene, s, 1, 7), again = render(scene, s, 3, 64);
  EXPECT_TRUE(identical(seven.film, again.film));
  EXPECT_FALSE(identical(seven.film, still.film));
  s.frame = 8;
  EXPECT_FALSE(identical(seven.film, render(scene, s).film));
  std::set<uint64_t> seeds;  // frames and seeds never share a sequence
  for (int seed = 0; seed < 4; ++seed)
    for (int frame = -2; frame < 50; ++frame) {
      RenderSettings f;
      f.seed = uint64_t(seed);
      f.frame = frame;
      EXPECT_TRUE(seeds.insert(f.sample_seed()).second) << seed << " " << frame;
    }
  s.frame = RenderSettings::kMaxFrame + 1;
  EXPECT_THROW(s.validate(), SettingsError);
}

TEST(Determinism, AdaptiveSamplingIsReproducibleAndStopsEarly) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  s.spp = 64;
  s.adaptive = true;
  s.adaptive_batch = 8;
  s.adaptive_tolerance = 0.2f;
  const RenderResult a = render(scene, s, 1, 5), b = render(scene, s, 2, 32);
  EXPECT_TRUE(identical(a.film, b.film));
  uint32_t min_n = 1u << 30, max_n = 0;
  for (const PixelSums& p : a.film.pixels()) {
    min_n = std::min(min_n, p.n);
    max_n = std::max(max_n, p.n);
    // Stops only where CS184 checks: after B+1, 2B+1, ... samples, or at the maximum.
    ASSERT_TRUE(p.n == 64 || (p.n - 1) % 8 == 0) << p.n;
  }
  EXPECT_EQ(min_n, 9u);  // some pixels converge at the first check
  EXPECT_EQ(max_n, 64u);
}

// The path tracer's pixels do not depend on the window. The light tracer's do: a window
// traces the light paths of its own camera samples (docs/light-tracing.md, "Windows"), so
// with it a window equals the whole image in expectation only.
TEST(Determinism, WindowRendersTheSamePixelsAsTheWholeImage) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  s.light_tracer = RenderSettings::LightTracer::kOff;
  const RenderResult whole = render(scene, s);
  s.window = Rect{10, 20, 17, 9};
  const RenderResult part = render(scene, s);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 17; ++x)
      ASSERT_TRUE(same_bits(part.film.at(x, y), whole.film.at(10 + x, 20 + y))) << x << "," << y;
}

TEST(MaxDepth, ZeroShowsOnlyEmitters) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  s.max_depth = 0;
  s.camera.width = 480;  // CS184 framing: only at 480x360 does the frame reach the light
  s.camera.height = 360;
  s.spp = 1;
  const RenderResult r = render(scene, s);
  int lit = 0;
  for (const PixelSums& p : r.film.pixels()) {
    const double v = p.lum_sum() / p.n;
    ASSERT_LE(v, 12.0 + 1e-9);  // at most the light's radiance
    if (v > 0) ++lit;
  }
  EXPECT_GT(lit, 0);
  EXPECT_LT(lit, int(r.film.pixels().size()) / 20);  // the light is a small part of the frame
}

TEST(MaxDepth, EachBounceAddsLight) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  double prev = -1;
  for (int m : {0, 1, 2, 4}) {
    s.max_depth = m;
    const double mean = film_estimate(render(scene, s).film).mean;
    EXPECT_GT(mean, prev) << "max depth " << m;
    prev = mean;
  }
}

TEST(Robustness, NoSelfIntersectionsAndNoNaNsInTheCornellBox) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  const RenderResult r = render(scene, small_cornell());
  EXPECT_EQ(r.stats.rays.self_hits, 0u);
  EXPECT_EQ(r.stats.nan_samples, 0u);
  EXPECT_GT(r.stats.rays.rays, r.stats.samples);
}

// Smoke renders at low sample counts against stored means from 1024 spp renders (same
// settings). Tolerance: 5 standard errors of the low-spp estimate, plus the reference's
// own error, which is 4x smaller still.
struct SmokeCase {
  const char* scene;
  bool shared;
  double reference;
};

void PrintTo(const SmokeCase& c, std::ostream* os) { *os << c.scene; }

class Smoke : public ::testing::TestWithParam<SmokeCase> {};

TEST_P(Smoke, MeanRadianceMatchesTheStoredValue) {
  const SmokeCase c = GetParam();
  std::string path = c.shared ? testing::shared_scene(c.scene) : testing::source_path(std::string("scenes/") + c.scene);
  if (path.empty()) GTEST_SKIP() << "shared CS184 scene " << c.scene << " not found under " TESSERA_SHARED_DIR;
  const Scene scene = load_scene(path);
  RenderSettings s;
  s.camera.width = 160;
  s.camera.height = 120;
  s.spp = 16;
  s.max_depth = 16;
  const RenderResult r = render(scene, s);
  const Estimate e = film_estimate(r.film);
  EXPECT_NEAR(e.mean, c.reference, 5 * e.stderr_ * 1.03) << "stderr " << e.stderr_;
  EXPECT_EQ(r.stats.nan_samples, 0u);
}

INSTANTIATE_TEST_SUITE_P(Scenes, Smoke,
                         ::testing::Values(SmokeCase{"CBspheres.dae", true, SMOKE_CBSPHERES},
                                           SmokeCase{"cornell-spheres.dae", false, SMOKE_CORNELL}),
                         [](const auto& info) {
                           return std::string(info.param.shared ? "CBspheres" : "cornell_spheres");
                         });

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

class ScaleInvariance : public ::testing::TestWithParam<std::pair<float, float>> {};

// Ray offsets are relative to the coordinates' magnitude (docs/ray-offsets.md): the image
// must not change with the scene's scale or distance from the origin, and no ray may hit
// the triangle it left.
TEST_P(ScaleInvariance, SameImageNoSelfHitsNoNaNs) {
  const auto [scale, offset] = GetParam();
  const Scene base = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  s.camera.width = 96;
  s.camera.height = 72;
  s.spp = 8;
  const RenderResult ref = render(base, s);
  const RenderResult r = render(transformed(base, scale, Vec3{offset, offset, offset}), s);
  const Estimate a = film_estimate(ref.film), b = film_estimate(r.film);
  EXPECT_NEAR(b.mean, a.mean, 0.01 * a.mean) << "scale " << scale << " offset " << offset;
  EXPECT_EQ(r.stats.rays.self_hits, 0u);
  EXPECT_EQ(r.stats.nan_samples, 0u);
}

INSTANTIATE_TEST_SUITE_P(Scales, ScaleInvariance,
                         ::testing::Values(std::make_pair(1e-4f, 0.0f), std::make_pair(1e-2f, 0.0f),
                                           std::make_pair(1e2f, 0.0f), std::make_pair(1e4f, 0.0f),
                                           std::make_pair(1.0f, 1e5f)));

// Surfaces lying exactly on coordinate planes: their hit points are exact (zero error
// bound), and a ray must still leave them. Regression: origins were not moved at all
// and every shadow ray from a floor at y = 0 hit the floor at t = 0.
TEST(Robustness, SurfacesOnCoordinatePlanesAreLit) {
  const Scene base = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s = small_cornell();
  s.camera.width = 96;
  s.camera.height = 72;
  s.spp = 8;
  const Estimate a = film_estimate(render(base, s).film);
  // Floor to y = 0, back wall to z = 0, left wall to x = 0.
  const RenderResult r = render(transformed(base, 1.0f, Vec3{1.0f, 0.75f, 1.0f}), s);
  EXPECT_NEAR(film_estimate(r.film).mean, a.mean, 0.01 * a.mean);
  EXPECT_EQ(r.stats.rays.self_hits, 0u);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// The default scene in both formats: the glTF file has fine sphere meshes, an emissive
// quad for the light and the camera CS184 framing gives the .dae at 480x360, so the two
// images must agree within noise, region by region.
TEST(Formats, ColladaAndGltfCornellSpheresGiveTheSameImage) {
  RenderSettings s;
  s.camera.width = 480;
  s.camera.height = 360;
  s.spp = 4;
  s.max_depth = 8;
  const Scene dae = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  const Scene gltf = load_scene(testing::source_path("scenes/cornell-spheres.gltf"));
  const RenderResult a = render(dae, s);
  s.camera.framing = Framing::kFile;
  const RenderResult b = render(gltf, s);
  const int nx = 4, ny = 3;
  for (int ry = 0; ry < ny; ++ry)
    for (int rx = 0; rx < nx; ++rx) {
      double ma = 0, mb = 0, va = 0, vb = 0;
      int n = 0;
      for (int y = ry * 360 / ny; y < (ry + 1) * 360 / ny; ++y)
        for (int x = rx * 480 / nx; x < (rx + 1) * 480 / nx; ++x, ++n) {
          const PixelSums &pa = a.film.at(x, y), &pb = b.film.at(x, y);
          ma += pa.lum_sum() / pa.n;
          mb += pb.lum_sum() / pb.n;
          va += pa.mean_variance();
          vb += pb.mean_variance();
        }
      ma /= n;
      mb /= n;
      const double sigma = std::sqrt(va + vb) / n;
      // 5 standard errors, plus 1% for the spheres' tessellation.
      EXPECT_NEAR(ma, mb, 5 * sigma + 0.01 * ma) << "region " << rx << "," << ry << " sigma " << sigma;
    }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Light sampling alone, BSDF sampling alone and their MIS combination estimate the same
// integral: the three means agree within their standard errors.
TEST(Estimators, SwitchesReachTheIntegrator) {
  // Regression: the switches were once left uninitialised, and NEE was on or off at random.
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s;
  s.camera.width = 32;
  s.camera.height = 24;
  s.spp = 2;
  for (int run = 0; run < 3; ++run) EXPECT_GT(testing::render(scene, s).stats.rays.shadow_rays, 0u);
  s.nee = false;
  EXPECT_EQ(testing::render(scene, s).stats.rays.shadow_rays, 0u);
}

TEST(Estimators, WithoutNeeAndWithoutMisTheMeanIsUnchanged) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s;
  s.camera.width = 160;
  s.camera.height = 120;
  s.spp = 8;
  s.max_depth = 6;
  const testing::Estimate full = testing::film_estimate(testing::render(scene, s).film);
  s.mis = false;
  const testing::Estimate no_mis = testing::film_estimate(testing::render(scene, s).film);
  s.mis = true;
  s.nee = false;
  const testing::Estimate no_nee = testing::film_estimate(testing::render(scene, s).film);
  EXPECT_NEAR(no_mis.mean, full.mean, 5 * std::hypot(no_mis.stderr_, full.stderr_));
  EXPECT_NEAR(no_nee.mean, full.mean, 5 * std::hypot(no_nee.stderr_, full.stderr_));
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: the variance channel was the double's variance rounded to float, +inf for
// an emitter near the 1e20 bound (its squared luminance passes float). It is float's
// largest there; the colour is untouched.
TEST(ExrOutput, AVarianceFloatCannotHoldIsItsLargest) {
  Film film(Rect{0, 0, 2, 1});
  film.at(0, 0) = PixelSums{9e19, 9e19, 9e19, 2 * 8.1e39, 2};
  film.at(1, 0) = PixelSums{0.5, 0.5, 0.5, 0.25, 2};
  const std::string path =
      (std::filesystem::temp_directory_path() / ("tessera_var_" + std::to_string(::getpid()) + ".exr")).string();
  write_exr(path, film, {});
  const ExrImage img = read_exr(path);
  std::filesystem::remove(path);
  EXPECT_EQ(img.channels.at("variance")[0], std::numeric_limits<float>::max());
  EXPECT_TRUE(std::isfinite(img.channels.at("variance")[1]));
  EXPECT_FLOAT_EQ(img.channels.at("R")[0], 4.5e19f);
}

}  // namespace
}  // namespace tessera
