// The glTF loader: what it makes of valid files, and a clear error (never a crash or a
// huge allocation) for hostile ones.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "core/scene/animation.h"
#include "core/scene/gltf/gltf_accessors.h"
#include "core/scene/gltf/gltf_document.h"
#include "core/scene/gltf/gltf_loader.h"
#include "core/scene/gltf/gltf_prechecks.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

std::string base64(const std::string& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int val = 0, bits = -6;
  for (unsigned char c : in) {
    val = (val << 8) + c;
    bits += 8;
    while (bits >= 0) {
      out.push_back(t[(val >> bits) & 0x3F]);
      bits -= 6;
    }
  }
  if (bits > -6) out.push_back(t[((val << 8) >> (bits + 8)) & 0x3F]);
  while (out.size() % 4) out.push_back('=');
  return out;
}

template <typename T>
void put(std::string& blob, std::initializer_list<T> values) {
  for (T v : values) blob.append(reinterpret_cast<const char*>(&v), sizeof v);
}

// One triangle (positions, normals, uvs, ushort indices) in a buffer, a node, a camera.
struct Doc {
  json j;
  std::string blob;
  Doc() {
    put<float>(blob, {0, 0, 0, 1, 0, 0, 0, 1, 0});     // positions, 36 bytes at 0
    put<float>(blob, {0, 0, 1, 0, 0, 1, 0, 0, 1});     // normals, 36 bytes at 36
    put<uint8_t>(blob, {0, 0, 255, 0, 0, 255, 0, 0});  // normalized ubyte uvs, 6 bytes (+2 pad) at 72
    put<uint16_t>(blob, {0, 1, 2, 0});                 // indices, 6 bytes (+2 pad) at 80
    j = {{"asset", {{"version", "2.0"}}},
         {"scene", 0},
         {"scenes", {{{"nodes", {0, 1}}}}},
         {"nodes", {{{"mesh", 0}}, {{"camera", 0}, {"translation", {0.25, 0.25, 3}}}}},
         {"cameras", {{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}}}}}},
         {"meshes",
          {{{"primitives",
             {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}, {"TEXCOORD_0", 2}}},
               {"indices", 3},
               {"material", 0}}}}}}},
         {"materials", {{{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.6, 0.7, 1}}, {"metallicFactor", 0}}}}}},
         {"accessors",
          {{{"bufferView", 0}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
           {{"bufferView", 1}, {"componentType", 5126}, {"count", 3}, {"type", "VEC3"}},
           {{"bufferView", 2}, {"componentType", 5121}, {"normalized", true}, {"count", 3}, {"type", "VEC2"}},
           {{"bufferView", 3}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}}},
         {"bufferViews",
          {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 36}},
           {{"buffer", 0}, {"byteOffset", 36}, {"byteLength", 36}},
           {{"buffer", 0}, {"byteOffset", 72}, {"byteLength", 6}},
           {{"buffer", 0}, {"byteOffset", 80}, {"byteLength", 6}}}},
         {"buffers", {{{"byteLength", 88}}}}};
  }
  void embed() { j["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64(blob); }
};

class Gltf : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_gltf_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
  std::string write(const std::string& name, const std::string& content) {
    const fs::path p = dir / name;
    std::ofstream(p, std::ios::binary) << content;
    return p.string();
  }
  std::string write(Doc d, bool embed = true) {
    if (embed) d.embed();
    return write("scene.gltf", d.j.dump());
  }
  Scene load(Doc d) { return load_gltf_file(write(std::move(d))); }
  void expect_error(const std::string& path, const std::string& reason) {
    try {
      load_scene(path);
      ADD_FAILURE() << "loaded without error; expected: " << reason;
    } catch (const SceneError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(fs::path(path).filename().string()), std::string::npos) << what;
      EXPECT_NE(what.find(reason), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << "one line: " << what;
    }
  }
  void expect_error(Doc d, const std::string& reason) { expect_error(write(std::move(d)), reason); }
};

// Issue 10, row 1: coordinates the ray tracer cannot handle are refused on load, whether
// in the vertices or through a node's transform.
TEST_F(Gltf, GeometryBeyondTheTraceableRangeIsRefused) {
  Doc far;
  far.blob.replace(0, 12, std::string(12, '\0'));
  const float big = 3e12f;
  std::memcpy(far.blob.data() + 12, &big, 4);  // vertex 1 at x = 3e12
  expect_error(far, "vertex 1 (3e+12, 0, 0) is not finite or outside +-1e12");
  Doc moved;
  moved.j["nodes"][0]["translation"] = {0, 5e12, 0};
  expect_error(moved, "outside +-1e12");
}

TEST_F(Gltf, EmbeddedBuffersNormalsUvsAndIndices) {
  const Scene s = load(Doc());
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  EXPECT_EQ(m.triangle_count(), 1u);
  EXPECT_TRUE(m.file_normals);
  EXPECT_FLOAT_EQ(m.normals[0].z, 1);
  ASSERT_EQ(m.uvs.size(), 3u);
  EXPECT_FLOAT_EQ(m.uvs[1].x, 1);  // normalized ubyte 255 -> 1
  EXPECT_EQ(s.materials[m.material].kind, Material::Kind::kPbr);
  EXPECT_FLOAT_EQ(s.materials[m.material].reflectance.b, 0.7f);
  ASSERT_TRUE(s.camera.present);
  EXPECT_NEAR(*s.camera.yfov_deg, 0.5 * 180 / M_PI, 1e-9);
  EXPECT_FLOAT_EQ(s.camera.eye.z, 3);
}

TEST_F(Gltf, ExternalBufferAndGlb) {
  Doc d;
  d.j["buffers"][0]["uri"] = "tri.bin";
  write("tri.bin", d.blob);
  EXPECT_EQ(load_gltf_file(write(d, false)).triangle_count(), 1u);
  // The same as a .glb: header, JSON chunk, BIN chunk.
  Doc g;
  g.j["buffers"][0].erase("uri");
  std::string js = g.j.dump();
  while (js.size() % 4) js.push_back(' ');
  std::string bin = g.blob;
  std::string glb = "glTF";
  put<uint32_t>(glb, {2, uint32_t(12 + 8 + js.size() + 8 + bin.size()), uint32_t(js.size()), 0x4E4F534Au});
  glb += js;
  put<uint32_t>(glb, {uint32_t(bin.size()), 0x004E4942u});
  glb += bin;
  EXPECT_EQ(load_scene(write("tri.glb", glb)).triangle_count(), 1u);
}

TEST_F(Gltf, NodeTransformsMatrixAndTrs) {
  Doc d;
  d.j["nodes"][0]["translation"] = {1, 2, 3};
  d.j["nodes"][0]["rotation"] = {0, 0, 0.7071068, 0.7071068};  // 90 degrees about z
  d.j["nodes"][0]["scale"] = {2, 2, 2};
  const Scene a = load(d);
  // Vertex (1,0,0): scale -> (2,0,0), rotate -> (0,2,0), translate -> (1,4,3).
  EXPECT_NEAR(a.meshes[0].positions[1].x, 1, 1e-5);
  EXPECT_NEAR(a.meshes[0].positions[1].y, 4, 1e-5);
  EXPECT_NEAR(a.meshes[0].normals[0].z, 1, 1e-5);
  Doc m;
  m.j["nodes"][0]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 6, 7, 1};  // column-major translation
  EXPECT_NEAR(load(m).meshes[0].positions[0].x, 5, 1e-6);
  Doc mirror;  // a negative scale keeps the winding outward: normals stay consistent
  mirror.j["nodes"][0]["scale"] = {-1, 1, 1};
  const Scene ms = load(mirror);
  const Mesh& mm = ms.meshes[0];
  const Vec3 ng = cross(mm.positions[mm.indices[1]] - mm.positions[mm.indices[0]],
                        mm.positions[mm.indices[2]] - mm.positions[mm.indices[0]]);
  EXPECT_GT(ng.z, 0);
}

TEST_F(Gltf, NonIndexedSparseAndOtherComponentTypes) {
  Doc d;
  d.j["meshes"][0]["primitives"][0].erase("indices");
  // Sparse: replace vertex 2's position with (0, 5, 0).
  put<uint8_t>(d.blob, {2, 0, 0, 0});  // sparse index (ubyte) at 88
  put<float>(d.blob, {0, 5, 0});       // sparse value at 92
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 88}, {"byteLength", 1}});
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 92}, {"byteLength", 12}});
  d.j["buffers"][0]["byteLength"] = 104;
  d.j["accessors"][0]["sparse"] = {
      {"count", 1}, {"indices", {{"bufferView", 4}, {"componentType", 5121}}}, {"values", {{"bufferView", 5}}}};
  const Scene s = load(d);
  EXPECT_EQ(s.meshes[0].indices, (std::vector<uint32_t>{0, 1, 2}));
  EXPECT_FLOAT_EQ(s.meshes[0].positions[2].y, 5);
}

TEST_F(Gltf, MaterialMapping) {
  Doc d;
  auto mat = [&](json m) {
    d.j["materials"][0] = m;
    return load(d);
  };
  const auto of = [](const Scene& s) { return s.materials[s.meshes[0].material]; };
  // Every glTF material is the metallic-roughness model, its parameters continuous.
  Scene s = mat({{"pbrMetallicRoughness",
                  {{"baseColorFactor", {1, 0.8, 0.4, 1}}, {"metallicFactor", 1}, {"roughnessFactor", 0}}}});
  EXPECT_EQ(of(s).kind, Material::Kind::kPbr);
  EXPECT_FLOAT_EQ(of(s).reflectance.b, 0.4f);
  EXPECT_TRUE(of(s).is_delta());  // a smooth metal: a mirror
  s = mat({{"pbrMetallicRoughness", {{"metallicFactor", 0.3}, {"roughnessFactor", 0.5}}}});
  EXPECT_FLOAT_EQ(of(s).metallic, 0.3f);
  EXPECT_FLOAT_EQ(of(s).alpha, 0.25f);  // roughness^2
  EXPECT_FALSE(of(s).is_delta());
  EXPECT_FALSE(of(s).is_dielectric());
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("metallic"), std::string::npos) << w;  // no rounding
  // Transmission alone is thin-walled (the extension's definition); with a volume of some
  // thickness a refracting solid, absorbing -ln(colour) / distance per unit length.
  s = mat({{"pbrMetallicRoughness", {{"metallicFactor", 0}, {"roughnessFactor", 0.2}}},
           {"extensions",
            {{"KHR_materials_transmission", {{"transmissionFactor", 1}}}, {"KHR_materials_ior", {{"ior", 1.33}}}}}});
  EXPECT_FLOAT_EQ(of(s).transmission, 1);
  EXPECT_FLOAT_EQ(of(s).ior, 1.33f);
  EXPECT_TRUE(of(s).thin);
  EXPECT_TRUE(of(s).is_dielectric());
  s = mat({{"pbrMetallicRoughness", {{"metallicFactor", 0}}},
           {"extensions",
            {{"KHR_materials_transmission", {{"transmissionFactor", 1}}},
             {"KHR_materials_volume",
              {{"thicknessFactor", 0.1}, {"attenuationColor", {0.5, 1, 1}}, {"attenuationDistance", 2}}}}}});
  EXPECT_FALSE(of(s).thin);
  EXPECT_NEAR(of(s).absorption.r, std::log(2.0) / 2, 1e-6);
  EXPECT_FLOAT_EQ(of(s).absorption.g, 0);
  s = mat({{"emissiveFactor", {1, 0.5, 0.25}},
           {"doubleSided", true},
           {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 8}}}}}});
  ASSERT_EQ(of(s).kind, Material::Kind::kEmission);
  EXPECT_FLOAT_EQ(of(s).radiance.g, 4);
  ASSERT_EQ(s.lights.size(), 1u);  // emitters are sampled as area lights
  EXPECT_EQ(s.lights[0].kind, Light::Kind::kMesh);
  EXPECT_TRUE(s.lights[0].two_sided);
  // No material: the spec's default, metallic 1 and roughness 1.
  d.j["meshes"][0]["primitives"][0].erase("material");
  s = load(d);
  EXPECT_FLOAT_EQ(of(s).metallic, 1);
  EXPECT_FLOAT_EQ(of(s).alpha, 1);
}

TEST_F(Gltf, MaterialValuesOutOfTheirRangeAreRefusedByName) {
  auto with = [](json m) {
    Doc d;
    d.j["materials"][0] = m;
    return d;
  };
  expect_error(with({{"pbrMetallicRoughness", {{"metallicFactor", 1.5}}}}),
               "materials[0]: metallicFactor 1.500000 is outside [0, 1]");
  expect_error(with({{"pbrMetallicRoughness", {{"baseColorFactor", {1, -2, 0, 1}}}}}),
               "baseColorFactor component -2.000000 is out of range");
  expect_error(with({{"extensions", {{"KHR_materials_ior", {{"ior", 0.5}}}}}}), "ior 0.500000 out of range [1, 10)");
  expect_error(with({{"extensions", {{"KHR_materials_transmission", {{"transmissionFactor", "all"}}}}}}),
               "KHR_materials_transmission.transmissionFactor is not a number");
  expect_error(with({{"extensions", {{"KHR_materials_volume", {{"attenuationDistance", 0}}}}}}),
               "attenuationDistance must be positive");
  expect_error(with({{"extensions", {{"KHR_materials_volume", {{"thicknessFactor", -1}}}}}}),
               "thicknessFactor is negative");
  expect_error(with({{"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", -3}}}}}}),
               "emissiveStrength is negative");
}

// A 2x1 PNG: red, then blue (sRGB 255 -> linear 1).
const unsigned char kRedBluePng[] = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00,
    0x00, 0x02, 0x00, 0x00, 0x00, 0x01, 0x08, 0x02, 0x00, 0x00, 0x00, 0x7b, 0x40, 0xe8, 0xdd, 0x00, 0x00, 0x00,
    0x0d, 0x49, 0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0xf8, 0xcf, 0x00, 0x04, 0xff, 0x01, 0x07, 0x00, 0x01, 0xff,
    0xe2, 0x23, 0x9e, 0x59, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};

std::string red_blue_png_uri() {
  return "data:image/png;base64," + base64(std::string(reinterpret_cast<const char*>(kRedBluePng), sizeof kRedBluePng));
}

TEST_F(Gltf, BaseColourTextureWithSamplerWrapModes) {
  Doc d;
  d.j["images"] = {{{"uri", red_blue_png_uri()}}};
  d.j["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33648}}};  // clamp, mirrored
  d.j["textures"] = {{{"source", 0}, {"sampler", 0}}};
  d.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
  const Scene s = load(d);
  ASSERT_EQ(s.textures.size(), 1u);
  const Texture& t = s.textures[0];
  EXPECT_EQ(t.wrap_s, Texture::Wrap::kClamp);
  EXPECT_EQ(t.wrap_t, Texture::Wrap::kMirror);
  EXPECT_EQ(s.materials[s.meshes[0].material].texture.index, 0);
  EXPECT_NEAR(t.sample({0.25f, 0.5f}).r, 1, 1e-6);  // texel centre of the red texel
  EXPECT_NEAR(t.sample({0.75f, 0.5f}).b, 1, 1e-6);
  EXPECT_NEAR(t.sample({7.0f, 0.5f}).b, 1, 1e-6);   // clamped to the right edge
  EXPECT_NEAR(t.sample({-3.0f, 0.5f}).r, 1, 1e-6);  // clamped to the left edge
}

TEST_F(Gltf, MetallicRoughnessNormalAndEmissiveTexturesWithTextureTransform) {
  Doc d;
  d.j["images"] = {{{"uri", red_blue_png_uri()}}};
  d.j["textures"] = {{{"source", 0}}};
  json& m = d.j["materials"][0];
  m["pbrMetallicRoughness"]["metallicFactor"] = 0.8;
  m["pbrMetallicRoughness"]["roughnessFactor"] = 0.5;
  m["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 0;
  json& mr = m["pbrMetallicRoughness"]["metallicRoughnessTexture"];
  mr["index"] = 0;
  mr["extensions"]["KHR_texture_transform"] = {{"offset", {0.5, 0}}, {"scale", {2, 1}}, {"rotation", 0}};
  m["normalTexture"] = {{"index", 0}, {"scale", 0.5}};
  const Scene s = load(d);
  // One image, decoded twice: sRGB for colour, linear for data.
  ASSERT_EQ(s.textures.size(), 2u);
  const Material& mat = s.materials[s.meshes[0].material];
  EXPECT_NE(mat.texture.index, mat.metal_rough_texture.index);
  EXPECT_EQ(mat.metal_rough_texture.index, mat.normal_texture.index);
  EXPECT_FLOAT_EQ(mat.normal_scale, 0.5f);
  EXPECT_FLOAT_EQ(mat.metal_rough_texture.xform[0], 2);  // u' = 2 u + 0.5
  EXPECT_FLOAT_EQ(mat.metal_rough_texture.xform[2], 0.5f);
  // At u = 0: the transform reads u' = 0.5, between the texels; at u = 0.125, u' = 0.75,
  // the blue texel: G = 0 (roughness 0), B = 1 (metallic = the factor).
  const Material at_blue = s.textured(mat, {0.125f, 0.5f});
  EXPECT_NEAR(at_blue.metallic, 0.8f, 1e-6);
  EXPECT_NEAR(at_blue.roughness, 0, 1e-6);
  EXPECT_NEAR(at_blue.alpha, 0, 1e-6);
  // The base colour texture has no transform: read at u = 0.125 itself.
  EXPECT_NEAR(at_blue.reflectance.r, mat.reflectance.r * s.textures[size_t(mat.texture.index)].sample({0.125f, 0.5f}).r,
              1e-6);
  // An emissive texture multiplies the emissive factor.
  Doc e;
  e.j["images"] = {{{"uri", red_blue_png_uri()}}};
  e.j["textures"] = {{{"source", 0}}};
  e.j["materials"][0] = {{"emissiveFactor", {1, 1, 1}}, {"emissiveTexture", {{"index", 0}}}};
  const Scene se = load(e);
  const Material& em = se.materials[se.meshes[0].material];
  ASSERT_EQ(em.kind, Material::Kind::kEmission);
  EXPECT_NEAR(se.textured(em, {0.75f, 0.5f}).radiance.b, 1, 1e-6);
  EXPECT_NEAR(se.textured(em, {0.75f, 0.5f}).radiance.r, 0, 1e-6);
  // A malformed transform that is used is refused by name.
  m["pbrMetallicRoughness"]["metallicRoughnessTexture"]["extensions"]["KHR_texture_transform"]["offset"] = {1};
  expect_error(d, "metallicRoughnessTexture KHR_texture_transform.offset is not two numbers");
}

TEST(TextureWrap, RepeatMirrorAndClamp) {
  Texture t;
  t.width = 4;
  t.height = 1;
  t.texels = {Rgb(0), Rgb(1), Rgb(2), Rgb(3)};
  auto at = [&](float u) { return t.sample({u, 0.5f}).r; };
  EXPECT_FLOAT_EQ(at(0.125f), 0);
  EXPECT_FLOAT_EQ(at(1.125f), 0);  // repeat
  EXPECT_FLOAT_EQ(at(0.875f), 3);
  t.wrap_s = Texture::Wrap::kMirror;
  EXPECT_FLOAT_EQ(at(1.125f), 3);  // mirrored: the first texel past 1 is the last one
  t.wrap_s = Texture::Wrap::kClamp;
  EXPECT_FLOAT_EQ(at(5.0f), 3);
}

TEST_F(Gltf, PunctualLightsInRadiometricUnits) {
  Doc d;
  d.j["extensionsUsed"] = {"KHR_lights_punctual"};
  d.j["extensions"]["KHR_lights_punctual"]["lights"] = {
      {{"type", "point"}, {"intensity", 683}, {"color", {1, 0.5, 1}}},
      {{"type", "directional"}, {"intensity", 1366}},
      {{"type", "spot"}, {"intensity", 68.3}, {"spot", {{"innerConeAngle", 0.2}, {"outerConeAngle", 0.4}}}}};
  for (int i = 0; i < 3; ++i)
    d.j["nodes"].push_back({{"translation", {0, 2, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", i}}}}}});
  d.j["scenes"][0]["nodes"] = {0, 1, 2, 3, 4};
  const Scene s = load(d);
  ASSERT_EQ(s.lights.size(), 3u);
  EXPECT_EQ(s.lights[0].kind, Light::Kind::kPoint);
  EXPECT_FLOAT_EQ(s.lights[0].color.r, 1);  // 683 cd = 1 W/sr
  EXPECT_FLOAT_EQ(s.lights[0].color.g, 0.5f);
  EXPECT_FLOAT_EQ(s.lights[0].att_quadratic, 1);
  EXPECT_EQ(s.lights[1].kind, Light::Kind::kDirectional);
  EXPECT_FLOAT_EQ(s.lights[1].color.r, 2);        // 1366 lux = 2 W/m^2
  EXPECT_NEAR(s.lights[1].direction.z, 1, 1e-6);  // shines down -z: the light is toward +z
  EXPECT_EQ(s.lights[2].kind, Light::Kind::kSpot);
  EXPECT_FLOAT_EQ(s.lights[2].cos_outer, std::cos(0.4f));
}

TEST_F(Gltf, NoCameraFramesTheBounds) {
  Doc d;
  d.j["scenes"][0]["nodes"] = {0};
  const Scene s = load(d);
  ASSERT_TRUE(s.camera.present);
  EXPECT_GT(s.camera.eye.z, 1);
  bool warned = false;
  for (const std::string& w : s.warnings) warned |= w.find("no camera") != std::string::npos;
  EXPECT_TRUE(warned);
  EXPECT_TRUE(s.unlit);
  EXPECT_NE(s.warnings.front().find("no lights"), std::string::npos) << s.warnings.front();
}

TEST_F(Gltf, OptionalUnsupportedExtensionIsAWarningOnce) {
  Doc d;
  d.j["extensionsUsed"] = {"KHR_materials_clearcoat", "KHR_materials_clearcoat"};
  const Scene s = load(d);
  int n = 0;
  for (const auto& w : s.warnings) n += w.find("'KHR_materials_clearcoat' is not supported") != std::string::npos;
  EXPECT_GE(n, 1);
}

// ---- refused, with a clear message ---------------------------------------------------

TEST_F(Gltf, RequiredUnsupportedExtensionIsRefusedByName) {
  Doc d;
  d.j["extensionsUsed"] = {"KHR_draco_mesh_compression"};
  d.j["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  expect_error(d, "required extension 'KHR_draco_mesh_compression' is not supported");
}

TEST_F(Gltf, NonTriangleModeIsRefused) {
  Doc d;
  d.j["meshes"][0]["primitives"][0]["mode"] = 1;
  expect_error(d, "mode LINES is not supported (only TRIANGLES)");
}

TEST_F(Gltf, OrthographicCameraIsRefused) {
  Doc d;
  d.j["cameras"][0] = {{"type", "orthographic"},
                       {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"znear", 0.1}, {"zfar", 10}}}};
  expect_error(d, "orthographic cameras are not supported");
}

TEST_F(Gltf, AccessorOffsetPastTheBufferView) {
  Doc d;
  d.j["accessors"][0]["byteOffset"] = 8;
  expect_error(d, "runs past the end of bufferView 0");
}

TEST_F(Gltf, BufferViewPastTheBuffer) {
  Doc d;
  d.j["bufferViews"][1]["byteLength"] = 4000;
  expect_error(d, "runs past the end of its buffer");
}

TEST_F(Gltf, IndexOutOfRange) {
  Doc d;
  std::memcpy(d.blob.data() + 82, "\x09\x00", 2);  // second index = 9 with 3 vertices
  expect_error(d, "index 9 out of range (3 vertices)");
}

TEST_F(Gltf, BufferShorterThanDeclared) {
  Doc d;
  d.j["buffers"][0]["uri"] = "short.bin";
  write("short.bin", d.blob.substr(0, 40));
  expect_error(write(d, false), "short.bin");
}

// Found by fuzz_gltf: a number too large for a double (1e999) made the JSON parser throw
// an exception the loader did not expect, and the process ended.
TEST_F(Gltf, NumberBeyondADoubleIsAnError) {
  expect_error(write("scene.gltf", R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"x":1e999})"), "JSON");
}

// Tolerant where viewers and the course's renderer are: data nothing uses is never read, so
// a malformed unused accessor is a warning and a broken unused image nothing at all; the
// same data in use is still the one-line error.
TEST_F(Gltf, MalformedDataNothingUsesIsToleratedAndInUseRefused) {
  Doc d;
  d.j["accessors"].push_back({{"count", "many"}, {"type", "VEC3"}});  // no componentType, count not a number
  const size_t bad = d.j["accessors"].size() - 1;
  d.j["images"] = {{{"uri", "data:image/png;base64,bm90IGFuIGltYWdl"}}};  // "not an image"
  d.j["textures"] = {{{"source", 0}}};
  const Scene s = load(d);
  EXPECT_EQ(s.meshes.size(), 1u);
  bool warned = false;
  for (const std::string& w : s.warnings)
    warned |= w.find("accessors[" + std::to_string(bad) + "] has no valid componentType; nothing uses it: ignored") !=
              std::string::npos;
  EXPECT_TRUE(warned);
  // The same image used by a material: refused, naming it.
  Doc used = d;
  used.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
  expect_error(used, "images[0]: not a readable PNG or JPEG");
  // The same accessor used as indices: refused (by tinygltf's parser).
  Doc idx = d;
  idx.j["meshes"][0]["primitives"][0]["indices"] = bad;
  std::string error;
  try {
    load(idx);
  } catch (const SceneError& e) {
    error = e.what();
  }
  EXPECT_FALSE(error.empty()) << "a malformed accessor in use loaded";
  // In a .glb too: the JSON chunk is rewritten around the unused accessor.
  Doc glb = d;
  glb.j["buffers"][0].erase("uri");
  std::string json = glb.j.dump();
  while (json.size() % 4) json += ' ';
  std::string bin = glb.blob;
  while (bin.size() % 4) bin += '\0';
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  const std::string file = "glTF" + u32(2) + u32(uint32_t(12 + 8 + json.size() + 8 + bin.size())) +
                           u32(uint32_t(json.size())) + "JSON" + json + u32(uint32_t(bin.size())) + "BIN" +
                           std::string(1, '\0') + bin;
  const Scene g = load_gltf_file(write("scene.glb", file));
  EXPECT_EQ(g.meshes.size(), 1u);
}

TEST_F(Gltf, BrokenBase64) {
  Doc d;
  d.embed();
  std::string uri = d.j["buffers"][0]["uri"];
  uri.replace(uri.size() - 20, 10, "!!**??%%^^");
  d.j["buffers"][0]["uri"] = uri;
  try {
    load_gltf_file(write("scene.gltf", d.j.dump()));
    ADD_FAILURE() << "broken base64 loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("scene.gltf"), std::string::npos) << e.what();
  }
}

TEST_F(Gltf, TenGigabyteByteLengthIsRefusedBeforeAllocating) {
  Doc d;
  d.j["buffers"][0]["byteLength"] = 10737418240.0;
  expect_error(d, "byteLength 10737418240 is over the 1 GiB limit");
}

TEST_F(Gltf, CyclicNodeGraph) {
  Doc d;
  d.j["nodes"][0]["children"] = {2};
  d.j["nodes"].push_back({{"children", {0}}});
  expect_error(d, "the node graph has a cycle");
}

TEST_F(Gltf, SelfParentNode) {
  Doc d;
  d.j["nodes"][0]["children"] = {0};
  expect_error(d, "nodes[0]: the node graph has a cycle");
}

TEST_F(Gltf, UriOutsideTheScenesFolderIsRefused) {
  Doc d;
  write("secret.bin", d.blob);
  fs::create_directories(dir / "sub");
  d.j["buffers"][0]["uri"] = "../secret.bin";
  const std::string path = (dir / "sub" / "scene.gltf").string();
  std::ofstream(path) << d.j.dump();
  expect_error(path, "outside the scene's folder");
}

TEST_F(Gltf, GarbageAndTruncatedFiles) {
  expect_error(write("junk.gltf", std::string(100, '\x07')), "JSON");
  Doc d;
  d.embed();
  const std::string full = d.j.dump();
  expect_error(write("cut.gltf", full.substr(0, full.size() / 2)), "JSON");
  std::string glb = "glTF";
  put<uint32_t>(glb, {2, 1000000, 50, 0x4E4F534Au});
  expect_error(write("cut.glb", glb), "GLB header");
}

TEST_F(Gltf, NaNPositionIsRefused) {
  Doc d;
  const float nan = std::nanf("");
  std::memcpy(d.blob.data() + 4, &nan, 4);
  expect_error(d, "NaN or infinite");
}

TEST_F(Gltf, AccessorWithTheWrongShape) {
  Doc d;
  d.j["accessors"][0]["type"] = "VEC2";
  expect_error(d, "has 2 components, expected 3");
}

}  // namespace
}  // namespace tessera

// ---- animation (issue 12) ----------------------------------------------------------------

namespace tessera {
namespace {

// Appends floats as an accessor of `type` (SCALAR, VEC3, VEC4); returns its index.
int add_floats(Doc& d, const std::vector<float>& v, const std::string& type) {
  const size_t offset = d.blob.size();
  for (float f : v) put<float>(d.blob, {f});
  const int comps = type == "SCALAR" ? 1 : type == "VEC3" ? 3 : 4;
  d.j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", v.size() * 4}});
  d.j["accessors"].push_back({{"bufferView", d.j["bufferViews"].size() - 1},
                              {"componentType", 5126},
                              {"count", v.size() / size_t(comps)},
                              {"type", type}});
  d.j["buffers"][0]["byteLength"] = d.blob.size();
  return int(d.j["accessors"].size() - 1);
}

// The triangle's node (0) animated on one path by one sampler.
Doc animated(const std::string& path, const std::string& interpolation, const std::vector<float>& times,
             const std::vector<float>& values) {
  Doc d;
  const int in = add_floats(d, times, "SCALAR");
  const int out = add_floats(d, values, path == "rotation" ? "VEC4" : "VEC3");
  const json channel = {{"sampler", 0}, {"target", {{"node", 0}, {"path", path}}}};
  const json sampler = {{"input", in}, {"output", out}, {"interpolation", interpolation}};
  d.j["animations"] =
      json::array({{{"name", "move"}, {"channels", json::array({channel})}, {"samplers", json::array({sampler})}}});
  return d;
}

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

// ---- the loader's units (core/scene/gltf/) ------------------------------------------------

namespace tessera {
namespace {

// The pre-checks on JSON alone: what tinygltf would refuse is set aside only when nothing
// uses it, and anything a mesh (attributes, indices, morph targets), an animation or a
// skin names counts as used.
TEST(GltfPrechecks, OnlyMalformedAccessorsNothingUsesAreSetAside) {
  const json bad = {{"count", 3}, {"type", "VEC3"}};  // no componentType
  json j = {{"asset", {{"version", "2.0"}}},
            {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"targets", {{{"POSITION", 1}}}}}}}}}},
            {"animations", {{{"samplers", {{{"input", 2}, {"output", 2}}}}}}},
            {"skins", {{{"inverseBindMatrices", 3}}}},
            {"accessors", {bad, bad, bad, bad, bad}}};
  std::vector<std::string> warnings;
  EXPECT_TRUE(precheck_gltf_json(j, "f.gltf", warnings));
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0], "f.gltf: accessors[4] has no valid componentType; nothing uses it: ignored");
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(j["accessors"][i], bad) << i;
  EXPECT_EQ(j["accessors"][4], json({{"componentType", 5126}, {"count", 0}, {"type", "SCALAR"}}));
  // Nothing left to set aside: unchanged.
  warnings.clear();
  EXPECT_FALSE(precheck_gltf_json(j, "f.gltf", warnings));
  EXPECT_TRUE(warnings.empty());
}

TEST(GltfPrechecks, RefusalsNameTheElement) {
  auto refusal = [](json j) -> std::string {
    std::vector<std::string> warnings;
    try {
      precheck_gltf_json(j, "f.gltf", warnings);
    } catch (const SceneError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(refusal(json::array()).find("JSON: top level is not an object"), std::string::npos);
  EXPECT_NE(refusal({{"extensionsRequired", {"KHR_draco_mesh_compression"}}})
                .find("extensionsRequired: required extension 'KHR_draco_mesh_compression' is not supported"),
            std::string::npos);
  EXPECT_NE(refusal({{"buffers", {{{"byteLength", 8}}, {{"uri", "a.bin"}}}}}).find("buffers[1]: missing byteLength"),
            std::string::npos);
  EXPECT_EQ(refusal({{"extensionsRequired", {"KHR_materials_volume"}}, {"buffers", {{{"byteLength", 1 << 30}}}}}), "");
}

class GltfDocumentTest : public Gltf {};

// The JSON of a .glb is its chunk 0, found by the file's first bytes whatever its name;
// external files are those outside it, percent-decoded, each once.
TEST_F(GltfDocumentTest, GlbChunkAndExternalFiles) {
  const json j = {{"buffers", {{{"uri", "a%20b.bin"}}, {{"uri", "data:application/octet-stream;base64,AAAA"}}}},
                  {"images", {{{"uri", "tex/c.png"}}, {{"uri", "a b.bin"}}, {{"bufferView", 0}}}}};
  std::string text = j.dump();
  while (text.size() % 4) text += ' ';
  std::string glb = "glTF";
  put<uint32_t>(glb, {2, uint32_t(20 + text.size()), uint32_t(text.size()), 0x4E4F534Au});
  glb += text;
  const GltfDocument doc = read_gltf_document(write("named.gltf", glb));
  EXPECT_TRUE(doc.binary);
  EXPECT_EQ(doc.json, j);
  EXPECT_EQ(gltf_document_external_files(doc.json), (std::vector<std::string>{"a b.bin", "tex/c.png"}));
  EXPECT_EQ(gltf_external_files(write("text.gltf", j.dump())), (std::vector<std::string>{"a b.bin", "tex/c.png"}));
}

// Accessors read from an in-memory model: interleaved (byteStride), normalized signed
// shorts clamped to -1 as the specification says, and a stride too small refused.
TEST(GltfAccessors, StrideAndNormalizedIntegers) {
  GltfContext ctx("m.gltf");
  std::string bytes;
  put<int16_t>(bytes, {-32768, 32767, 7, 0, 0, -32767, 9, 0});  // two VEC2 shorts, 8-byte stride
  ctx.model.buffers.resize(1);
  ctx.model.buffers[0].data.assign(bytes.begin(), bytes.end());
  ctx.model.bufferViews.resize(1);
  ctx.model.bufferViews[0].buffer = 0;
  ctx.model.bufferViews[0].byteLength = bytes.size();
  ctx.model.bufferViews[0].byteStride = 8;
  tinygltf::Accessor a;
  a.bufferView = 0;
  a.componentType = TINYGLTF_COMPONENT_TYPE_SHORT;
  a.normalized = true;
  a.count = 2;
  a.type = TINYGLTF_TYPE_VEC2;
  ctx.model.accessors.push_back(a);
  EXPECT_EQ(read_accessor_floats(ctx, 0, 2, "test"), (std::vector<float>{-1, 1, 0, -1}));
  ctx.model.bufferViews[0].byteStride = 2;
  try {
    read_accessor_floats(ctx, 0, 2, "test");
    ADD_FAILURE() << "a stride smaller than an element was read";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("accessors[0] (test): byteStride 2 is smaller than an element"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace tessera
