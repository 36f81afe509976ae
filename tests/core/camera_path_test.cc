// Camera paths: the file format's checks, the interpolation, and what a frame's camera
// takes from the path (turntable, focus pull).
#include "core/camera/camera_path.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "core/camera/camera.h"
#include "core/render/settings.h"
#include "core/render/tile_renderer.h"
#include "core/scene/load.h"
#include "tests/core/gltf_fixture.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

void expect_refused(const std::string& json, const std::string& part) {
  try {
    CameraPath::parse(json);
    ADD_FAILURE() << "accepted: " << json;
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--camera-path");
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(CameraPath, BadFilesAreRefusedNamingTheKeyAndField) {
  expect_refused("not json", "not JSON");
  expect_refused("[1, 2]", "must be a JSON object");
  expect_refused(R"({"keyz": []})", "keyz: unknown field");
  expect_refused(R"({"keys": [{"eye": [0, 0, 1]}]})", "key 1: has no frame");
  expect_refused(R"({"keys": [{"frame": 1}, {"frame": 1}]})", "key 2: frame 1.0 does not come after");
  expect_refused(R"({"keys": [{"frame": 5}, {"frame": 2}]})", "key 2: frame 2.0 does not come after");
  expect_refused(R"({"keys": [{"frame": 1, "eye": [0, 1]}]})", "key 1 eye: must be [x, y, z]");
  expect_refused(R"({"keys": [{"frame": 1, "eye": [0, "a", 1]}]})", "key 1 eye: must be a number");
  expect_refused(R"({"keys": [{"frame": 1, "eye": [0, 1e999, 1]}]})", "1e999");
  expect_refused(R"({"keys": [{"frame": 1, "eye": [0, 1e13, 1]}]})", "within 1e12");
  expect_refused(R"({"keys": [{"frame": 1, "fov": 180}]})", "key 1 fov: must be between 0 and 180");
  expect_refused(R"({"keys": [{"frame": 1, "lens_radius": -0.1}]})", "key 1 lens_radius");
  expect_refused(R"({"keys": [{"frame": 1, "focal_distance": 0}]})", "key 1 focal_distance: must be > 0");
  expect_refused(R"({"keys": [{"frame": 1, "max_depth": 2.5}]})", "key 1 max_depth: must be a whole number");
  expect_refused(R"({"keys": [{"frame": 1, "up": [0, 0, 0]}]})", "key 1 up: must not be zero");
  expect_refused(R"({"keys": [{"frame": 1, "eye": [1, 1, 1], "target": [1, 1, 1]}]})", "the same point");
  expect_refused(R"({"keys": [{"frame": 1, "zoom": 2}]})", "key 1 zoom: unknown field");
  expect_refused(R"({"turntable": {}})", "turntable: has no frames");
  expect_refused(R"({"turntable": {"frames": 0}})", "turntable frames: must not be 0");
  expect_refused(R"({"turntable": {"frames": 10, "axis": [0, 0, 0]}})", "turntable axis: must not be zero");
  expect_refused(std::string(CameraPath::kMaxBytes + 1, ' '), "larger than 1 MiB");
}

TEST(CameraPath, MonotoneCubicPassesThroughItsKeysAndNeverOvershoots) {
  const std::vector<double> xs{0, 1, 2, 10}, ys{0, 1, 1.1, 5};
  for (size_t i = 0; i < xs.size(); ++i) EXPECT_DOUBLE_EQ(monotone_cubic(xs, ys, xs[i]), ys[i]);
  EXPECT_EQ(monotone_cubic(xs, ys, -5), 0);  // held outside
  EXPECT_EQ(monotone_cubic(xs, ys, 50), 5);
  double prev = -1;
  for (double x = 0; x <= 10; x += 0.01) {  // monotone data: a monotone curve
    const double y = monotone_cubic(xs, ys, x);
    EXPECT_GE(y, prev - 1e-12) << x;
    prev = y;
  }
  // Smooth (C1) through an interior key: equal slopes either side.
  const double h = 1e-6;
  const double left = (monotone_cubic(xs, ys, 1) - monotone_cubic(xs, ys, 1 - h)) / h;
  const double right = (monotone_cubic(xs, ys, 1 + h) - monotone_cubic(xs, ys, 1)) / h;
  EXPECT_NEAR(left, right, 1e-4);
  // A peak stays a peak: no overshoot past the highest key.
  const std::vector<double> px{0, 1, 2}, py{0, 1, 0};
  for (double x = 0; x <= 2; x += 0.01) EXPECT_LE(monotone_cubic(px, py, x), 1 + 1e-12);
}

TEST(CameraPath, ChannelsInterpolateOverTheKeysThatSetThemAndStepsHold) {
  const CameraPath path = CameraPath::parse(R"({"keys": [
      {"frame": 0, "focal_distance": 2, "max_depth": 0},
      {"frame": 5, "lens_radius": 0.1, "max_depth": 3},
      {"frame": 10, "focal_distance": 6}]})");
  CameraPath::At a = path.at(5);
  EXPECT_FLOAT_EQ(*a.focal_distance, 4);  // two keys: a straight line
  EXPECT_FLOAT_EQ(*a.lens_radius, 0.1f);  // one key: held everywhere
  EXPECT_EQ(*a.max_depth, 3);
  EXPECT_FALSE(a.eye || a.target || a.up || a.fov || a.orbit);  // from the scene
  EXPECT_EQ(*path.at(4.9).max_depth, 0);
  EXPECT_EQ(*path.at(-3).max_depth, 0);
  EXPECT_FLOAT_EQ(*path.at(-3).focal_distance, 2);
  EXPECT_FLOAT_EQ(*path.at(30).focal_distance, 6);
  // The wire's canonical text gives the same path.
  const CameraPath again = CameraPath::parse(path.to_json());
  EXPECT_EQ(again.to_json(), path.to_json());
  for (double f : {-1.0, 2.5, 7.0}) EXPECT_EQ(*again.at(f).focal_distance, *path.at(f).focal_distance);
}

TEST(CameraPath, ATurntableTurnsTheCameraAboutTheSceneAndComesBack) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(R"({"turntable": {"frames": 8}})"));
  auto camera_at = [&](int frame) {
    s.frame = frame;
    return Camera(scene, s.at_frame().camera);
  };
  const Camera still(scene, RenderSettings().camera);
  const Vec3 center = scene.object_bounds().center();
  const Camera c0 = camera_at(0), c2 = camera_at(2), c8 = camera_at(8);
  EXPECT_EQ(c0.eye().x, still.eye().x);  // angle 0: the still's camera, bit for bit
  EXPECT_EQ(c0.eye().z, still.eye().z);
  EXPECT_NEAR(c8.eye().x, c0.eye().x, 1e-5);  // one turn: back where it started
  EXPECT_NEAR(c8.eye().z, c0.eye().z, 1e-5);
  // A quarter turn about +Y: the eye moves from +Z of the centre to +X, still looking at it.
  const Vec3 d0 = c0.eye() - center, d2 = c2.eye() - center;
  EXPECT_NEAR(length(d2), length(d0), 1e-4);
  EXPECT_NEAR(d2.x, d0.z, 1e-4);
  EXPECT_NEAR(d2.y, d0.y, 1e-4);
  EXPECT_NEAR(dot(c2.forward(), normalize(center - c2.eye())), dot(c0.forward(), normalize(center - c0.eye())), 1e-5);
}

TEST(CameraPath, AFocusPullMovesThePlaneWhereLensRaysMeet) {
  Scene scene;
  scene.camera.present = true;
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 1, "lens_radius": 0.2, "focal_distance": 2}, {"frame": 11, "focal_distance": 4}]})"));
  for (const auto& [frame, distance] : {std::pair{1, 2.0f}, {6, 3.0f}, {11, 4.0f}}) {
    s.frame = frame;
    const Camera cam(scene, s.at_frame().camera);
    ASSERT_TRUE(cam.is_thin_lens());
    // Rays through the centre pixel from two lens points meet on the optical axis at -F.
    const float fx = s.camera.width / 2.0f, fy = s.camera.height / 2.0f;
    const Ray a = cam.generate(fx, fy, Vec2{0.1f, 0.5f}), b = cam.generate(fx, fy, Vec2{0.9f, 0.5f});
    const float ta = (distance - 0) / -a.d.z;  // both start on the lens plane z = 0 (camera at the origin)
    const float tb = distance / -b.d.z;
    EXPECT_NEAR(a.o.x + ta * a.d.x, b.o.x + tb * b.d.x, 1e-4) << frame;
    EXPECT_NEAR(a.o.z + ta * a.d.z, -distance, 1e-4) << frame;
  }
}

TEST(CameraPath, AFrameOfAPathRendersAloneAsInItsSequenceAndSharesTheBvh) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s;
  s.camera.width = 24;
  s.camera.height = 18;
  s.spp = 4;
  s.light_tracer = RenderSettings::LightTracer::kOff;  // the path tracer's tiles (light paths: light_tracer_test)
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 1, "lens_radius": 0.05, "focal_distance": 3}, {"frame": 3, "focal_distance": 5}],
          "turntable": {"frames": 12}})"));
  TileRenderer sequence(scene, s);
  TileStats st;
  const Rect all{0, 0, 24, 18};
  for (int frame : {1, 2, 3}) {
    sequence.set_frame(frame);
    const auto in_sequence = sequence.render(all, 0, 4, nullptr, &st);
    RenderSettings alone = s;
    alone.frame = frame;
    const auto by_itself = TileRenderer(scene, alone).render(all, 0, 4, nullptr, &st);
    const auto shared = TileRenderer(sequence, alone).render(all, 0, 4, nullptr, &st);
    for (size_t i = 0; i < by_itself.size(); ++i) {
      ASSERT_EQ(in_sequence[i].r, by_itself[i].r) << frame;
      ASSERT_EQ(shared[i].g, by_itself[i].g) << frame;
    }
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a path was checked at frame 0 alone. One whose eye crossed its target at
// frame 5 was accepted and failed there (on the farm a task at a time, for good), and one
// that crosses only at frame 0, which the sequence never renders, was refused.
TEST(CameraPath, EachFrameOfTheSequenceIsCheckedAndOnlyThose) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-spheres.dae"));
  RenderSettings s;
  s.camera.framing = Framing::kCs184;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 0, "eye": [0, 0.5, 3], "target": [0, 0.5, 0]},
                   {"frame": 10, "eye": [0, 0.5, -3], "target": [0, 0.5, 0]}]})"));
  EXPECT_NO_THROW(TileRenderer::check_settings(scene, s, {1, 2, 3, 4}));
  try {
    TileRenderer::check_settings(scene, s, {1, 2, 3, 4, 5, 6});
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--camera-path");
    EXPECT_NE(std::string(e.what()).find("at frame 5: the camera is degenerate"), std::string::npos) << e.what();
  }
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": -10, "eye": [0, 0.5, 3], "target": [0, 0.5, 0]},
                   {"frame": 10, "eye": [0, 0.5, -3], "target": [0, 0.5, 0]}]})"));
  EXPECT_THROW(TileRenderer::check_settings(scene, s), SettingsError);  // a still at frame 0
  EXPECT_NO_THROW(TileRenderer::check_settings(scene, s, {1, 2, 3}));
  // A turntable whose turn takes 1e-320 frames: its angle is not a number past frame 0.
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(R"({"turntable": {"frames": 1e-320}})"));
  try {
    TileRenderer::check_settings(scene, s, {0, 1, 2});
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--turntable");
    EXPECT_NE(std::string(e.what()).find("at frame 1:"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a farm job carries the path written out again, longer than the file (1e11
// becomes 100000000000.0), and the coordinator held that to the file's 1 MiB: a file under
// it rendered here and was refused at submit. Now both refuse it, saying why.
TEST(CameraPath, APathThatWrittenOutPassesTheBoundIsRefusedHereToo) {
  std::string text = R"({"keys": [)";
  for (int k = 0; k < 26000; ++k)
    text += (k ? "," : "") + std::string(R"({"frame":)") + std::to_string(k) + R"(,"focal_distance":1e11})";
  text += "]}";
  ASSERT_LT(text.size(), CameraPath::kMaxBytes);
  try {
    CameraPath::parse(text);
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_NE(std::string(e.what()).find("written out as a job carries it, it takes"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// A frame's job carries only what that frame takes from the path (CameraPath::for_frame),
// written out and read back as the wire does: the frame's values must be the whole path's
// bit for bit, at keys, between them, before the first and after the last, turntable too.
TEST(CameraPath, WhatAFrameTakesFromThePathIsThePathAtThatFrameBitForBit) {
  const CameraPath path = CameraPath::parse(R"({"keys": [
      {"frame": 1, "eye": [0.1, 1.3, 4.7], "target": [0, 1, 0], "fov": 39.7, "lens_radius": 0.013},
      {"frame": 4, "eye": [1.7, 1.1, 3.9], "focal_distance": 3.3, "max_depth": 5},
      {"frame": 9, "eye": [-2.3, 0.7, 2.1], "up": [0.1, 1, 0], "fov": 61.3, "max_depth": 9},
      {"frame": 13, "target": [0.3, 0.9, -0.2], "lens_radius": 0.071, "focal_distance": 5.9}],
    "turntable": {"frames": 37, "start": 2, "axis": [0, 1, 0.2]}})");
  const auto same = [](const std::optional<Vec3>& a, const std::optional<Vec3>& b) {
    return a.has_value() == b.has_value() &&
           (!a || (std::memcmp(&a->x, &b->x, 4) == 0 && std::memcmp(&a->y, &b->y, 4) == 0 &&
                   std::memcmp(&a->z, &b->z, 4) == 0));
  };
  const auto same_f = [](const std::optional<float>& a, const std::optional<float>& b) {
    return a.has_value() == b.has_value() && (!a || std::memcmp(&*a, &*b, 4) == 0);
  };
  for (int frame = -3; frame <= 20; ++frame) {
    const CameraPath one = CameraPath::parse(path.for_frame(frame).to_json());
    ASSERT_EQ(one.keys.size(), 1u);
    const CameraPath::At a = path.at(frame), b = one.at(frame);
    EXPECT_TRUE(same(a.eye, b.eye) && same(a.target, b.target) && same(a.up, b.up)) << frame;
    EXPECT_TRUE(same_f(a.fov, b.fov) && same_f(a.lens_radius, b.lens_radius) &&
                same_f(a.focal_distance, b.focal_distance))
        << frame;
    EXPECT_EQ(a.max_depth, b.max_depth) << frame;
    EXPECT_EQ(a.orbit, b.orbit);
    EXPECT_EQ(std::memcmp(&a.orbit_angle, &b.orbit_angle, 4), 0) << frame;
    EXPECT_TRUE(same(a.orbit_axis, b.orbit_axis));
  }
  // A turntable alone stays as it is: no key appears.
  const CameraPath orbit = CameraPath::parse(R"({"turntable": {"frames": 12}})");
  EXPECT_TRUE(orbit.for_frame(5).keys.empty());
  EXPECT_EQ(orbit.for_frame(5).to_json(), orbit.to_json());
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a camera path over an animated file camera was checked against the rest
// pose's camera only, so a path target the animated camera reached failed that frame in
// the middle of the sequence (frames written, then "degenerate"). Each frame's camera is
// posed for the check: refused before anything renders, naming the frame.
TEST(CameraPath, AnAnimatedCameraIsCheckedWhereEachFramePosesIt) {
  // The camera (node 1) moves from (0.25, 0.25, 3) to the origin.
  const Scene scene = load_gltf_doc(animated("translation", "LINEAR", {0, 1}, {0.25f, 0.25f, 3, 0, 0, 0}, 1));
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.path =
      std::make_shared<const CameraPath>(CameraPath::parse(R"({"keys": [{"frame": 0, "target": [0, 0, 0]}]})"));
  EXPECT_NO_THROW(TileRenderer::check_settings(scene, s, {0, 12}));
  try {
    TileRenderer::check_settings(scene, s, {0, 12, 24});  // at 24 fps, frame 24 puts the eye on the target
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_NE(std::string(e.what()).find("at frame 24"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera
