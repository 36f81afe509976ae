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

#include <set>
#include <string>
#include <utility>

#include "core/scene/scene.h"
#include "core/scene/scene_error.h"

namespace tessera {

// The most texels a glTF scene's textures hold together: 2^28, up to 4 GiB as floats (12
// bytes a texel, 16 with alpha); GltfContext::max_scene_texels, lowered by tests.
constexpr uint64_t kMaxSceneTexels = uint64_t(1) << 28;

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

 private:
  std::set<std::string> warned_;
};

}  // namespace tessera
