// Loads a scene file, choosing the loader by extension.
#pragma once

#include <string>

#include "core/scene/scene.h"

namespace tessera {

// Throws SceneError (file, element, reason) for anything it cannot load.
Scene load_scene(const std::string& path);

}  // namespace tessera
