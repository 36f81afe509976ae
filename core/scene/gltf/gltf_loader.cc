#include "core/scene/gltf/gltf_loader.h"

#include <stb/stb_image.h>
#include <tiny_gltf.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "core/math/transform.h"
#include "core/scene/animation.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

constexpr uint64_t kMaxBufferBytes = uint64_t(1) << 30;  // per buffer and per file
constexpr uint64_t kMaxImagePixels = uint64_t(1) << 26;  // 64 M texels
constexpr int kMaxNodeDepth = 256;
// 1 W = 683 lm at 555 nm: KHR_lights_punctual's photometric units to our radiometric RGB.
constexpr double kLumensPerWatt = 683.0;

const std::set<std::string> kSupportedExtensions = {
    "KHR_lights_punctual",  "KHR_materials_transmission",      "KHR_materials_ior",
    "KHR_materials_volume", "KHR_materials_emissive_strength", "KHR_texture_transform"};

// A little-endian 32-bit word of a GLB at byte `at` (the caller checks the size).
uint32_t glb_u32(const std::string& b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

std::string read_file(const std::string& path, const std::string& file_for_errors) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) throw SceneError(file_for_errors, "", "cannot open file");
  if (size > kMaxBufferBytes) throw SceneError(file_for_errors, "", "file larger than the 1 GiB limit");
  std::ifstream in(path, std::ios::binary);
  std::string s(size, '\0');
  in.read(s.data(), std::streamsize(size));
  if (!in) throw SceneError(file_for_errors, "", "cannot read file");
  return s;
}

// Filesystem access for tinygltf: only files inside the scene's folder, none too large.
struct FsGuard {
  fs::path base;
  std::string scene;
};

bool guarded_exists(const std::string& path, void* user) {
  (void)user;
  std::error_code ec;
  return fs::exists(path, ec);
}
std::string guarded_expand(const std::string& path, void*) { return path; }
bool guarded_read(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
  const FsGuard& g = *static_cast<FsGuard*>(user);
  std::error_code ec;
  const fs::path p = fs::weakly_canonical(path, ec);
  const std::string base = g.base.string() + "/";
  if (ec || p.string().compare(0, base.size(), base) != 0) {
    *err = "'" + path + "' is outside the scene's folder";
    return false;
  }
  const auto size = fs::file_size(p, ec);
  if (ec) {
    *err = "cannot open '" + path + "'";
    return false;
  }
  if (size > kMaxBufferBytes) {
    *err = "'" + path + "' is larger than the 1 GiB limit";
    return false;
  }
  std::ifstream in(p, std::ios::binary);
  out->resize(size);
  in.read(reinterpret_cast<char*>(out->data()), std::streamsize(size));
  if (!in) {
    *err = "cannot read '" + path + "'";
    return false;
  }
  return true;
}
bool guarded_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  *err = "writing is not allowed";
  return false;
}

// Keeps each image's encoded bytes: an image is decoded only when a material uses it
// (decode_image), so an unused broken one costs nothing and refuses nothing, as in viewers.
constexpr int kEncoded = -1;  // tinygltf::Image::component of bytes not yet decoded
bool load_image(tinygltf::Image* image, const int, std::string*, std::string*, int, int, const unsigned char* bytes,
                int size, void*) {
  image->image.assign(bytes, bytes + size);
  image->width = image->height = 0;
  image->component = kEncoded;
  return true;
}

std::string percent_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(uint8_t(s[i + 1])) && std::isxdigit(uint8_t(s[i + 2]))) {
      out.push_back(char(std::stoi(s.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(s[i]);
    }
  }
  return out;
}

float srgb_to_linear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

class GltfLoader {
 public:
  explicit GltfLoader(std::string path) : path_(std::move(path)) {}

  // The external files (buffers, images) the document names, as paths relative to its
  // folder, percent-decoded; data: URIs are inside the file.
  std::vector<std::string> external_files() const {
    const std::string bytes = read_file(path_, path_);
    const bool binary = bytes.size() >= 4 && bytes.compare(0, 4, "glTF") == 0;
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(binary ? glb_json(bytes) : bytes);
    } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
      fail("JSON", first_line(e.what()));
    }
    std::vector<std::string> out;
    std::set<std::string> seen;
    for (const char* key : {"buffers", "images"}) {
      if (!j.is_object() || !j.contains(key) || !j[key].is_array()) continue;
      for (const auto& item : j[key]) {
        if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) continue;
        const std::string uri = item["uri"];
        if (uri.rfind("data:", 0) == 0) continue;
        const std::string rel = percent_decode(uri);
        if (seen.insert(rel).second) out.push_back(rel);
      }
    }
    return out;
  }

  Scene load() {
    scene_.source = path_;
    std::string bytes = read_file(path_, path_);
    const bool binary = bytes.size() >= 4 && bytes.compare(0, 4, "glTF") == 0;
    if (std::optional<std::string> fixed = prevalidate(binary ? glb_json(bytes) : bytes))
      bytes = binary ? replace_glb_json(bytes, *fixed) : *fixed;

    tinygltf::TinyGLTF loader;
    FsGuard guard{fs::weakly_canonical(fs::absolute(path_).parent_path()), path_};
    tinygltf::FsCallbacks cb{guarded_exists, guarded_expand, guarded_read, guarded_write, &guard};
    loader.SetFsCallbacks(cb);
    loader.SetImageLoader(load_image, nullptr);
    std::string err, warn;
    const std::string base = fs::absolute(path_).parent_path().string();
    const bool ok =
        binary ? loader.LoadBinaryFromMemory(&model_, &err, &warn, reinterpret_cast<const unsigned char*>(bytes.data()),
                                             unsigned(bytes.size()), base)
               : loader.LoadASCIIFromString(&model_, &err, &warn, bytes.data(), unsigned(bytes.size()), base);
    if (!ok) throw SceneError(path_, "", first_line(err.empty() ? "glTF parse error" : err));
    if (!warn.empty()) scene_.warnings.push_back(path_ + ": " + first_line(warn));
    for (const std::string& ext : model_.extensionsUsed)
      if (!kSupportedExtensions.count(ext))
        scene_.warnings.push_back(path_ + ": optional extension '" + ext + "' is not supported; ignored");

    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      const int s = model_.defaultScene >= 0 ? model_.defaultScene : 0;
      if (s >= int(model_.scenes.size())) fail("scene", "defaultScene " + std::to_string(s) + " does not exist");
      roots = model_.scenes[size_t(s)].nodes;
    } else {  // no scenes: every node that is nobody's child
      std::vector<bool> child(model_.nodes.size());
      for (const auto& n : model_.nodes)
        for (int c : n.children)
          if (c >= 0 && size_t(c) < child.size()) child[size_t(c)] = true;
      for (size_t i = 0; i < child.size(); ++i)
        if (!child[i]) roots.push_back(int(i));
    }
    std::vector<int> path;
    recording_ = !model_.animations.empty();
    for (int r : roots) visit(r, Mat4(), path, -1);
    if (recording_) read_animations();
    if (scene_.meshes.empty() && scene_.spheres.empty()) fail("scene", "no triangles to render");
    if (!scene_.camera.present) frame_bounds();
    scene_.finalize();
    if (scene_.lights.empty()) {  // (emissive materials are lights by now)
      scene_.unlit = true;
      scene_.warnings.insert(scene_.warnings.begin(),  // first: it explains the whole image
                             path_ +
                                 ": no lights (no KHR_lights_punctual light, no emissive material): rendered under a "
                                 "neutral default environment of radiance 1 from every direction (--env-color sets "
                                 "another, --no-default-env none)");
    }
    return std::move(scene_);
  }

 private:
  [[noreturn]] void fail(const std::string& element, const std::string& reason) const {
    throw SceneError(path_, element, reason);
  }
  // tinygltf's messages span lines: join them into one.
  static std::string first_line(const std::string& s) {
    std::string t;
    for (char c : s) {
      if (c == '\r') continue;
      if (c == '\n') {
        while (!t.empty() && t.back() == ' ') t.pop_back();
        if (!t.empty() && t.back() != ':' && t.back() != ';') t += ';';
        t += ' ';
      } else {
        t += c;
      }
    }
    while (!t.empty() && (t.back() == ' ' || t.back() == ';')) t.pop_back();
    return t;
  }

  std::string glb_json(const std::string& b) const {
    auto u32 = [&](size_t at) { return glb_u32(b, at); };
    if (b.size() < 20) fail("GLB header", "file too short");
    if (u32(4) != 2) fail("GLB header", "version " + std::to_string(u32(4)) + " (expected 2)");
    if (u32(8) > b.size())
      fail("GLB header", "declares " + std::to_string(u32(8)) + " bytes, file has " + std::to_string(b.size()));
    const uint32_t json_len = u32(12);
    if (u32(16) != 0x4E4F534Au) fail("GLB chunk 0", "is not JSON");
    if (uint64_t(json_len) + 20 > b.size())
      fail("GLB chunk 0", "length " + std::to_string(json_len) + " runs past the end of the file");
    return b.substr(20, json_len);
  }

  // A GLB with its JSON chunk replaced (padded with spaces to 4 bytes, as the spec asks).
  std::string replace_glb_json(const std::string& b, std::string json) const {
    auto u32 = [&](size_t at) { return glb_u32(b, at); };
    const size_t old_end = 20 + size_t(u32(12));
    while (json.size() % 4) json += ' ';
    std::string out = b.substr(0, 12);
    const uint32_t len = uint32_t(json.size()), type = 0x4E4F534Au;
    out.append(reinterpret_cast<const char*>(&len), 4);
    out.append(reinterpret_cast<const char*>(&type), 4);
    out += json;
    out += b.substr(std::min(old_end, b.size()));
    const uint32_t total = uint32_t(out.size());
    std::memcpy(out.data() + 8, &total, 4);
    return out;
  }

  // Accessors no mesh, animation or skin refers to. The course's renderer and glTF viewers
  // read accessors only when something uses them, so a malformed unused one must not cost
  // the scene: it is replaced by a harmless one, with a warning. Returns the accessor's
  // problem, or empty when tinygltf will parse it.
  static std::string accessor_problem(const nlohmann::json& a) {
    static const std::set<std::string> kTypes = {"SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4"};
    static const std::set<int64_t> kComponents = {5120, 5121, 5122, 5123, 5125, 5126};
    if (!a.is_object()) return "is not an object";
    if (!a.contains("componentType") || !a["componentType"].is_number_integer() ||
        !kComponents.count(a["componentType"].get<int64_t>()))
      return "has no valid componentType";
    if (!a.contains("count") || !a["count"].is_number_integer() || a["count"].get<int64_t>() < 0)
      return "has no valid count";
    if (!a.contains("type") || !a["type"].is_string() || !kTypes.count(a["type"].get<std::string>()))
      return "has no valid type";
    if (a.contains("bufferView") && !(a["bufferView"].is_number_integer() && a["bufferView"].get<int64_t>() >= 0))
      return "has an invalid bufferView";
    if (a.contains("sparse") && !a["sparse"].is_object()) return "has an invalid sparse";
    return "";
  }
  static std::set<int64_t> used_accessors(const nlohmann::json& j) {
    std::set<int64_t> used;
    auto take = [&](const nlohmann::json& v) {
      if (v.is_number_integer()) used.insert(v.get<int64_t>());
    };
    auto values_of = [&](const nlohmann::json& o) {
      if (o.is_object())
        for (const auto& [k, v] : o.items()) take(v);
    };
    if (j.contains("meshes") && j["meshes"].is_array())
      for (const auto& m : j["meshes"])
        if (m.is_object() && m.contains("primitives") && m["primitives"].is_array())
          for (const auto& p : m["primitives"]) {
            if (!p.is_object()) continue;
            if (p.contains("attributes")) values_of(p["attributes"]);
            if (p.contains("indices")) take(p["indices"]);
            if (p.contains("targets") && p["targets"].is_array())
              for (const auto& t : p["targets"]) values_of(t);
          }
    if (j.contains("animations") && j["animations"].is_array())
      for (const auto& a : j["animations"])
        if (a.is_object() && a.contains("samplers") && a["samplers"].is_array())
          for (const auto& sm : a["samplers"])
            if (sm.is_object()) {
              if (sm.contains("input")) take(sm["input"]);
              if (sm.contains("output")) take(sm["output"]);
            }
    if (j.contains("skins") && j["skins"].is_array())
      for (const auto& sk : j["skins"])
        if (sk.is_object() && sk.contains("inverseBindMatrices")) take(sk["inverseBindMatrices"]);
    return used;
  }

  // Checks that tinygltf does not do, before it allocates anything. Returns the JSON to
  // parse instead when unused malformed data had to be set aside.
  std::optional<std::string> prevalidate(const std::string& json_text) {
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(json_text);
    } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
      fail("JSON", first_line(e.what()));
    }
    if (!j.is_object()) fail("JSON", "top level is not an object");
    if (j.contains("extensionsRequired") && j["extensionsRequired"].is_array())
      for (const auto& e : j["extensionsRequired"])
        if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>()))
          fail("extensionsRequired", "required extension '" + e.get<std::string>() + "' is not supported");
    if (j.contains("buffers") && j["buffers"].is_array())
      for (size_t i = 0; i < j["buffers"].size(); ++i) {
        const auto& b = j["buffers"][i];
        if (!b.is_object() || !b.contains("byteLength") || !b["byteLength"].is_number())
          fail("buffers[" + std::to_string(i) + "]", "missing byteLength");
        const double len = b["byteLength"].get<double>();
        if (!(len >= 0) || len > double(kMaxBufferBytes)) {
          char shown[64];
          std::snprintf(shown, sizeof shown, "%.0f", len);
          fail("buffers[" + std::to_string(i) + "]", std::string("byteLength ") + shown + " is over the 1 GiB limit");
        }
      }
    bool changed = false;
    if (j.contains("accessors") && j["accessors"].is_array()) {
      const std::set<int64_t> used = used_accessors(j);
      for (size_t i = 0; i < j["accessors"].size(); ++i) {
        if (used.count(int64_t(i))) continue;
        const std::string problem = accessor_problem(j["accessors"][i]);
        if (problem.empty()) continue;
        scene_.warnings.push_back(path_ + ": accessors[" + std::to_string(i) + "] " + problem +
                                  "; nothing uses it: ignored");
        j["accessors"][i] = {{"componentType", 5126}, {"count", 0}, {"type", "SCALAR"}};
        changed = true;
      }
    }
    if (!changed) return std::nullopt;
    return j.dump();
  }

  // ---- accessors ---------------------------------------------------------------------
  // Reads an accessor as floats (n components per element), checking every bound.
  std::vector<float> read_floats(int index, int want_components, const std::string& what) {
    const std::string el = "accessors[" + std::to_string(index) + "] (" + what + ")";
    if (index < 0 || size_t(index) >= model_.accessors.size())
      fail(what, "accessor " + std::to_string(index) + " does not exist");
    const tinygltf::Accessor& a = model_.accessors[size_t(index)];
    const int comps = tinygltf::GetNumComponentsInType(uint32_t(a.type));
    if (comps != want_components)
      fail(el, "has " + std::to_string(comps) + " components, expected " + std::to_string(want_components));
    if (a.count > (size_t(1) << 28)) fail(el, "count " + std::to_string(a.count) + " is too large");
    std::vector<float> out(a.count * size_t(comps), 0.0f);
    if (a.bufferView >= 0)
      read_view(a.bufferView, a.byteOffset, a.componentType, a.normalized, a.count, comps, el, out.data());
    if (a.sparse.isSparse) {
      const auto& sp = a.sparse;
      if (sp.count < 0 || size_t(sp.count) > a.count) fail(el, "sparse count out of range");
      std::vector<float> idx(size_t(sp.count)), val(size_t(sp.count) * comps);
      read_view(sp.indices.bufferView, size_t(std::max(0, sp.indices.byteOffset)), sp.indices.componentType, false,
                size_t(sp.count), 1, el + " sparse indices", idx.data());
      read_view(sp.values.bufferView, size_t(std::max(0, sp.values.byteOffset)), a.componentType, a.normalized,
                size_t(sp.count), comps, el + " sparse values", val.data());
      for (size_t k = 0; k < idx.size(); ++k) {
        const double i = idx[k];
        if (!(i >= 0 && i < double(a.count))) fail(el, "sparse index " + std::to_string(i) + " out of range");
        std::copy(val.begin() + long(k * comps), val.begin() + long((k + 1) * comps),
                  out.begin() + long(size_t(i) * comps));
      }
    }
    for (float v : out)
      if (!std::isfinite(v)) fail(el, "contains a NaN or infinite value");
    return out;
  }

  // Where `count` elements of `comps` components of `type` start in a buffer view, after
  // checking that every byte of them lies inside the view and the view inside its buffer.
  struct ViewSpan {
    const unsigned char* base;
    size_t stride;
    int csize;
  };
  ViewSpan checked_view(int view_index, size_t offset, int type, size_t count, int comps, const std::string& el) {
    if (view_index < 0 || size_t(view_index) >= model_.bufferViews.size())
      fail(el, "bufferView " + std::to_string(view_index) + " does not exist");
    const tinygltf::BufferView& v = model_.bufferViews[size_t(view_index)];
    if (v.buffer < 0 || size_t(v.buffer) >= model_.buffers.size())
      fail(el, "buffer " + std::to_string(v.buffer) + " does not exist");
    const std::vector<unsigned char>& data = model_.buffers[size_t(v.buffer)].data;
    const int csize = tinygltf::GetComponentSizeInBytes(uint32_t(type));
    if (csize <= 0) fail(el, "unknown component type " + std::to_string(type));
    const uint64_t elem = uint64_t(csize) * uint64_t(comps);
    const uint64_t stride = v.byteStride ? v.byteStride : elem;
    if (stride < elem) fail(el, "byteStride " + std::to_string(v.byteStride) + " is smaller than an element");
    if (uint64_t(v.byteOffset) + v.byteLength > data.size())
      fail(el, "bufferView " + std::to_string(view_index) + " runs past the end of its buffer (" +
                   std::to_string(v.byteOffset + v.byteLength) + " > " + std::to_string(data.size()) + " bytes)");
    if (count > 0 && uint64_t(offset) + stride * (count - 1) + elem > v.byteLength)
      fail(el, "byteOffset " + std::to_string(offset) + " with " + std::to_string(count) +
                   " elements runs past the end of bufferView " + std::to_string(view_index));
    return {data.data() + v.byteOffset + offset, size_t(stride), csize};
  }

  void read_view(int view_index, size_t offset, int type, bool normalized, size_t count, int comps,
                 const std::string& el, float* out) {
    const auto [base, stride, csize] = checked_view(view_index, offset, type, count, comps, el);
    for (size_t i = 0; i < count; ++i)
      for (int c = 0; c < comps; ++c) {
        const unsigned char* p = base + i * stride + size_t(c) * size_t(csize);
        float f = 0;
        switch (type) {
          case TINYGLTF_COMPONENT_TYPE_BYTE: {
            int8_t x;
            std::memcpy(&x, p, 1);
            f = normalized ? std::max(float(x) / 127.0f, -1.0f) : float(x);
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            f = normalized ? float(*p) / 255.0f : float(*p);
            break;
          case TINYGLTF_COMPONENT_TYPE_SHORT: {
            int16_t x;
            std::memcpy(&x, p, 2);
            f = normalized ? std::max(float(x) / 32767.0f, -1.0f) : float(x);
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            uint16_t x;
            std::memcpy(&x, p, 2);
            f = normalized ? float(x) / 65535.0f : float(x);
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
            uint32_t x;
            std::memcpy(&x, p, 4);
            f = float(x);
            break;
          }
          case TINYGLTF_COMPONENT_TYPE_FLOAT:
            std::memcpy(&f, p, 4);
            break;
          default:
            fail(el, "component type " + std::to_string(type) + " is not allowed here");
        }
        out[i * size_t(comps) + size_t(c)] = f;
      }
  }

  std::vector<uint32_t> read_indices(int index, size_t vertex_count, const std::string& what) {
    const std::string el = "accessors[" + std::to_string(index) + "] (" + what + ")";
    if (index < 0 || size_t(index) >= model_.accessors.size())
      fail(what, "accessor " + std::to_string(index) + " does not exist");
    const tinygltf::Accessor& a = model_.accessors[size_t(index)];
    if (a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
        a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
      fail(el, "indices must be unsigned byte, short or int");
    if (a.bufferView < 0) fail(el, "indices need a bufferView");
    // Read as integers, not through read_view's floats, which lose precision past 2^24.
    const auto [base, stride, csize] = checked_view(a.bufferView, a.byteOffset, a.componentType, a.count, 1, el);
    std::vector<uint32_t> out(a.count);
    for (size_t i = 0; i < a.count; ++i) {
      uint32_t x = 0;
      std::memcpy(&x, base + i * stride, size_t(csize));
      if (x >= vertex_count)
        fail(el, "index " + std::to_string(x) + " out of range (" + std::to_string(vertex_count) + " vertices)");
      out[i] = x;
    }
    return out;
  }

  // ---- nodes -------------------------------------------------------------------------
  Mat4 local_matrix(const tinygltf::Node& n, const std::string& el) const {
    if (!n.matrix.empty()) {
      if (n.matrix.size() != 16) fail(el, "matrix needs 16 numbers");
      std::array<double, 16> m{};
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = n.matrix[size_t(c * 4 + r)];  // glTF is column-major
      return Mat4::from_row_major(m);
    }
    const Trs x = trs_of(n, el);
    return trs_matrix(x.t, x.r, x.s);
  }

  // A node's translation, rotation and scale (glTF's defaults where absent), checked.
  struct Trs {
    std::array<double, 3> t{0, 0, 0}, s{1, 1, 1};
    std::array<double, 4> r{0, 0, 0, 1};
  };
  Trs trs_of(const tinygltf::Node& n, const std::string& el) const {
    Trs x;
    if (!n.translation.empty()) {
      if (n.translation.size() != 3) fail(el, "translation needs 3 numbers");
      x.t = {n.translation[0], n.translation[1], n.translation[2]};
    }
    if (!n.rotation.empty()) {
      if (n.rotation.size() != 4) fail(el, "rotation needs 4 numbers");
      x.r = {n.rotation[0], n.rotation[1], n.rotation[2], n.rotation[3]};
      const double len = std::sqrt(x.r[0] * x.r[0] + x.r[1] * x.r[1] + x.r[2] * x.r[2] + x.r[3] * x.r[3]);
      if (!(len > 0)) fail(el, "rotation quaternion is zero");
    }
    if (!n.scale.empty()) {
      if (n.scale.size() != 3) fail(el, "scale needs 3 numbers");
      x.s = {n.scale[0], n.scale[1], n.scale[2]};
    }
    return x;
  }

  void visit(int index, const Mat4& parent, std::vector<int>& path, int32_t parent_entry) {
    const std::string el = "nodes[" + std::to_string(index) + "]";
    if (index < 0 || size_t(index) >= model_.nodes.size()) fail(el, "does not exist");
    if (std::find(path.begin(), path.end(), index) != path.end())
      fail(el, "the node graph has a cycle through this node");
    if (path.size() >= kMaxNodeDepth) fail(el, "node hierarchy deeper than 256 levels");
    const tinygltf::Node& n = model_.nodes[size_t(index)];
    const Mat4 local = local_matrix(n, el);
    const Mat4 world = parent * local;
    if (recording_) {  // the hierarchy, for posing frames of an animation
      SceneAnimation::Node e;
      e.gltf_node = uint32_t(index);
      e.parent = parent_entry;
      e.trs = n.matrix.empty();
      e.matrix = local;
      if (e.trs) {
        const Trs x = trs_of(n, el);
        e.translation = x.t;
        e.rotation = x.r;
        e.scale = x.s;
      }
      entry_ = int32_t(animation_.nodes.size());
      animation_.nodes.push_back(e);
    }
    const int32_t entry = entry_;
    path.push_back(index);
    if (n.mesh >= 0) add_mesh(n.mesh, world, el);
    if (n.camera >= 0) {
      const bool first = !scene_.camera.present;
      add_camera(n.camera, world, el);
      if (recording_ && first) animation_.camera_node = entry;
    }
    if (auto it = n.extensions.find("KHR_lights_punctual"); it != n.extensions.end()) {
      if (!it->second.Has("light") || !it->second.Get("light").IsInt())
        fail(el, "KHR_lights_punctual without a light index");
      add_light(it->second.Get("light").GetNumberAsInt(), world, el);
      if (recording_) animation_.lights.push_back({uint32_t(scene_.lights.size() - 1), uint32_t(entry)});
    }
    for (int c : n.children) visit(c, world, path, entry);
    path.pop_back();
  }

  void add_mesh(int index, const Mat4& w, const std::string& node_el) {
    if (size_t(index) >= model_.meshes.size()) fail(node_el, "mesh " + std::to_string(index) + " does not exist");
    const tinygltf::Mesh& mesh = model_.meshes[size_t(index)];
    // det < 0 mirrors the mesh: swap winding so geometric normals stay outward.
    const double det = w.det3();
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
      const tinygltf::Primitive& prim = mesh.primitives[p];
      const std::string el = "meshes[" + std::to_string(index) + "].primitives[" + std::to_string(p) + "]";
      static const char* kModes[] = {"POINTS",    "LINES",          "LINE_LOOP",   "LINE_STRIP",
                                     "TRIANGLES", "TRIANGLE_STRIP", "TRIANGLE_FAN"};
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES)
        fail(el, std::string("mode ") + (mode >= 0 && mode < 7 ? kModes[mode] : std::to_string(mode).c_str()) +
                     " is not supported (only TRIANGLES)");
      auto pos = prim.attributes.find("POSITION");
      if (pos == prim.attributes.end()) fail(el, "has no POSITION attribute");
      const std::vector<float> p3 = read_floats(pos->second, 3, el + " POSITION");
      Mesh out;
      out.name = mesh.name.empty() ? "mesh" + std::to_string(index) : mesh.name;
      const size_t nv = p3.size() / 3;
      out.positions.resize(nv);
      for (size_t i = 0; i < nv; ++i) {
        out.positions[i] = w.point(p3[3 * i], p3[3 * i + 1], p3[3 * i + 2]).to_float();
        if (!is_finite(out.positions[i])) fail(el, "vertex " + std::to_string(i) + " is not finite after transform");
      }
      if (prim.indices >= 0) {
        out.indices = read_indices(prim.indices, nv, el + " indices");
      } else {
        out.indices.resize(nv);
        for (size_t i = 0; i < nv; ++i) out.indices[i] = uint32_t(i);
      }
      if (out.indices.size() % 3) fail(el, std::to_string(out.indices.size()) + " indices is not a multiple of 3");
      if (det < 0)
        for (size_t t = 0; t < out.indices.size(); t += 3) std::swap(out.indices[t + 1], out.indices[t + 2]);
      std::vector<float> n3;  // the file's normals, object space
      if (auto nrm = prim.attributes.find("NORMAL"); nrm != prim.attributes.end()) {
        n3 = read_floats(nrm->second, 3, el + " NORMAL");
        if (n3.size() != p3.size()) fail(el, "NORMAL count differs from POSITION count");
        const Mat4 nt = w.normal_matrix();
        out.normals.resize(nv);
        for (size_t i = 0; i < nv; ++i) out.normals[i] = nt.unit_vector(n3[3 * i], n3[3 * i + 1], n3[3 * i + 2]);
        out.file_normals = true;
      }
      if (auto uv = prim.attributes.find("TEXCOORD_0"); uv != prim.attributes.end()) {
        const std::vector<float> t2 = read_floats(uv->second, 2, el + " TEXCOORD_0");
        if (t2.size() / 2 != nv) fail(el, "TEXCOORD_0 count differs from POSITION count");
        out.uvs.resize(nv);
        for (size_t i = 0; i < nv; ++i) out.uvs[i] = {t2[2 * i], t2[2 * i + 1]};
      }
      out.material = material(prim.material);
      if (out.indices.empty()) continue;
      if (recording_) {  // its object-space geometry, to transform again for each pose
        SceneAnimation::MeshBinding b;
        b.mesh = uint32_t(scene_.meshes.size());
        b.node = uint32_t(entry_);
        b.positions.resize(nv);
        for (size_t i = 0; i < nv; ++i) b.positions[i] = Vec3{p3[3 * i], p3[3 * i + 1], p3[3 * i + 2]};
        b.normals.resize(n3.size() / 3);
        for (size_t i = 0; i < b.normals.size(); ++i) b.normals[i] = Vec3{n3[3 * i], n3[3 * i + 1], n3[3 * i + 2]};
        b.indices = out.indices;
        if (det < 0)  // back to the file's winding: each pose fixes it for its own transform
          for (size_t t = 0; t < b.indices.size(); t += 3) std::swap(b.indices[t + 1], b.indices[t + 2]);
        animation_.meshes.push_back(std::move(b));
      }
      scene_.meshes.push_back(std::move(out));
    }
  }

  // ---- materials (docs/gltf.md) --------------------------------------------------------
  // A number of a material extension, when the file gives one; NaN or infinity refused.
  static const tinygltf::Value* ext_value(const tinygltf::ExtensionMap& exts, const char* ext, const char* key) {
    auto it = exts.find(ext);
    if (it == exts.end() || !it->second.IsObject() || !it->second.Has(key)) return nullptr;
    return &it->second.Get(key);
  }
  double ext_number(const tinygltf::ExtensionMap& exts, const char* ext, const char* key, double fallback,
                    const std::string& el) const {
    const tinygltf::Value* v = ext_value(exts, ext, key);
    if (!v) return fallback;
    if (!v->IsNumber()) fail(el, std::string(ext) + "." + key + " is not a number");
    const double d = v->GetNumberAsDouble();
    if (!std::isfinite(d)) fail(el, std::string(ext) + "." + key + " is not finite");
    return d;
  }
  // A factor the specification bounds to [0, 1]: out of range refused.
  double unit_factor(double v, const std::string& el, const std::string& what) const {
    if (!(v >= 0 && v <= 1)) fail(el, what + " " + std::to_string(v) + " is outside [0, 1]");
    return v;
  }
  Rgb color_factor(const std::vector<double>& f, Rgb fallback, const std::string& el, const std::string& what,
                   double hi = 1) const {
    if (f.empty()) return fallback;
    if (f.size() < 3) fail(el, what + " has " + std::to_string(f.size()) + " numbers, expected 3 or 4");
    for (size_t i = 0; i < 3; ++i)
      if (!(f[i] >= 0 && f[i] <= hi)) fail(el, what + " component " + std::to_string(f[i]) + " is out of range");
    return Rgb(float(f[0]), float(f[1]), float(f[2]));
  }

  // A textureInfo: the texture, its KHR_texture_transform, and a warning for a texCoord
  // other than 0 (only TEXCOORD_0 is read).
  TextureRef texture_ref(int index, int tex_coord, const tinygltf::ExtensionMap& exts, bool srgb, const std::string& el,
                         const std::string& what) {
    TextureRef r;
    if (index < 0) return r;
    r.index = load_texture(index, el + " " + what, srgb);
    if (auto it = exts.find("KHR_texture_transform"); it != exts.end() && it->second.IsObject()) {
      const tinygltf::Value& t = it->second;
      auto pair = [&](const char* key, double x, double y) -> std::pair<double, double> {
        if (!t.Has(key)) return {x, y};
        const tinygltf::Value& v = t.Get(key);
        if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber())
          fail(el, what + " KHR_texture_transform." + key + " is not two numbers");
        const double a = v.Get(0).GetNumberAsDouble(), b = v.Get(1).GetNumberAsDouble();
        if (!std::isfinite(a) || !std::isfinite(b)) fail(el, what + " KHR_texture_transform." + key + " is not finite");
        return {a, b};
      };
      const auto [ox, oy] = pair("offset", 0, 0);
      const auto [sx, sy] = pair("scale", 1, 1);
      double rot = 0;
      if (t.Has("rotation")) {
        if (!t.Get("rotation").IsNumber() || !std::isfinite(t.Get("rotation").GetNumberAsDouble()))
          fail(el, what + " KHR_texture_transform.rotation is not a finite number");
        rot = t.Get("rotation").GetNumberAsDouble();
      }
      // uv' = T R S uv, R = [cos sin; -sin cos] (the extension's matrix).
      const double c = std::cos(rot), sn = std::sin(rot);
      const double m[6] = {c * sx, sn * sy, ox, -sn * sx, c * sy, oy};
      for (int i = 0; i < 6; ++i) r.xform[i] = float(m[i]);
      if (t.Has("texCoord") && t.Get("texCoord").IsInt()) tex_coord = t.Get("texCoord").GetNumberAsInt();
    }
    if (tex_coord > 0)
      warn_once(el + ": " + what + " uses TEXCOORD_" + std::to_string(tex_coord) + "; TEXCOORD_0 is used");
    return r;
  }

  uint32_t material(int index) {
    if (auto it = materials_.find(index); it != materials_.end()) return it->second;
    Material m;
    m.kind = Material::Kind::kPbr;
    const std::string el = "materials[" + std::to_string(index) + "]";
    // No material: the specification's default, white, metallic 1, roughness 1.
    m.reflectance = Rgb(1.0f);
    m.metallic = 1;
    m.roughness = 1;
    Rgb emissive(0.0f);
    double strength = 1;
    bool double_sided = false;
    TextureRef emissive_texture;
    if (index >= 0) {
      if (size_t(index) >= model_.materials.size()) fail(el, "does not exist");
      const tinygltf::Material& g = model_.materials[size_t(index)];
      m.name = g.name;
      const auto& pbr = g.pbrMetallicRoughness;
      m.reflectance = color_factor(pbr.baseColorFactor, Rgb(1.0f), el, "baseColorFactor");
      m.metallic = float(unit_factor(pbr.metallicFactor, el, "metallicFactor"));
      m.roughness = float(unit_factor(pbr.roughnessFactor, el, "roughnessFactor"));
      emissive = color_factor(g.emissiveFactor, Rgb(0.0f), el, "emissiveFactor");
      double_sided = g.doubleSided;
      const auto& ex = g.extensions;
      strength = ext_number(ex, "KHR_materials_emissive_strength", "emissiveStrength", 1, el);
      if (!(strength >= 0)) fail(el, "KHR_materials_emissive_strength.emissiveStrength is negative");
      m.transmission = float(unit_factor(ext_number(ex, "KHR_materials_transmission", "transmissionFactor", 0, el), el,
                                         "transmissionFactor"));
      const double ior = ext_number(ex, "KHR_materials_ior", "ior", 1.5, el);
      if (!(ior >= 1 && ior < 10)) fail(el, "KHR_materials_ior ior " + std::to_string(ior) + " out of range [1, 10)");
      m.ior = float(ior);
      // KHR_materials_volume: thickness > 0 makes a solid; absorption from the attenuation
      // colour reached after the attenuation distance: sigma = -ln(colour) / distance.
      const double thickness = ext_number(ex, "KHR_materials_volume", "thicknessFactor", 0, el);
      if (!(thickness >= 0)) fail(el, "KHR_materials_volume.thicknessFactor is negative");
      m.thin = thickness == 0;
      const double distance = ext_number(ex, "KHR_materials_volume", "attenuationDistance", HUGE_VAL, el);
      if (!(distance > 0)) fail(el, "KHR_materials_volume.attenuationDistance must be positive");
      Rgb att(1.0f);
      if (const tinygltf::Value* v = ext_value(ex, "KHR_materials_volume", "attenuationColor")) {
        std::vector<double> f;
        if (v->IsArray())
          for (size_t i = 0; i < v->ArrayLen(); ++i)
            f.push_back(v->Get(int(i)).IsNumber() ? v->Get(int(i)).GetNumberAsDouble() : NAN);
        att = color_factor(f, Rgb(1.0f), el, "KHR_materials_volume.attenuationColor");
      }
      if (!m.thin && std::isfinite(distance)) {
        auto sigma = [&](float c) { return float(-std::log(std::max(double(c), 1e-30)) / distance); };
        m.absorption = Rgb(sigma(att.r), sigma(att.g), sigma(att.b));
      }
      m.texture = texture_ref(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord,
                              pbr.baseColorTexture.extensions, true, el, "baseColorTexture");
      m.metal_rough_texture =
          texture_ref(pbr.metallicRoughnessTexture.index, pbr.metallicRoughnessTexture.texCoord,
                      pbr.metallicRoughnessTexture.extensions, false, el, "metallicRoughnessTexture");
      m.normal_texture = texture_ref(g.normalTexture.index, g.normalTexture.texCoord, g.normalTexture.extensions, false,
                                     el, "normalTexture");
      m.normal_scale = float(g.normalTexture.scale);
      if (!std::isfinite(m.normal_scale)) fail(el, "normalTexture.scale is not finite");
      emissive_texture = texture_ref(g.emissiveTexture.index, g.emissiveTexture.texCoord, g.emissiveTexture.extensions,
                                     true, el, "emissiveTexture");
      if (const tinygltf::Value* v = ext_value(ex, "KHR_materials_transmission", "transmissionTexture"))
        if (v->IsObject() && v->Has("index"))
          warn_once(el + ": transmissionTexture is not supported; transmissionFactor is used");
      if (g.alphaMode != "OPAQUE" && !g.alphaMode.empty())
        warn_once(el + ": alphaMode " + g.alphaMode + " is rendered opaque");
    }
    m.alpha = m.roughness * m.roughness;  // glTF's alpha = roughness^2
    const Rgb radiance = emissive * float(strength);
    if (!radiance.is_black()) {
      const Rgb base = m.reflectance;
      const std::string name = m.name;
      m = Material();
      m.kind = Material::Kind::kEmission;  // emitters do not reflect (docs/gltf.md)
      m.name = name;
      m.reflectance = base;
      m.radiance = radiance;
      m.two_sided_emission = double_sided;
      m.emissive_texture = emissive_texture;
    }
    const uint32_t id = scene_.add_material(std::move(m));
    materials_[index] = id;
    return id;
  }

  // Decodes images[index] (PNG or JPEG, RGBA 8-bit), refusing absurd sizes before
  // allocating; once, whatever number of textures use it.
  const tinygltf::Image& decode_image(int index) {
    tinygltf::Image& img = model_.images[size_t(index)];
    const std::string el = "images[" + std::to_string(index) + "]";
    if (img.component != kEncoded) {
      if (img.width <= 0 || img.height <= 0 || img.image.size() < size_t(img.width) * size_t(img.height) * 4)
        fail(el, "has no pixel data");
      return img;
    }
    if (img.image.empty()) fail(el, "has no data (a missing file?)");
    int w = 0, h = 0, comp = 0;
    const int size = int(std::min<size_t>(img.image.size(), size_t(INT32_MAX)));
    if (!stbi_info_from_memory(img.image.data(), size, &w, &h, &comp)) fail(el, "not a readable PNG or JPEG");
    if (w <= 0 || h <= 0 || uint64_t(w) * uint64_t(h) > kMaxImagePixels)
      fail(el, std::to_string(w) + "x" + std::to_string(h) + " is over the 64 M texel limit");
    unsigned char* data = stbi_load_from_memory(img.image.data(), size, &w, &h, &comp, 4);
    if (!data) fail(el, stbi_failure_reason());
    img.width = w;
    img.height = h;
    img.component = 4;
    img.bits = 8;
    img.image.assign(data, data + size_t(w) * size_t(h) * 4);
    stbi_image_free(data);
    return img;
  }

  // Colour textures (base colour, emission) are sRGB-encoded, data (metallic-roughness,
  // normals) linear: a texture used both ways is decoded twice.
  int load_texture(int index, const std::string& el, bool srgb) {
    if (index < 0 || size_t(index) >= model_.textures.size())
      fail(el, "texture " + std::to_string(index) + " does not exist");
    const int key = 2 * index + (srgb ? 1 : 0);
    if (auto it = textures_.find(key); it != textures_.end()) return it->second;
    const tinygltf::Texture& t = model_.textures[size_t(index)];
    const std::string tel = "textures[" + std::to_string(index) + "]";
    if (t.source < 0 || size_t(t.source) >= model_.images.size())
      fail(tel, "image " + std::to_string(t.source) + " does not exist");
    const tinygltf::Image& img = decode_image(t.source);
    Texture tex;
    tex.width = img.width;
    tex.height = img.height;
    tex.texels.resize(size_t(img.width) * size_t(img.height));
    auto decode = [srgb](unsigned char c) { return srgb ? srgb_to_linear(c / 255.0f) : c / 255.0f; };
    for (size_t i = 0; i < tex.texels.size(); ++i)
      tex.texels[i] = Rgb(decode(img.image[4 * i]), decode(img.image[4 * i + 1]), decode(img.image[4 * i + 2]));
    if (t.sampler >= 0) {
      if (size_t(t.sampler) >= model_.samplers.size())
        fail(tel, "sampler " + std::to_string(t.sampler) + " does not exist");
      auto wrap = [&](int mode) {
        switch (mode) {
          case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE:
            return Texture::Wrap::kClamp;
          case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT:
            return Texture::Wrap::kMirror;
          default:
            return Texture::Wrap::kRepeat;
        }
      };
      tex.wrap_s = wrap(model_.samplers[size_t(t.sampler)].wrapS);
      tex.wrap_t = wrap(model_.samplers[size_t(t.sampler)].wrapT);
    }
    scene_.textures.push_back(std::move(tex));
    return textures_[key] = int(scene_.textures.size() - 1);
  }

  // ---- cameras and lights ------------------------------------------------------------
  void add_camera(int index, const Mat4& w, const std::string& node_el) {
    if (size_t(index) >= model_.cameras.size()) fail(node_el, "camera " + std::to_string(index) + " does not exist");
    if (scene_.camera.present) return;  // the first camera in the scene's node order wins
    const tinygltf::Camera& c = model_.cameras[size_t(index)];
    const std::string el = "cameras[" + std::to_string(index) + "]";
    if (c.type == "orthographic") fail(el, "orthographic cameras are not supported (use a perspective camera)");
    if (c.type != "perspective") fail(el, "unknown camera type '" + c.type + "'");
    const double yfov = c.perspective.yfov * 180 / M_PI;
    if (!(yfov > 0 && yfov < 180)) fail(el, "yfov must be in (0, pi)");
    CameraDesc& d = scene_.camera;
    d.present = true;
    d.yfov_deg = yfov;
    if (c.perspective.aspectRatio > 0) d.aspect_ratio = c.perspective.aspectRatio;
    d.xfov_deg = 2 * std::atan(std::tan(c.perspective.yfov / 2) * d.aspect_ratio.value_or(4.0 / 3.0)) * 180 / M_PI;
    d.znear = float(c.perspective.znear > 0 ? c.perspective.znear : 0.001);
    d.zfar = float(c.perspective.zfar > c.perspective.znear ? c.perspective.zfar : 1e30);
    place_camera(d, w);
    if (!is_finite(d.forward) || !is_finite(d.up)) fail(node_el, "camera transform is degenerate");
  }

  void add_light(int index, const Mat4& w, const std::string& node_el) {
    if (index < 0 || size_t(index) >= model_.lights.size())
      fail(node_el, "light " + std::to_string(index) + " does not exist");
    const tinygltf::Light& g = model_.lights[size_t(index)];
    const std::string el = "KHR_lights_punctual.lights[" + std::to_string(index) + "]";
    Rgb color(1.0f);
    if (g.color.size() >= 3) color = Rgb(float(g.color[0]), float(g.color[1]), float(g.color[2]));
    if (!(g.intensity >= 0) || !std::isfinite(g.intensity)) fail(el, "intensity must be >= 0");
    Light l;
    l.name = g.name.empty() ? "light" + std::to_string(index) : g.name;
    // Point and spot intensity is in candela (lm/sr), directional in lux (lm/m^2):
    // divided by 683 lm/W they become W/sr and W/m^2.
    l.color = color * float(g.intensity / kLumensPerWatt);
    if (g.type == "directional") {
      l.kind = Light::Kind::kDirectional;
    } else if (g.type == "point" || g.type == "spot") {
      l.kind = g.type == "point" ? Light::Kind::kPoint : Light::Kind::kSpot;
      l.att_constant = 0;
      l.att_linear = 0;
      l.att_quadratic = 1;  // physical inverse square
      if (g.type == "spot") {
        if (!(g.spot.outerConeAngle > g.spot.innerConeAngle && g.spot.innerConeAngle >= 0 &&
              g.spot.outerConeAngle <= M_PI / 2 + 1e-6))
          fail(el, "needs 0 <= innerConeAngle < outerConeAngle <= pi/2");
        l.cos_inner = float(std::cos(g.spot.innerConeAngle));
        l.cos_outer = float(std::cos(g.spot.outerConeAngle));
      }
      if (g.range > 0) warn_once(el + ": range is ignored (inverse-square falloff)");
    } else {
      fail(el, "unknown light type '" + g.type + "'");
    }
    place_light(l, w);
    if (!is_finite(l.position) || !is_finite(l.direction)) fail(node_el, "light transform is degenerate");
    scene_.lights.push_back(l);
  }

  // A camera that frames the scene: looking down -Z at the bounds' centre, 40 degrees
  // vertical field of view, far enough back to see the bounding sphere.
  void frame_bounds() {
    const Bounds b = scene_.object_bounds();
    const Vec3 c = b.center();
    const float r = 0.5f * length(b.diagonal());
    CameraDesc& d = scene_.camera;
    d.present = true;
    d.yfov_deg = 40;
    d.eye = c + Vec3{0, 0, r / std::sin(20 * kPi / 180) * 1.05f};
    d.forward = {0, 0, -1};
    d.up = {0, 1, 0};
    d.cs184_dir = {0, 0, 1};
    scene_.warnings.push_back(path_ + ": no camera; framing the scene's bounds from +Z");
  }

  void warn_once(const std::string& w) {
    if (warned_.insert(w).second) scene_.warnings.push_back(path_ + ": " + w);
  }

  std::string path_;
  // ---- animations ----------------------------------------------------------------------
  // Every animation's channels, checked (times increasing, counts agreeing with the
  // interpolation, targets and samplers that exist); then only the meshes under nodes some
  // animation moves keep their object-space copy.
  void read_animations() {
    for (size_t ai = 0; ai < model_.animations.size(); ++ai) {
      const tinygltf::Animation& an = model_.animations[ai];
      const std::string el = "animations[" + std::to_string(ai) + "]";
      SceneAnimation::Clip clip;
      clip.name = an.name;
      for (size_t ci = 0; ci < an.channels.size(); ++ci) {
        const tinygltf::AnimationChannel& ch = an.channels[ci];
        const std::string cel = el + ".channels[" + std::to_string(ci) + "]";
        if (ch.sampler < 0 || size_t(ch.sampler) >= an.samplers.size())
          fail(cel, "sampler " + std::to_string(ch.sampler) + " does not exist");
        if (ch.target_node < 0 || size_t(ch.target_node) >= model_.nodes.size())
          fail(cel, "target node " + std::to_string(ch.target_node) + " does not exist");
        SceneAnimation::Channel c;
        c.gltf_node = uint32_t(ch.target_node);
        size_t comps = 3;
        if (ch.target_path == "translation") {
          c.path = SceneAnimation::Path::kTranslation;
        } else if (ch.target_path == "rotation") {
          c.path = SceneAnimation::Path::kRotation;
          comps = 4;
        } else if (ch.target_path == "scale") {
          c.path = SceneAnimation::Path::kScale;
        } else if (ch.target_path == "weights") {
          warn_once(cel + ": morph target weights are not supported; ignored");
          continue;
        } else {
          fail(cel, "unknown target path '" + ch.target_path + "' (translation, rotation, scale or weights)");
        }
        if (!model_.nodes[size_t(ch.target_node)].matrix.empty())
          fail(cel, "targets nodes[" + std::to_string(ch.target_node) +
                        "], which has a matrix: only nodes given by translation, rotation and scale can be animated");
        const tinygltf::AnimationSampler& smp = an.samplers[size_t(ch.sampler)];
        const std::string sel = el + ".samplers[" + std::to_string(ch.sampler) + "]";
        if (smp.interpolation == "LINEAR" || smp.interpolation.empty())
          c.interpolation = SceneAnimation::Interpolation::kLinear;
        else if (smp.interpolation == "STEP")
          c.interpolation = SceneAnimation::Interpolation::kStep;
        else if (smp.interpolation == "CUBICSPLINE")
          c.interpolation = SceneAnimation::Interpolation::kCubicSpline;
        else
          fail(sel, "unknown interpolation '" + smp.interpolation + "' (LINEAR, STEP or CUBICSPLINE)");
        const std::vector<float> times = read_floats(smp.input, 1, sel + " input");
        if (times.empty()) fail(sel, "input has no keys");
        for (size_t k = 1; k < times.size(); ++k)
          if (!(times[k] > times[k - 1]))
            fail(sel, "input times must increase: key " + std::to_string(k) + " (" + std::to_string(times[k]) +
                          " s) does not come after key " + std::to_string(k - 1) + " (" + std::to_string(times[k - 1]) +
                          " s)");
        const std::vector<float> values = read_floats(smp.output, int(comps), sel + " output");
        const bool cubic = c.interpolation == SceneAnimation::Interpolation::kCubicSpline;
        const size_t want = times.size() * (cubic ? 3 : 1);
        if (values.size() / comps != want)
          fail(sel, "output has " + std::to_string(values.size() / comps) + " elements for " +
                        std::to_string(times.size()) + " input keys; " + (cubic ? "CUBICSPLINE" : smp.interpolation) +
                        " needs " + std::to_string(want));
        c.times.assign(times.begin(), times.end());
        c.values.assign(values.begin(), values.end());
        clip.duration = std::max(clip.duration, c.times.back());
        clip.channels.push_back(std::move(c));
      }
      animation_.clips.push_back(std::move(clip));
    }
    // Keep only what some animation moves.
    std::set<uint32_t> targets;
    for (const auto& clip : animation_.clips)
      for (const auto& c : clip.channels) targets.insert(c.gltf_node);
    std::vector<bool> moves(animation_.nodes.size());
    for (size_t i = 0; i < animation_.nodes.size(); ++i) {
      const auto& e = animation_.nodes[i];
      moves[i] = targets.count(e.gltf_node) || (e.parent >= 0 && moves[size_t(e.parent)]);
    }
    auto& ms = animation_.meshes;
    ms.erase(std::remove_if(ms.begin(), ms.end(), [&](const auto& b) { return !moves[b.node]; }), ms.end());
    scene_.animation = std::make_shared<const SceneAnimation>(std::move(animation_));
  }

  tinygltf::Model model_;
  Scene scene_;
  bool recording_ = false;  // the file has animations: keep what posing needs
  SceneAnimation animation_;
  int32_t entry_ = -1;  // the node entry being visited
  std::map<int, uint32_t> materials_;
  std::map<int, int> textures_;
  std::set<std::string> warned_;
};

}  // namespace

Scene load_gltf_file(const std::string& path) { return GltfLoader(path).load(); }

std::vector<std::string> gltf_external_files(const std::string& path) { return GltfLoader(path).external_files(); }

}  // namespace tessera
