// Loader for the CS184 COLLADA profile (../shared/docs/cs184-scene-format.md).
#pragma once

#include <string>

#include "core/scene/scene.h"

namespace tessera {

// Throws SceneError naming the file, the element (with its line) and the problem.
Scene load_collada_file(const std::string& path);
// `name` is used in error messages in place of a path; `base_dir` is unused by COLLADA
// (every CS184 construct is inline) but kept symmetric with the glTF loader.
Scene load_collada_string(const std::string& text, const std::string& name);

}  // namespace tessera
