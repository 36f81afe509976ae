// glTF 2.0 loader (.gltf with external or embedded buffers, and .glb), through tinygltf.
// The mapping from glTF's materials and lights to ours is in docs/gltf.md.
#pragma once

#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace tessera {

// Throws SceneError naming the file, the element (e.g. "accessors[3]") and the problem.
Scene load_gltf_file(const std::string& path);
// The buffers and images the file names outside itself, relative to its folder.
std::vector<std::string> gltf_external_files(const std::string& path);

}  // namespace tessera
