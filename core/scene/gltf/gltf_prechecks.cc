#include "core/scene/gltf/gltf_prechecks.h"

#include <cmath>
#include <cstdio>
#include <set>

#include "core/scene/gltf/gltf_extensions.h"
#include "core/scene/scene_error.h"

namespace tessera {
namespace {

// The accessor's problem, or empty when tinygltf will parse it.
std::string accessor_problem(const nlohmann::json& a) {
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

// The accessors something refers to: mesh attributes, indices and morph targets,
// animation samplers, skins' inverse bind matrices. (A new feature that reads accessors
// from elsewhere, e.g. EXT_mesh_gpu_instancing's node attributes, adds them here.)
std::set<int64_t> used_accessors(const nlohmann::json& j) {
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

// Why a required image-format extension is refused, in words.
std::string image_format_note(const std::string& ext) {
  const char* format = gltf_undecodable_format(ext);
  if (!format) return "";
  return std::string(" (") + format +
         " textures cannot be decoded here, and a file that requires them has no PNG or JPEG fallback; export "
         "with PNG or JPEG textures)";
}

// An EXT_meshopt_compression fallback buffer without a uri: it holds no data (the views
// into it are decoded from compressed ones), so it is neither read nor counted.
bool meshopt_fallback(const nlohmann::json& b) {
  return !b.contains("uri") && b.contains("extensions") && b["extensions"].is_object() &&
         b["extensions"].contains("EXT_meshopt_compression") &&
         b["extensions"]["EXT_meshopt_compression"].is_object() &&
         b["extensions"]["EXT_meshopt_compression"].value("fallback", false) == true;
}

}  // namespace

bool precheck_gltf_json(nlohmann::json& j, const std::string& path, std::vector<std::string>& warnings) {
  if (!j.is_object()) throw SceneError(path, "JSON", "top level is not an object");
  if (j.contains("extensionsRequired") && j["extensionsRequired"].is_array())
    for (const auto& e : j["extensionsRequired"])
      if (e.is_string() && !gltf_extension_supported(e.get<std::string>()))
        throw SceneError(path, "extensionsRequired",
                         "required extension '" + e.get<std::string>() + "' is not supported" +
                             image_format_note(e.get<std::string>()));
  if (j.contains("buffers") && j["buffers"].is_array()) {
    // Each buffer is read whole, used or not, so all of them together are bounded too: one
    // 100 MB file named by 20 buffers held 2 GB.
    double total = 0;
    for (size_t i = 0; i < j["buffers"].size(); ++i) {
      const auto& b = j["buffers"][i];
      const std::string el = "buffers[" + std::to_string(i) + "]";
      if (!b.is_object() || !b.contains("byteLength") || !b["byteLength"].is_number())
        throw SceneError(path, el, "missing byteLength");
      const double len = b["byteLength"].get<double>();
      if (!(len >= 0) || len > double(kMaxGltfBufferBytes)) {
        char shown[64];
        std::snprintf(shown, sizeof shown, "%.0f", len);
        throw SceneError(path, el, std::string("byteLength ") + shown + " is over the 1 GiB limit");
      }
      if (!meshopt_fallback(b)) total += len;
      if (total > double(kMaxGltfBuffersBytes))
        throw SceneError(path, el,
                         "the buffers up to this one declare " + std::to_string(uint64_t(total)) +
                             " bytes together, over the 2 GiB limit");
    }
  }
  // Every bufferView inside its buffer (the buffer's declared length: tinygltf makes each
  // buffer's data exactly that long), used or not: tinygltf hands an image's view to the
  // image loader unchecked, and a view past its buffer (or whose offset and length wrap
  // past 2^64) was read past the buffer's end.
  if (j.contains("bufferViews") && j["bufferViews"].is_array() && j.contains("buffers") && j["buffers"].is_array())
    for (size_t i = 0; i < j["bufferViews"].size(); ++i) {
      const auto& v = j["bufferViews"][i];
      if (!v.is_object() || !v.contains("buffer") || !v["buffer"].is_number()) continue;
      const double bd = v["buffer"].get<double>();  // (tinygltf takes 0.0 for 0 too)
      if (!(bd >= 0) || bd != std::floor(bd) || bd >= double(j["buffers"].size())) continue;  // (tinygltf refuses it)
      const size_t b = size_t(bd);
      const double len = j["buffers"][b]["byteLength"].get<double>();
      const auto number = [&](const char* key) {
        return v.contains(key) && v[key].is_number() ? v[key].get<double>() : 0.0;
      };
      const double offset = number("byteOffset"), length = number("byteLength");
      // (Doubles: exact below 2^53, and anything above is past any buffer.)
      if (offset < 0 || length < 0 || offset > len || length > len - offset) {
        char shown[160];
        std::snprintf(shown, sizeof shown,
                      "runs past the end of its buffer (byteOffset %.0f + byteLength %.0f > %.0f bytes of buffer %llu)",
                      offset, length, len, static_cast<unsigned long long>(b));
        throw SceneError(path, "bufferViews[" + std::to_string(i) + "]", shown);
      }
    }
  bool changed = false;
  // EXT_meshopt_compression's fallback buffers have no data (the views that point into them
  // are decoded from compressed ones): one byte stands in, so the parser has nothing to load.
  if (j.contains("buffers") && j["buffers"].is_array())
    for (auto& b : j["buffers"]) {
      if (meshopt_fallback(b)) {
        b["uri"] = "data:application/octet-stream;base64,AA==";
        b["byteLength"] = 1;
        changed = true;
      }
    }
  // Debian's tinygltf 2.7 drops data URIs of image types it does not know (WebP): as
  // octet-stream they keep their bytes, and the texture unit recognises WebP by content.
  if (j.contains("images") && j["images"].is_array())
    for (auto& img : j["images"]) {
      static const std::string kWebp = "data:image/webp;base64,";
      if (!img.is_object() || !img.contains("uri") || !img["uri"].is_string()) continue;
      const std::string& uri = img["uri"].get_ref<const std::string&>();
      if (uri.rfind(kWebp, 0) == 0) {
        img["uri"] = "data:application/octet-stream;base64," + uri.substr(kWebp.size());
        changed = true;
      }
    }
  // A Draco primitive's accessors have no bufferView (their data is in the compressed
  // stream), which Debian's tinygltf 2.7 refuses for indices: the stream's view stands in
  // until gltf_compression.cc puts the decoded indices there.
  if (j.contains("meshes") && j["meshes"].is_array() && j.contains("accessors") && j["accessors"].is_array())
    for (auto& mesh : j["meshes"]) {
      if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
      for (auto& p : mesh["primitives"]) {
        if (!p.is_object() || !p.contains("extensions") || !p["extensions"].is_object()) continue;
        const auto& ext = p["extensions"];
        if (!ext.contains("KHR_draco_mesh_compression") || !ext["KHR_draco_mesh_compression"].is_object()) continue;
        const auto& view = ext["KHR_draco_mesh_compression"].value("bufferView", nlohmann::json());
        if (!view.is_number_unsigned() || !p.contains("indices") || !p["indices"].is_number_unsigned()) continue;
        const size_t idx = p["indices"].get<size_t>();
        if (idx < j["accessors"].size() && j["accessors"][idx].is_object() &&
            !j["accessors"][idx].contains("bufferView")) {
          j["accessors"][idx]["bufferView"] = view;
          changed = true;
        }
      }
    }
  if (j.contains("accessors") && j["accessors"].is_array()) {
    const std::set<int64_t> used = used_accessors(j);
    for (size_t i = 0; i < j["accessors"].size(); ++i) {
      if (used.count(int64_t(i))) continue;
      const std::string problem = accessor_problem(j["accessors"][i]);
      if (problem.empty()) continue;
      warnings.push_back(path + ": accessors[" + std::to_string(i) + "] " + problem + "; nothing uses it: ignored");
      j["accessors"][i] = {{"componentType", 5126}, {"count", 0}, {"type", "SCALAR"}};
      changed = true;
    }
  }
  return changed;
}

}  // namespace tessera
