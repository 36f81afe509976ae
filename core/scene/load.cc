#include "core/scene/load.h"

#include <algorithm>

#include "core/scene/collada/collada_loader.h"
#include "core/scene/gltf/gltf_loader.h"
#include "core/scene/scene_error.h"

namespace tessera {

Scene load_scene(const std::string& path) {
  std::string ext = path.substr(path.find_last_of('.') == std::string::npos ? path.size() : path.find_last_of('.'));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".dae") return load_collada_file(path);
  if (ext == ".gltf" || ext == ".glb") return load_gltf_file(path);
  throw SceneError(path, "", "unknown scene format '" + ext + "' (expected .dae, .gltf or .glb)");
}

}  // namespace tessera
