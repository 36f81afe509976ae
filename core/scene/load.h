// Loads a scene file, and says which files it needs: the one place that chooses a loader
// by the file's extension.
#pragma once

#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace tessera {

enum class SceneFormat { kCollada, kGltf };

// By extension (.dae; .gltf or .glb; any case). Throws SceneError for anything else.
SceneFormat scene_format(const std::string& path);

// Throws SceneError (file, element, reason) for anything it cannot load.
Scene load_scene(const std::string& path);

// The files a scene needs besides itself, as paths relative to its folder (a glTF's
// external buffers and images; none for CS184 COLLADA, which is self-contained). Throws
// SceneError if the file cannot be read far enough to tell.
std::vector<std::string> scene_files(const std::string& path);

}  // namespace tessera
