// What the glTF tests share: documents built in memory (Doc), written to a temporary
// folder and loaded (the Gltf fixture).
#pragma once

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
#include "core/scene/gltf/gltf_skins.h"
#include "core/scene/gltf/gltf_textures.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#include "tests/core/test_paths.h"

namespace tessera {

namespace fs = std::filesystem;
using json = nlohmann::json;

inline std::string base64(const std::string& in) {
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
inline void put(std::string& blob, std::initializer_list<T> values) {
  for (T v : values) blob.append(reinterpret_cast<const char*>(&v), sizeof v);
}

// A 2x1 RGB PNG, red then blue, and it as a data URI.
inline const unsigned char kRedBluePng[] = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00,
    0x00, 0x02, 0x00, 0x00, 0x00, 0x01, 0x08, 0x02, 0x00, 0x00, 0x00, 0x7b, 0x40, 0xe8, 0xdd, 0x00, 0x00, 0x00,
    0x0d, 0x49, 0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0xf8, 0xcf, 0x00, 0x04, 0xff, 0x01, 0x07, 0x00, 0x01, 0xff,
    0xe2, 0x23, 0x9e, 0x59, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};

inline std::string red_blue_png_uri() {
  return "data:image/png;base64," + base64(std::string(reinterpret_cast<const char*>(kRedBluePng), sizeof kRedBluePng));
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

// Appends floats as an accessor of `type` (SCALAR, VEC3, VEC4); returns its index.
inline int add_floats(Doc& d, const std::vector<float>& v, const std::string& type) {
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

// The triangle's node (0) animated on one path by one sampler (`node`: another node).
inline Doc animated(const std::string& path, const std::string& interpolation, const std::vector<float>& times,
                    const std::vector<float>& values, int node = 0) {
  Doc d;
  const int in = add_floats(d, times, "SCALAR");
  const int out = add_floats(d, values, path == "rotation" ? "VEC4" : "VEC3");
  const json channel = {{"sampler", 0}, {"target", {{"node", node}, {"path", path}}}};
  const json sampler = {{"input", in}, {"output", out}, {"interpolation", interpolation}};
  d.j["animations"] =
      json::array({{{"name", "move"}, {"channels", json::array({channel})}, {"samplers", json::array({sampler})}}});
  return d;
}

// `d` written to a temporary file and loaded (tests outside the Gltf fixture).
inline Scene load_gltf_doc(Doc d) {
  d.embed();
  const fs::path file = fs::temp_directory_path() / ("tessera_doc_" + std::to_string(::getpid()) + ".gltf");
  std::ofstream(file) << d.j.dump();
  Scene scene = load_scene(file.string());
  fs::remove(file);
  return scene;
}

// A .glb of `json` (padded with spaces) and `bin` (padded with zeros unless `pad_bin` is
// false, to make a broken one).
inline std::string glb_file(std::string json, std::string bin, bool pad_bin = true) {
  while (json.size() % 4) json += ' ';
  while (pad_bin && bin.size() % 4) bin += '\0';
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  return "glTF" + u32(2) + u32(uint32_t(12 + 8 + json.size() + 8 + bin.size())) + u32(uint32_t(json.size())) + "JSON" +
         json + u32(uint32_t(bin.size())) + "BIN" + std::string(1, '\0') + bin;
}

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

}  // namespace tessera
