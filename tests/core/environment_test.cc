// The uniform environment light (--env-color) and the default environment of an unlit
// glTF scene: white furnaces, each estimator alone unbiased, and the settings' effect.
#include <gtest/gtest.h>

#include "core/light/lights.h"
#include "core/render/lighting.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#include "tests/core/render_helpers.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

using testing::film_estimate;
using testing::render;

// A unit sphere of albedo rho under a uniform environment of radiance 1 and nothing else:
// every point on it sees radiance 1 over its whole hemisphere, so every pixel is rho (the
// background 1).
Scene open_furnace(Material inner) { return testing::lone_sphere(std::move(inner)); }

RenderSettings env_settings() {
  RenderSettings s = testing::furnace_settings();
  s.environment = Rgb(1);
  return s;
}

TEST(Environment, AWhiteSphereUnderAUniformEnvironmentIsOneEverywhereWithEveryEstimator) {
  Material white;
  white.reflectance = Rgb(1);
  const Scene scene = open_furnace(white);
  for (const auto& [nee, mis] : {std::pair{true, true}, {true, false}, {false, true}}) {
    RenderSettings s = env_settings();
    s.nee = nee;
    s.mis = mis;
    const testing::Estimate e = film_estimate(render(scene, s).film);
    EXPECT_NEAR(e.mean, 1.0, 4 * e.stderr_ + 2e-3) << "nee " << nee << " mis " << mis;
  }
  Material grey;
  grey.reflectance = Rgb(0.5f);
  RenderSettings s = env_settings();
  const Film film = render(open_furnace(grey), s).film;
  // The centre pixel sees only the sphere: 0.5 (1 bounce, then the environment).
  const PixelSums& centre = film.pixels()[size_t(12 * 24 + 12)];
  EXPECT_NEAR(centre.lum_sum() / centre.n, 0.5, 0.02);
  // A corner pixel sees only the environment: exactly 1 (no sampling involved).
  const PixelSums& corner = film.pixels()[0];
  EXPECT_DOUBLE_EQ(corner.lum_sum() / corner.n, 1.0);
}

TEST(Environment, WithoutTheFlagNothingChanges) {
  Material white;
  white.reflectance = Rgb(1);
  const Scene scene = open_furnace(white);  // no lights at all, and not a glTF scene
  const testing::Estimate e = film_estimate(render(scene, testing::furnace_settings()).film);
  EXPECT_EQ(e.mean, 0.0);
  EXPECT_EQ(LightSet(scene).size(), 0u);  // nothing added: no per-sample cost
}

TEST(Environment, AnUnlitGltfSceneGetsTheDefaultEnvironmentWithAWarningAndTheFlagTurnsItOff) {
  EXPECT_FALSE(load_scene(testing::source_path("scenes/cornell-spheres.gltf")).unlit);  // it has an emitter
  // A triangle with the default material, no light and no emitter.
  const Scene unlit = load_scene(testing::source_path("tests/fuzz/seeds/gltf/animated.gltf"));
  ASSERT_TRUE(unlit.unlit);
  bool warned = false;
  for (const std::string& w : unlit.warnings) warned |= w.find("no lights") != std::string::npos;
  EXPECT_TRUE(warned);
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = 16;
  s.camera.height = 12;
  s.spp = 4;
  EXPECT_GT(film_estimate(render(unlit, s).film).mean, 0.1);
  s.default_environment = false;
  EXPECT_EQ(film_estimate(render(unlit, s).film).mean, 0.0);
  s.environment = Rgb(0.25f);  // an explicit one replaces the default
  s.default_environment = true;
  const double quarter = film_estimate(render(unlit, s).film).mean;
  s.environment = Rgb(1);
  EXPECT_NEAR(film_estimate(render(unlit, s).film).mean, 4 * quarter, 1e-6 * quarter);  // linear in it
}

// The lighting line the CLI prints names what lights the render, as TileRenderer chooses.
TEST(Environment, TheLightingChosenIsDescribed) {
  RenderSettings s;
  const Scene cornell = load_scene(testing::source_path("scenes/cornell-spheres.gltf"));
  EXPECT_EQ(describe_lighting(cornell, s), "1 emissive surface sampled as a light");
  const Scene unlit = load_scene(testing::source_path("tests/fuzz/seeds/gltf/animated.gltf"));
  EXPECT_NE(describe_lighting(unlit, s).find("the default environment (uniform radiance 1)"), std::string::npos);
  s.default_environment = false;
  EXPECT_EQ(describe_lighting(unlit, s),
            "none: the scene has no light and --no-default-env is set, so the image is black");
  // A scene without lights that is not glTF gets no default environment: no flag to blame.
  Scene dark = unlit;
  dark.unlit = false;
  EXPECT_EQ(describe_lighting(dark, RenderSettings()), "none: the scene has no light, so the image is black");
  s.environment = Rgb(0.5f);
  s.environment_strength = 2;
  EXPECT_EQ(describe_lighting(unlit, s), "a uniform environment of radiance (0.5, 0.5, 0.5) x strength 2");
  // Dim emission glows: counted, not a light, and the default environment stays.
  Scene glow = unlit;
  glow.materials[glow.meshes[0].material].radiance = Rgb(0.2f);
  const std::string d = describe_lighting(glow, RenderSettings());
  EXPECT_NE(d.find(std::to_string(glow.meshes.size()) + " glowing surface"), std::string::npos) << d;
  EXPECT_NE(d.find("(emission below a mean radiance of 1: seen and reflected, not sampled as a light)"),
            std::string::npos)
      << d;
  EXPECT_NE(d.find("default environment"), std::string::npos) << d;
  const Scene dae = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  EXPECT_NE(describe_lighting(dae, RenderSettings()).find("area light"), std::string::npos);
}

TEST(Environment, RangeIsChecked) {
  RenderSettings s;
  s.environment = Rgb(1, -1, 0);
  EXPECT_THROW(s.validate(), SettingsError);
  s.environment = Rgb(1, std::nanf(""), 0);
  EXPECT_THROW(s.validate(), SettingsError);
  s.environment = Rgb(1e21f);
  EXPECT_THROW(s.validate(), SettingsError);
  s.environment = Rgb(2);
  EXPECT_NO_THROW(s.validate());
  // --env-strength, --env-rotate and the --env path, each refused by its flag.
  auto flag_of = [](const RenderSettings& r) {
    try {
      r.validate();
    } catch (const SettingsError& e) {
      return e.flag();
    }
    return std::string("none");
  };
  for (float strength : {-1.0f, std::nanf(""), 1e21f}) {
    RenderSettings r;
    r.environment_strength = strength;
    EXPECT_EQ(flag_of(r), "--env-strength") << strength;
  }
  for (float rotation : {std::nanf(""), INFINITY, 1e7f}) {
    RenderSettings r;
    r.environment_rotation = rotation;
    EXPECT_EQ(flag_of(r), "--env-rotate") << rotation;
  }
  for (float ev : {std::nanf(""), INFINITY, 65.0f, -65.0f}) {  // --exposure, with them (a display setting)
    RenderSettings r;
    r.exposure = ev;
    EXPECT_EQ(flag_of(r), "--exposure") << ev;
  }
  RenderSettings r;
  r.environment_map.assign(RenderSettings::kMaxEnvironmentPath + 1, 'x');
  EXPECT_EQ(flag_of(r), "--env");
  r.environment_map = "sky.hdr";
  r.environment_strength = 0;
  r.environment_rotation = -720;
  EXPECT_EQ(flag_of(r), "none");
}

}  // namespace
}  // namespace tessera
