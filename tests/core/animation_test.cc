// Rendering frames of an animated glTF scene (scenes/cornell-animated.gltf): each frame is
// the scene posed at frame / fps, the same image alone or within a sequence.
#include "core/scene/animation.h"

#include <gtest/gtest.h>

#include "core/accel/accel.h"
#include "core/render/tile_renderer.h"
#include "core/scene/load.h"
#include "tests/core/gltf_fixture.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

TEST(Animation, FramesArePosedAtTheirTimeAndEqualTheFrameRenderedAlone) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-animated.gltf"));
  ASSERT_TRUE(scene.animation);
  ASSERT_EQ(scene.animation->clips.size(), 1u);
  EXPECT_DOUBLE_EQ(scene.animation->clips[0].duration, 2.0);
  // Only the two spheres are kept in object space: the box does not move.
  EXPECT_EQ(scene.animation->meshes.size(), 2u);
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = 24;
  s.camera.height = 18;
  s.spp = 4;
  s.light_tracer = RenderSettings::LightTracer::kOff;  // the path tracer's tiles (light paths: light_tracer_test)
  TileRenderer sequence(scene, s);
  const Rect all{0, 0, 24, 18};
  TileStats st;
  std::vector<float> eye_x;
  for (int frame : {0, 12, 48}) {
    sequence.set_frame(frame);
    eye_x.push_back(sequence.scene().camera.eye.x);
    const auto in_sequence = sequence.render(all, 0, 4, nullptr, &st);
    RenderSettings alone = s;
    alone.frame = frame;
    const auto by_itself = TileRenderer(scene, alone).render(all, 0, 4, nullptr, &st);
    for (size_t i = 0; i < by_itself.size(); ++i) ASSERT_EQ(in_sequence[i].r, by_itself[i].r) << frame;
  }
  EXPECT_EQ(eye_x[0], scene.camera.eye.x);  // t = 0 is the rest pose here
  EXPECT_LT(eye_x[0], eye_x[1]);            // the camera moves
  EXPECT_LT(eye_x[1], eye_x[2]);
  // The frame's time is frame / fps: frame 24 at 24 fps is frame 48 at 48 fps.
  RenderSettings a = s, b = s;
  a.frame = 24;
  b.frame = 48;
  b.fps = 48;
  EXPECT_EQ(TileRenderer(scene, a).scene().meshes[6].positions[0].x,
            TileRenderer(scene, b).scene().meshes[6].positions[0].x);
}

// Only the moving meshes are built per frame; the rest is instanced from one BVH. The image
// is the one a full build of the same pose gives.
TEST(Animation, InstancingTheStaticPartGivesTheImageOfAFullBuild) {
  const Scene scene = load_scene(testing::source_path("scenes/cornell-animated.gltf"));
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = 32;
  s.camera.height = 24;
  s.spp = 8;
  s.light_tracer = RenderSettings::LightTracer::kOff;  // the path tracer's tiles (light paths: light_tracer_test)
  s.frame = 30;
  const TileRenderer instanced(scene, s);
  Scene pose = pose_scene(scene, 0, s.time());
  pose.animation.reset();  // a still of the same geometry: one BVH over everything
  RenderSettings still = s;
  const TileRenderer full(pose, still);
  const Rect all{0, 0, 32, 24};
  TileStats a, b;
  const auto x = instanced.render(all, 0, 8, nullptr, &a), y = full.render(all, 0, 8, nullptr, &b);
  for (size_t i = 0; i < x.size(); ++i) {
    ASSERT_EQ(x[i].r, y[i].r) << i;
    ASSERT_EQ(x[i].b, y[i].b) << i;
  }
  EXPECT_EQ(a.rays.rays, b.rays.rays);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: CS184 framing and a turntable took each frame's posed objects, so the
// camera drifted and zoomed with whatever moved (a static quad slid across the image from
// frame to frame), while the sequence's check took the rest pose's. Both take the rest
// pose's bounds: a triangle moving 5 units leaves the camera where it was.
TEST(Animation, Cs184FramingAndATurntableTakeTheRestPosesBounds) {
  // The triangle moves from where it rests to 5 units along x.
  const Scene scene = load_gltf_doc(animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 5, 0, 0}));
  ASSERT_TRUE(scene.animation);
  for (const bool turntable : {false, true}) {
    RenderSettings s;
    s.camera.width = 16;
    s.camera.height = 12;
    s.camera.framing = turntable ? Framing::kFile : Framing::kCs184;
    if (turntable)
      s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(R"({"turntable": {"frames": 24}})"));
    std::vector<Vec3> eyes;
    for (const int frame : {0, 24}) {  // 24 fps: the rest pose, then 5 units along x
      s.frame = frame;
      const TileRenderer r(scene, s);
      eyes.push_back(r.camera().eye());
    }
    EXPECT_EQ(eyes[0].x, eyes[1].x) << turntable;  // (a whole turn apart: the same place)
    EXPECT_EQ(eyes[0].y, eyes[1].y) << turntable;
    EXPECT_EQ(eyes[0].z, eyes[1].z) << turntable;
  }
}

}  // namespace
}  // namespace tessera
