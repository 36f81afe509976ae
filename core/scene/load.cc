#include "core/scene/load.h"

#include <algorithm>

#include "core/scene/collada/collada_loader.h"
#include "core/scene/gltf/gltf_loader.h"
#include "core/scene/scene_error.h"

namespace tessera {

SceneFormat scene_format(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  std::string ext = dot == std::string::npos || (slash != std::string::npos && dot < slash) ? "" : path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".dae") return SceneFormat::kCollada;
  if (ext == ".gltf" || ext == ".glb") return SceneFormat::kGltf;
  throw SceneError(path, "", "unknown scene format '" + ext + "' (expected .dae, .gltf or .glb)");
}

Scene load_scene(const std::string& path) {
  return scene_format(path) == SceneFormat::kCollada ? load_collada_file(path) : load_gltf_file(path);
}

std::vector<std::string> scene_files(const std::string& path) {
  return scene_format(path) == SceneFormat::kCollada ? std::vector<std::string>{} : gltf_external_files(path);
}

}  // namespace tessera
