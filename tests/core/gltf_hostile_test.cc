// glTF scenes an audit (2026-11-29) found aborting the process inside Embree or rendering
// NaN: an orthographic view wider than the traceable range, an instance scaled nearly flat
// (Embree's object-space rays past its range), a light keyed to scale 0 in an animation
// (no direction: NaN samples, and a crash through the sheen table), directions of nodes
// scaled past float's squares (a light shining nowhere, silently).
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/bsdf/sheen.h"
#include "core/camera/camera.h"
#include "core/math/transform.h"
#include "core/render/settings.h"
#include "core/scene/animation.h"
#include "core/scene/instance.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// A 10 x 10 floor quad, a camera and a spot light; the buffer's last 16 bytes are one
// animation key: time 0, scale (0, 0, 0).
json base() {
  return json::parse(R"({"asset":{"version":"2.0"},"extensionsUsed":["KHR_lights_punctual"],
"extensions":{"KHR_lights_punctual":{"lights":[{"type":"spot","intensity":3000,"spot":{"outerConeAngle":0.6}}]}},
"buffers":[{"byteLength":76,"uri":"data:application/octet-stream;base64,AACgwAAAAAAAAKDAAACgQAAAAAAAAKDAAACgQAAAAAAAAKBAAACgwAAAAAAAAKBAAAACAAEAAAADAAIAAAAAAAAAAAAAAAAAAAAAAA=="}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":12},
{"buffer":0,"byteOffset":60,"byteLength":4},{"buffer":0,"byteOffset":64,"byteLength":12}],
"accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[-5,0,-5],"max":[5,0,5]},
{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"},
{"bufferView":2,"componentType":5126,"count":1,"type":"SCALAR","min":[0],"max":[0]},
{"bufferView":3,"componentType":5126,"count":1,"type":"VEC3"}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"cameras":[{"type":"perspective","perspective":{"yfov":0.8,"znear":0.01}}],
"nodes":[{"mesh":0},{"camera":0,"translation":[0,2,6],"rotation":[-0.2,0,0,0.98]},
 {"translation":[0,3,0],"rotation":[-0.7071,0,0,0.7071],"extensions":{"KHR_lights_punctual":{"light":0}}}],
"scenes":[{"nodes":[0,1,2]}],"scene":0})");
}

class GltfHostile : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_gltf_hostile_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
  Scene load(const json& j) {
    const std::string path = (dir / "s.gltf").string();
    std::ofstream(path) << j.dump();
    return load_scene(path);
  }
  std::string error(const json& j) {
    try {
      load(j);
    } catch (const SceneError& e) {
      return e.what();
    }
    return "";
  }
};

TEST_F(GltfHostile, AnOrthographicViewPastTheTraceableRangeIsRefused) {
  json j = base();
  j["cameras"][0] =
      json::parse(R"({"type":"orthographic","orthographic":{"xmag":1e19,"ymag":1e19,"znear":0,"zfar":100}})");
  EXPECT_NE(error(j).find("orthographic xmag and ymag must be finite, not zero and within +-1e12"), std::string::npos)
      << error(j);
  // And the camera refuses one however it came (another loader, a path).
  Scene s = load(base());
  s.camera.ortho_half_height = 1e19;
  CameraSettings cs;
  cs.framing = Framing::kFile;
  EXPECT_THROW(Camera(s, cs), SettingsError);
}

// An instance whose inverse has entries past 1e5 is copied into world space, not given
// to Embree as an instance (SCALE (1, 1e-18, 1) aborted the process).
TEST_F(GltfHostile, AnInstanceScaledNearlyFlatIsNotAnEmbreeInstance) {
  EXPECT_FALSE(Instance::make(0, Mat4::scale(1, 1e-18, 1)));
  EXPECT_FALSE(Instance::make(0, Mat4::scale(1e-6, 1, 1)));
  EXPECT_TRUE(Instance::make(0, Mat4::scale(1, 1e-4, 1)));
  EXPECT_TRUE(Instance::make(0, Mat4::translate(1e12, 0, 0)));
}

// A light keyed to scale 0: its pose's transform gives no direction (a spot gave NaN
// samples; a directional one crashed through the sheen table, which now reads NaN as 0).
// It was refused; it now keeps its rotation's direction (scale does not affect a light:
// gltf_animation_test.cc), finite and unit.
TEST_F(GltfHostile, ALightKeyedToScaleZeroKeepsAFiniteDirection) {
  json j = base();
  j["animations"] = json::parse(R"([{"samplers":[{"input":2,"output":3}],
    "channels":[{"sampler":0,"target":{"node":2,"path":"scale"}}]}])");
  const Scene s = load(j);  // the rest pose has scale 1
  const Scene posed = pose_scene(s, 0, 0);
  ASSERT_EQ(posed.lights.size(), 1u);
  EXPECT_TRUE(is_finite(posed.lights[0].direction));
  EXPECT_NEAR(length(posed.lights[0].direction), 1, 1e-6);
  EXPECT_EQ(sheen_albedo(NAN, 0.5f), sheen_albedo(0, 0.5f));
  EXPECT_TRUE(std::isfinite(sheen_albedo(0.5f, NAN)));
}

// Directions of nodes scaled by 1e20: float's squared length overflowed, giving (0, 0, 0),
// which passed as finite (a light shining nowhere, a camera refused as degenerate).
TEST_F(GltfHostile, DirectionsOfHugelyScaledNodesStayUnit) {
  json j = base();
  j["nodes"][1]["scale"] = {1e20, 1e20, 1e20};
  j["nodes"][2]["scale"] = {1e20, 1e20, 1e20};
  const Scene s = load(j);
  ASSERT_EQ(s.lights.size(), 1u);
  EXPECT_NEAR(length(s.lights[0].direction), 1, 1e-6);
  EXPECT_NEAR(s.lights[0].direction.y, -1, 1e-3);  // pointing down, as at scale 1
  EXPECT_NEAR(length(s.camera.forward), 1, 1e-6);
  CameraSettings cs;
  cs.framing = Framing::kFile;
  EXPECT_NO_THROW(Camera(s, cs));
}

// The specification forbids animating one (node, path) twice in an animation; a file that
// did so 3,000 times took 52 s a frame. Refused naming both channels.
TEST_F(GltfHostile, ANodesPathAnimatedTwiceIsRefused) {
  json j = base();
  j["animations"] = json::parse(R"([{"samplers":[{"input":2,"output":3}],
    "channels":[{"sampler":0,"target":{"node":0,"path":"scale"}},{"sampler":0,"target":{"node":0,"path":"translation"}},
                {"sampler":0,"target":{"node":0,"path":"scale"}}]}])");
  EXPECT_NE(error(j).find("animations[0].channels[2]: nodes[0]'s scale is animated by channels[0] already"),
            std::string::npos)
      << error(j);
}

// glTF's images are PNG, JPEG and (EXT_texture_webp) WebP. stb decodes more, and its TGA
// reader rendered a truncated file's missing texels from uninitialised memory, different
// each run; anything else is refused naming the image.
TEST_F(GltfHostile, OnlyPngJpegAndWebpTexturesAreDecoded) {
  json j = base();
  j["images"] = {
      {{"uri", "data:image/png;base64,AAACAAAAAAAAAAAAEAAQABgg"}}};  // an 18-byte TGA header, 16 x 16, no texels
  j["textures"] = {{{"source", 0}}};
  j["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}};
  j["meshes"][0]["primitives"][0]["material"] = 0;
  EXPECT_NE(error(j).find("images[0]: not a PNG, JPEG or WebP image"), std::string::npos) << error(j);
}

}  // namespace
}  // namespace tessera
