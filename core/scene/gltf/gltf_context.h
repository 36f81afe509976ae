// What the units of one glTF load share: the file's name, which starts every error and
// warning; tinygltf's model of the file; the scene being built.
//
// The load, in order (gltf_loader.cc): gltf_document reads the file and parses its JSON,
// gltf_prechecks checks it, tinygltf makes the model; gltf_compression decodes meshopt
// and Draco geometry into plain buffer views; gltf_budget counts what the node graph
// expands to (refusing a bomb before anything is expanded); gltf_nodes walks the graph
// (EXT_mesh_gpu_instancing too) and places what each node carries: meshes (gltf_meshes,
// over gltf_accessors, with gltf_materials and gltf_textures; morph targets and skins by
// gltf_skins), lights and the camera (gltf_lights_cameras); gltf_animation keeps what
// posing needs and reads the animations.
#pragma once

#include <tiny_gltf.h>

#include <cstdio>
#include <map>
#include <set>
#include <string>
#include <utility>

#include "core/scene/scene.h"
#include "core/scene/scene_error.h"

namespace tessera {

// The most texels a glTF scene's textures hold together: 2^28, up to 4 GiB as floats (12
// bytes a texel, 16 with alpha); GltfContext::max_scene_texels, lowered by tests.
constexpr uint64_t kMaxSceneTexels = uint64_t(1) << 28;

// The most memory one glTF load may take, all kinds together: each kind has a limit of its
// own (buffers 2 GiB, decoded meshopt and Draco views 4 GiB, textures 2^28 texels, morph
// targets 2^28 values, 100 M triangles), but within all of them at once a small file could
// still ask for about 20 GB (100 M triangles copied by its node graph are 10.8 GB of
// vertex arrays alone). 8 GiB: what scene_load_default (server/scene_loads.h) gives a
// load. GltfContext::max_load_bytes, lowered by tests.
constexpr uint64_t kMaxGltfLoadBytes = uint64_t(8) << 30;

struct GltfContext {
  explicit GltfContext(std::string file) : path(std::move(file)) { scene.source = path; }

  // Throws SceneError "file: element: reason".
  [[noreturn]] void fail(const std::string& element, const std::string& reason) const {
    throw SceneError(path, element, reason);
  }
  // A warning naming the file, given once however often the file repeats its cause.
  void warn_once(const std::string& w) {
    if (warned_.insert(w).second) scene.warnings.push_back(path + ": " + w);
  }

  const std::string path;
  tinygltf::Model model;
  Scene scene;
  uint64_t max_scene_texels = kMaxSceneTexels;
  // The values the scene's morph targets hold so far, and at most (gltf_skins.cc; 2^28,
  // kMaxAccessorValues, lowered by tests).
  uint64_t morph_values = 0, max_morph_values = uint64_t(1) << 28;
  uint64_t max_load_bytes = kMaxGltfLoadBytes;

  // Counts `bytes` of kind `what` ("buffers", "meshes", "textures", ...) against the load's
  // memory bound, before they are allocated; fails at `element` naming what the load would
  // hold, kind by kind, and the bound.
  void charge(const std::string& element, const std::string& what, uint64_t bytes) {
    charged_[what] += bytes;
    load_bytes_ += bytes;
    if (load_bytes_ <= max_load_bytes) return;
    std::string kinds;
    for (const auto& [kind, n] : charged_) kinds += (kinds.empty() ? "" : ", ") + kind + " " + gib(n);
    fail(element, "the scene would take " + gib(load_bytes_) + " to load (" + kinds + "), over the " +
                      gib(max_load_bytes) + " limit of a glTF load, all kinds together");
  }
  uint64_t load_bytes() const { return load_bytes_; }

 private:
  static std::string gib(uint64_t bytes) {  // "12 bytes", "3.50 MiB", "10.02 GiB"
    if (bytes < (uint64_t(1) << 20)) return std::to_string(bytes) + " bytes";
    char buf[32];
    const bool g = bytes >= (uint64_t(1) << 30);
    std::snprintf(buf, sizeof buf, "%.2f %s", double(bytes) / double(uint64_t(1) << (g ? 30 : 20)), g ? "GiB" : "MiB");
    return buf;
  }
  std::set<std::string> warned_;
  std::map<std::string, uint64_t> charged_;
  uint64_t load_bytes_ = 0;
};

}  // namespace tessera
