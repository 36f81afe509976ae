// glTF animation: channels, interpolation, hostile animation data.
#include "tests/core/gltf_fixture.h"

namespace tessera {
namespace {

class GltfAnimation : public Gltf {
 protected:
  // Vertex 1 of the triangle (object space (1, 0, 0)) posed at `time`.
  Vec3 vertex1(const Scene& s, double time) { return pose_scene(s, 0, time).meshes[0].positions[1]; }
};

TEST_F(GltfAnimation, LinearStepAndCubicSplineTranslationFollowTheSpec) {
  const Scene lin = load(animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 2, 0, 0}));
  ASSERT_TRUE(lin.animation);
  EXPECT_EQ(lin.animation->clips.at(0).name, "move");
  EXPECT_FLOAT_EQ(vertex1(lin, 0.5).x, 2);           // 1 + halfway to 2
  EXPECT_FLOAT_EQ(vertex1(lin, -1).x, 1);            // before the first key: the first value
  EXPECT_FLOAT_EQ(vertex1(lin, 7).x, 3);             // after the last: the last
  EXPECT_FLOAT_EQ(lin.meshes[0].positions[1].x, 1);  // the loaded scene keeps its rest pose
  const Scene step = load(animated("translation", "STEP", {0, 1}, {0, 0, 0, 2, 0, 0}));
  EXPECT_FLOAT_EQ(vertex1(step, 0.99).x, 1);
  EXPECT_FLOAT_EQ(vertex1(step, 1).x, 3);
  // CUBICSPLINE keys are (in-tangent, value, out-tangent); with zero tangents the curve is
  // the Hermite smoothstep: at t = 0.25, (3t^2 - 2t^3) x 2 = 0.3125.
  const Scene cubic =
      load(animated("translation", "CUBICSPLINE", {0, 1}, {0, 0, 0, 0, 0, 0, 0, 0, 0, /**/ 0, 0, 0, 2, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(vertex1(cubic, 0.25).x, 1.3125, 1e-6);
  EXPECT_NEAR(vertex1(cubic, 0.5).x, 2, 1e-6);
  // Tangents count: an out-tangent of 4 units/s at key 0 lifts the start (td = 1).
  const Scene tangent =
      load(animated("translation", "CUBICSPLINE", {0, 1}, {0, 0, 0, 0, 0, 0, 4, 0, 0, /**/ 0, 0, 0, 2, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(vertex1(tangent, 0.25).x, 1 + 0.3125 + 4 * (0.015625 - 2 * 0.0625 + 0.25), 1e-6);
}

TEST_F(GltfAnimation, RotationsSlerpTheShortWayAndScaleSteps) {
  const float h = float(std::sqrt(0.5));
  // Identity to 90 degrees about +Z; halfway is 45 degrees: (1, 0, 0) -> (cos 45, sin 45, 0).
  const Scene r = load(animated("rotation", "LINEAR", {0, 2}, {0, 0, 0, 1, 0, 0, h, h}));
  Vec3 v = vertex1(r, 1);
  EXPECT_NEAR(v.x, h, 1e-6);
  EXPECT_NEAR(v.y, h, 1e-6);
  // The same end given as -q (the same rotation): still the 45-degree halfway, not 135.
  const Scene neg = load(animated("rotation", "LINEAR", {0, 2}, {0, 0, 0, 1, 0, 0, -h, -h}));
  v = vertex1(neg, 1);
  EXPECT_NEAR(v.x, h, 1e-6);
  EXPECT_NEAR(v.y, h, 1e-6);
  const Scene s = load(animated("scale", "STEP", {0, 1}, {1, 1, 1, 3, 3, 3}));
  EXPECT_FLOAT_EQ(vertex1(s, 0.5).x, 1);
  EXPECT_FLOAT_EQ(vertex1(s, 1.5).x, 3);
  // A mirroring scale keeps the geometric normal outward: the winding flips with it.
  const Scene m = load(animated("scale", "STEP", {0, 1}, {1, 1, 1, -1, 1, 1}));
  EXPECT_EQ(pose_scene(m, 0, 0).meshes[0].indices, m.meshes[0].indices);
  EXPECT_NE(pose_scene(m, 0, 1).meshes[0].indices, m.meshes[0].indices);
}

TEST_F(GltfAnimation, TheCameraNodeMovesAndAnimationsArePickedByNameOrIndex) {
  Doc d = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 2, 0, 0});
  const int in = add_floats(d, {0, 4}, "SCALAR");
  const int out = add_floats(d, {0.25f, 0.25f, 3, 0.25f, 0.25f, 7}, "VEC3");
  const json channel = {{"sampler", 0}, {"target", {{"node", 1}, {"path", "translation"}}}};
  const json sampler = {{"input", in}, {"output", out}};
  d.j["animations"].push_back(
      {{"name", "dolly"}, {"channels", json::array({channel})}, {"samplers", json::array({sampler})}});
  const Scene s = load(d);
  EXPECT_EQ(s.animation->find_clip(""), 0u);
  EXPECT_EQ(s.animation->find_clip("dolly"), 1u);
  EXPECT_EQ(s.animation->find_clip("1"), 1u);
  try {
    s.animation->find_clip("walk");
    ADD_FAILURE() << "found";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("0 'move', 1 'dolly'"), std::string::npos) << e.what();
  }
  EXPECT_FLOAT_EQ(pose_scene(s, 1, 2).camera.eye.z, 5);
  EXPECT_FLOAT_EQ(pose_scene(s, 0, 2).camera.eye.z, 3);  // "move" leaves the camera be
  EXPECT_FLOAT_EQ(pose_scene(s, 1, 2).meshes[0].positions[1].x, 1);
}

TEST_F(GltfAnimation, AStillSceneCarriesNoAnimation) { EXPECT_FALSE(load(Doc()).animation); }

TEST_F(GltfAnimation, HostileAnimationDataIsRefusedNamingTheElement) {
  expect_error(animated("translation", "LINEAR", {0, 1, 1}, {0, 0, 0, 1, 0, 0, 2, 0, 0}),
               "animations[0].samplers[0]: input times must increase: key 2");
  expect_error(animated("translation", "LINEAR", {1, 0}, {0, 0, 0, 1, 0, 0}), "input times must increase");
  expect_error(animated("translation", "LINEAR", {0, 1}, {0, 0, 0}), "output has 1 elements for 2 input keys");
  expect_error(animated("translation", "CUBICSPLINE", {0, 1}, {0, 0, 0, 1, 0, 0}),
               "output has 2 elements for 2 input keys; CUBICSPLINE needs 6");
  expect_error(animated("translation", "LINEAR", {0, std::nanf("")}, {0, 0, 0, 1, 0, 0}),
               "contains a NaN or infinite value");
  expect_error(animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1, std::numeric_limits<float>::infinity(), 0}),
               "contains a NaN or infinite value");
  expect_error(animated("translation", "BEZIER", {0, 1}, {0, 0, 0, 1, 0, 0}), "unknown interpolation 'BEZIER'");
  expect_error(animated("position", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0}), "unknown target path 'position'");
  expect_error(animated("rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0}), "output has 1 elements for 2 input keys");
  Doc nowhere = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0});
  nowhere.j["animations"][0]["channels"][0]["sampler"] = 5;
  expect_error(nowhere, "animations[0].channels[0]: sampler 5 does not exist");
  Doc no_node = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0});
  no_node.j["animations"][0]["channels"][0]["target"]["node"] = 9;
  expect_error(no_node, "target node 9 does not exist");
  Doc no_input = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0});
  no_input.j["animations"][0]["samplers"][0]["input"] = 40;
  expect_error(no_input, "accessor 40 does not exist");
  Doc matrix = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0});
  matrix.j["nodes"][0]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  expect_error(matrix, "which has a matrix");
  // A pose beyond the traceable range is refused when posed, naming the animation.
  const Scene far = load(animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 1e13f, 0, 0}));
  EXPECT_THROW(pose_scene(far, 0, 1), SceneError);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a spot or directional light scaled to zero (a common way to hide one;
// glTF says scale does not affect a light) had no direction: a file whose light rests at
// scale 0 was refused, and one animated to 0 failed its sequence midway. Its direction is
// its node's rotation then. Node 2 holds a spot light (turned 90 degrees about x: aimed at
// +y) under node 3, which the clip scales from 1 to 0 (or 0 to 1).
TEST_F(GltfAnimation, ALightScaledToZeroKeepsItsRotationsDirection) {
  for (const bool from_zero : {false, true}) {
    Doc d = animated("scale", "LINEAR", {0, 1},
                     from_zero ? std::vector<float>{0, 0, 0, 1, 1, 1} : std::vector<float>{1, 1, 1, 0, 0, 0}, 3);
    d.j["extensionsUsed"] = {"KHR_lights_punctual"};
    d.j["extensions"]["KHR_lights_punctual"]["lights"] = {
        {{"type", "spot"}, {"intensity", 68.3}, {"spot", {{"innerConeAngle", 0.2}, {"outerConeAngle", 0.4}}}}};
    const double h = std::sqrt(0.5);
    d.j["nodes"].push_back({{"rotation", {h, 0, 0, h}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    d.j["nodes"].push_back(
        {{"children", {2}}, {"translation", {0, 1, 0}}, {"scale", from_zero ? json{0, 0, 0} : json{1, 1, 1}}});
    d.j["scenes"][0]["nodes"] = {0, 1, 3};
    const Scene s = load(d);
    ASSERT_EQ(s.lights.size(), 1u);
    for (const double time : {0.0, 0.5, 1.0}) {
      const Vec3 aim = pose_scene(s, 0, time).lights[0].direction;
      EXPECT_NEAR(aim.x, 0, 1e-6) << time;
      EXPECT_NEAR(aim.y, 1, 1e-6) << time;
      EXPECT_NEAR(aim.z, 0, 1e-6) << time;
    }
  }
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: an animated node's single EXT_mesh_gpu_instancing instance lost its
// transform in every posed frame (only several instances were baked into the mesh's object
// space): the triangle at x + 2 at rest sat at x + 0 in frame 0.
TEST_F(GltfAnimation, AnAnimatedNodesSingleInstanceKeepsItsTransform) {
  Doc d = animated("translation", "LINEAR", {0, 1}, {0, 0, 0, 0, 1, 0});
  const int shift = add_floats(d, {2, 0, 0}, "VEC3");
  d.j["nodes"][0]["extensions"] = {{"EXT_mesh_gpu_instancing", {{"attributes", {{"TRANSLATION", shift}}}}}};
  d.j["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
  const Scene s = load(d);
  EXPECT_FLOAT_EQ(s.meshes[0].positions[1].x, 3);  // the rest pose: (1, 0, 0) + (2, 0, 0)
  EXPECT_FLOAT_EQ(vertex1(s, 0).x, 3);
  EXPECT_FLOAT_EQ(vertex1(s, 1).x, 3);
  EXPECT_FLOAT_EQ(vertex1(s, 1).y, 1);
}

}  // namespace
}  // namespace tessera
