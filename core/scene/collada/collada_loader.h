// Loader for the CS184 COLLADA profile (../shared/docs/cs184-scene-format.md).
#pragma once

#include <cstdint>
#include <string>

#include "core/scene/scene.h"

namespace tessera {

// The most triangles, and the most vertices, a scene's nodes may place (glTF's triangle
// budget too): each <instance_geometry> is a copy of its mesh, so a small file could ask
// for billions.
constexpr uint64_t kMaxColladaTriangles = 100'000'000;

// Throws SceneError naming the file, the element (with its line) and the problem.
Scene load_collada_file(const std::string& path);
// `name` is used in error messages in place of a path; `base_dir` is unused by COLLADA
// (every CS184 construct is inline) but kept symmetric with the glTF loader.
// `max_triangles` bounds what the nodes place (tests lower it).
Scene load_collada_string(const std::string& text, const std::string& name,
                          uint64_t max_triangles = kMaxColladaTriangles);

}  // namespace tessera
